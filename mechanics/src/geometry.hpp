// The object as a solid, for the tracked contact model (model.hpp) and the
// scene validation: closest surface points, the entry of a closing line, and
// the support feature towards a flat pad. Everything here is in the object
// frame O (the frame object.pose places: a box's and cylinder's centre, a
// prism's polygon origin at mid-height); the model converts.
//
// Shapes: a box is the prism of its x-y rectangle; a prism is a simple
// polygon (counter-clockwise, convex or not) extruded along z over
// [-h/2, h/2]; a cylinder
// has its axis along z. Outward normals throughout; signed distances are
// negative inside.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "arena/mechanics/scene.hpp"

namespace arena::mechanics::geometry {

struct Closest {
  Eigen::Vector3d point_O = Eigen::Vector3d::Zero();    // on the surface
  Eigen::Vector3d normal_O = Eigen::Vector3d::UnitZ();  // outward, unit
  double distance = 0;                                  // signed: < 0 inside
};

// Where the line p + s d (d unit) enters the solid: s_in, the entry point and
// the outward normal of the entered face. nullopt: the line misses.
struct Entry {
  double s = 0;
  Eigen::Vector3d point_O = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal_O = Eigen::Vector3d::UnitZ();
};

// The solid's points that come first along a direction: a face (>= 3
// points: its vertices, or a cylinder cap's centre), an edge (2 points, its
// ends) or a vertex (1 point).
struct Feature {
  enum class Kind { kVertex, kEdge, kFace } kind = Kind::kFace;
  std::vector<Eigen::Vector3d> points_O;
};

class Solid {
 public:
  explicit Solid(const ObjectSpec& object);

  Closest ClosestTo(const Eigen::Vector3d& p_O) const;
  // The same, except that a point inside a convex prism within `tolerance`
  // (m) of several faces' planes takes the one whose outward normal is
  // nearest `prefer_O` (unit) instead of the least deep: a point on an edge
  // or vertex otherwise takes whichever face rounding makes least deep, so
  // its normal flips from step to step.
  Closest ClosestTo(const Eigen::Vector3d& p_O, const Eigen::Vector3d& prefer_O,
                    double tolerance) const;
  std::optional<Entry> EntryOf(const Eigen::Vector3d& p_O, const Eigen::Vector3d& d_O,
                               double tolerance) const;
  // The feature minimising dir · x (dir unit), with points within `tolerance`
  // (m) of the minimum counted in.
  Feature Support(const Eigen::Vector3d& dir_O, double tolerance) const;

  // Centre of mass in O (uniform density) and the largest extent (m).
  const Eigen::Vector3d& centroid_O() const { return centroid_O_; }
  double extent() const { return extent_; }

 private:
  Closest ClosestToNonConvex(const Eigen::Vector3d& p_O) const;
  std::optional<Entry> EntryOfNonConvex(const Eigen::Vector3d& p_O, const Eigen::Vector3d& d_O,
                                        double tolerance, double s_in, double s_out,
                                        Eigen::Vector3d cap_normal_O) const;

  ObjectShape shape_;
  bool convex_ = true;  // prisms: a non-convex outline takes the general paths
  double radius_ = 0, half_height_ = 0;
  std::vector<Eigen::Vector2d> polygon_;  // box: its rectangle
  std::vector<Eigen::Vector2d> edge_normals_;
  std::vector<double> edge_offsets_;  // n_i · x <= offset_i inside
  Eigen::Vector3d centroid_O_ = Eigen::Vector3d::Zero();
  double extent_ = 1;
};

// Prism polygons: nullopt when simple, counter-clockwise and non-degenerate;
// otherwise the index of the offending vertex and why.
struct PolygonProblem {
  size_t vertex = 0;
  std::string reason;
};
std::optional<PolygonProblem> CheckPolygon(const std::vector<Eigen::Vector2d>& polygon);

// Area, centroid and the second moments ∫x², ∫y², ∫xy about the centroid.
struct PolygonMoments {
  double area = 0;
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  double xx = 0, yy = 0, xy = 0;
};
PolygonMoments MomentsOf(const std::vector<Eigen::Vector2d>& polygon);

}  // namespace arena::mechanics::geometry
