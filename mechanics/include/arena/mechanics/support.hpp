// The support (scene.hpp, SupportSpec): the object's resting face as
// weighted pressure points, and the Coulomb friction they give a planar
// twist (the limit surface). The model and the MuJoCo backend both place
// the support's load with these points.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "arena/mechanics/scene.hpp"

namespace arena::mechanics {

// Where the object presses on the support: points on its resting face in
// the object frame (z = the cap's), and their share of the load (> 0,
// summing to 1).
struct SupportPressure {
  std::vector<Eigen::Vector3d> points_O;
  std::vector<double> weights;
  double cap_z_O = 0;  // the resting cap's z in the object frame (-h/2 or +h/2)
};

// The resting face's pressure: `support.pressure_points` normalised (points
// of zero weight dropped), or uniform pressure as a quadrature of about
// `target` points: a polygon (a box's rectangle, a prism's outline) cut
// into triangles (ear clipping), each split into k² equal triangles with
// their centroids (linear functions integrate exactly, so the points'
// centre is the face's centroid); a disk in equal-area rings, each ring's
// points at its annulus's mean radius (2/3 (ro³ - ri³)/(ro² - ri²)), so
// that Σ w r is ∫ r dA / A exactly: a disk spun about its centre meets the
// closed-form torque (2/3) μ N R.
// @throws std::invalid_argument naming `support` when the object's z axis is
// not along gravity (it rests on no z cap).
SupportPressure SupportPressureOf(const Scene& scene, int target = 400);

// The friction of the pressure points r (2-D, relative to the reference
// point, m) with shares w, under a total normal load N and friction mu, for
// the planar twist (v: velocity of the reference point, omega: rate about
// the support's normal): each point's force -mu N w_i u_i / |u_i| with
// u_i = v + omega ẑ × r_i (none where u_i = 0). Returns (fx, fy, torque
// about the reference point).
Eigen::Vector3d SupportFriction(const std::vector<Eigen::Vector2d>& r, const std::vector<double>& w,
                                double mu_N, const Eigen::Vector2d& v, double omega);

}  // namespace arena::mechanics
