// Simple polygons (a prism's outline, a support's footprint): the 2-D
// geometry the model and the MuJoCo backend share. A polygon is a list of
// vertices [x, y] (m), counter-clockwise, simple (no two edges meet but
// neighbours at their shared vertex), convex or not.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace arena::mechanics::polygon {

using Polygon = std::vector<Eigen::Vector2d>;

// The signed area (m², > 0 counter-clockwise).
double SignedArea(const Polygon& poly);

// Whether every vertex turns left (counter-clockwise and convex).
bool IsConvex(const Polygon& poly);

// Whether p lies inside or on the boundary (even-odd rule; a simple polygon).
bool Contains(const Polygon& poly, const Eigen::Vector2d& p);

// The closest boundary point to p and its distance (unsigned, m); *edge is
// the index of the edge [i, i+1] it lies on.
struct BoundaryPoint {
  Eigen::Vector2d point = Eigen::Vector2d::Zero();
  double distance = 0;
  size_t edge = 0;
};
BoundaryPoint ClosestOnBoundary(const Polygon& poly, const Eigen::Vector2d& p);

// Ear clipping: triangles (vertex indices, counter-clockwise) that tile a
// simple counter-clockwise polygon; n - 2 of them. @pre CheckSimple() passed.
std::vector<std::array<int, 3>> Triangulate(const Polygon& poly);

// A polygon's problem: nullopt when simple, counter-clockwise and
// non-degenerate; otherwise the offending vertex and why.
struct Problem {
  size_t vertex = 0;
  std::string reason;
};
std::optional<Problem> CheckSimple(const Polygon& poly);

}  // namespace arena::mechanics::polygon
