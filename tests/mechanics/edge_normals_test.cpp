// Issue 31 item 6: a point on an edge or a vertex of the object takes a
// face's normal. It used to take whichever face was least deep, which at an
// edge is decided by rounding (both depths are ~0 once the step has put the
// point on the surface), so the normal could flip between the faces from
// step to step or, as below, stay on the wrong one from the first step.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "arena/mechanics/simulate.hpp"
#include "scenes.hpp"

namespace arena::mechanics {
namespace {

// The canonical box (0.05 × 0.03 × 0.1 m, 0.2 kg) held at 10 N by two point
// fingers (μ 0.5) on the x axis, no gravity, pushed from below by a point
// (μ 0.3) that starts ON the bottom-front edge, (0, -0.015, -0.05), and
// moves up at 1 cm/s for 0.2 s (2 mm).
//
// What must hold, whatever the object does: the pusher can enter the box
// only by the bottom face it closes onto (its normal +z), so the object must
// move out of its way. In the object frame the pusher's point p_O =
// Rᵀ (p0 + v t − c) then lies on the surface at every sample: its signed distance
// to the box, max(|x| − a, |y| − b, |z| − h) inside, is 0 within the model's
// gap tolerance (1e-4 of the length scale, 10 µm). And with nothing in the
// scene that knows dt (no gravity, no stiffness), the final pose is the same
// at dt 1 ms and 0.1 ms (within 1 % of the pusher's travel).
//
// The old rule took the front face (normal -y, depth exactly 0 at the
// start, the bottom's growing): the pusher slid along the front face into
// the box, the object never moved (pusher force 0 N) and the run said ok,
// the pusher 2 mm inside at the end.
Scene EdgePush(double dt, Eigen::Vector3d velocity) {
  Scene s = testing::HeldBox(0.2, 10, 0.5);
  s.gravity = {0, 0, 0};
  PusherSpec p;
  p.name = "pusher";
  p.position = {0, -0.015, -0.05};
  p.normal = {0, 0, 1};
  p.mu = 0.3;
  p.motion.velocity = velocity;
  s.pusher = p;
  s.model.dt = dt;
  return s;
}

// Signed distance of a point (object frame, centred box) to the box.
double BoxDistance(const Eigen::Vector3d& p_O, const Eigen::Vector3d& half) {
  const Eigen::Vector3d q = p_O.cwiseAbs() - half;
  const double outside = q.cwiseMax(0.0).norm();
  return outside > 0 ? outside : q.maxCoeff();
}

TEST(EdgeNormals, APusherOnAnEdgeMovesTheObjectAndStaysOnItsSurface) {
  const Eigen::Vector3d half(0.025, 0.015, 0.05);
  // Straight up, and nearly along the front face (tilted 0.05 rad towards
  // the box).
  for (const Eigen::Vector3d& v : std::initializer_list<Eigen::Vector3d>{
           Eigen::Vector3d(0, 0, 0.01),
           Eigen::Vector3d(Eigen::Vector3d(0, 0.05, 1).normalized() * 0.01)}) {
    Eigen::Vector3d end[2];
    double angle[2] = {0, 0};
    int k = 0;
    for (double dt : {1e-3, 1e-4}) {
      const SimulationResult r = Simulate(EdgePush(dt, v));
      ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
      double worst = 0;
      for (const TrajectorySample& s : r.samples) {
        // The pusher's own point (where its motion puts it), not the
        // contact point the model reports on the surface.
        const Eigen::Vector3d pusher = Eigen::Vector3d(0, -0.015, -0.05) + s.t * v;
        const Eigen::Vector3d p_O = s.orientation.conjugate() * (pusher - s.position);
        worst = std::max(worst, std::abs(BoxDistance(p_O, half)));
      }
      const TrajectorySample& e = r.samples.back();
      std::printf(
          "v (%g, %g) dt %g: c (%.5f, %.5f) mm, roll %.5f rad, force (%.3f, %.3f) N, "
          "pusher off the surface %.3g m at worst\n",
          v.y(), v.z(), dt, e.position.y() * 1e3, e.position.z() * 1e3,
          Eigen::AngleAxisd(e.orientation).angle(), e.pusher_force.y(), e.pusher_force.z(), worst);
      EXPECT_LT(worst, 1e-5) << "the pusher left the surface (dt " << dt << ")";
      EXPECT_GT(e.position.z(), 1e-4) << "the object did not move out of the pusher's way";
      end[k] = e.position;
      angle[k] = Eigen::AngleAxisd(e.orientation).angle();
      ++k;
    }
    const double travel = 0.2 * v.norm();
    EXPECT_LT((end[0] - end[1]).norm(), 0.01 * travel) << "dt-dependent answer";
    EXPECT_LT(std::abs(angle[0] - angle[1]), 0.01 * std::abs(angle[1]) + 1e-9);
  }
}

}  // namespace
}  // namespace arena::mechanics
