// The parallel-jaw gripper in arena's model (issue 31 item 5): two opposed
// fingers on one mechanism that closes symmetrically about a centre fixed in
// the hand. Against closed forms, each beside the independent pads' answer on
// the same scene, so that the coupling is what the test sees.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "scenes.hpp"

namespace arena::mechanics {
namespace {

SimulationResult SimulateOk(const Scene& scene) {
  SimulationResult r = Simulate(scene);
  EXPECT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_FALSE(r.samples.empty());
  return r;
}

// Gravity along the grip axis, no pusher. Independent pads follow the
// object, each pressing with the grip force, so nothing holds it along x: it
// falls freely. Semi-implicit Euler from rest gives v_k = -g k dt and
// x_N = -g dt² N (N + 1) / 2 at the step boundaries (the samples there are
// the steps' poses). The jaw holds it: x stays 0 and its fingers share
// 2 g_grip with the difference carrying the weight, λ_left - λ_right = m g
// (left presses +x), so λ_left = g_grip + m g / 2 = 10.981 N and
// λ_right = 9.019 N.
TEST(ParallelJaw, HoldsTheObjectAgainstAForceAlongTheGripAxis) {
  Scene s = testing::HeldBox(0.2, 10, 0.5);
  s.gravity = {-9.81, 0, 0};
  s.duration = 0.04;
  s.model.dt = 0.001;
  const SimulationResult free_pads = SimulateOk(s);
  const double n_steps = 40;
  EXPECT_NEAR(free_pads.samples.back().position.x(), -9.81 * 1e-6 * n_steps * (n_steps + 1) / 2,
              1e-9);
  EXPECT_NEAR(free_pads.samples.back().contacts[0].normal_force, 10.0, 1e-9);
  EXPECT_NEAR(free_pads.samples.back().contacts[1].normal_force, 10.0, 1e-9);

  s.gripper.coupling = GripperCoupling::kParallelJaw;
  const SimulationResult jaw = SimulateOk(s);
  for (const TrajectorySample& sample : jaw.samples) {
    ASSERT_NEAR(sample.position.x(), 0, 1e-12) << "t = " << sample.t;
    ASSERT_NEAR(sample.contacts[0].normal_force, 10 + 0.2 * 9.81 / 2, 1e-9) << "t = " << sample.t;
    ASSERT_NEAR(sample.contacts[1].normal_force, 10 - 0.2 * 9.81 / 2, 1e-9) << "t = " << sample.t;
  }
}

// Issue 31's push along the grip axis (pusher at 30° from z towards x, μ
// 0.3, point fingers μ 0.5, grip 10 N, no gravity), quasi-static (the
// carried momentum excites a pitch mode here, issue 31 item 2). Independent
// pads: the pusher sticks and carries the object along, x(T) = v sin 30° T =
// 1.000 mm, z(T) = v cos 30° T = 1.732 mm, no pitch.
//
// In the jaw the centre between the fingers is fixed: x cannot follow the
// pusher. The fingers slide along z, so their friction is μ λ each along -z
// whatever the object's pitch rate (|ω| 0.025 m << v_z): it resists no
// pitch, and the sticking pusher turns the object about y instead. With the
// pusher's material point P = (0, 0, -h) (h = 0.05 m) carried to the
// pusher, (a, b) = (v_x T, v_z T), and the centre c = (c_x, c_z):
//   c_x - h sin θ = a,  c_z - h cos θ = b - h,
// and the point fingers on the x axis touching the tilted faces
// (n = (cos θ, 0, ∓sin θ)) symmetrically about the jaw's centre x = 0:
//   c_x cos θ - c_z sin θ = 0, i.e. c_x = c_z tan θ.
// Solved for θ below (one root near -a/h). Along x the object does not
// accelerate, so the jaw takes the push's axial component: the fingers'
// forces along x sum to minus the pusher's.
TEST(ParallelJaw, TakesThePushsAxialComponent) {
  const std::string body =
      R"({"object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{"position":[0,0,0],)"
      R"("rpy":[0,0,0]}},"gravity":[0,0,0],"duration":0.2,"grip_force":10.0,"fingers":[{"name":)"
      R"("left","type":"point","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5},{"name":)"
      R"("right","type":"point","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5}],"model":)"
      R"({"facets":8,"points":3,"dt":0.001,"reduce":"auto","inertia":"quasi_static"},"pusher":)"
      R"({"type":"point","position":[0,0,-0.05],"normal":[0,0,1],"mu":0.3,"motion":{"velocity":)"
      R"([0.004999999999999999,0,0.008660254037844387],"angular_velocity":[0,0,0]}}})";
  Scene s = ParseScene(body);
  const SimulationResult free_pads = SimulateOk(s);
  // Within issue 31's 1 % (0.994 mm today: the pads' slip is another item's).
  EXPECT_NEAR(free_pads.samples.back().position.x(), 1.000e-3, 1e-5);
  EXPECT_NEAR(free_pads.samples.back().position.z(), 1.732e-3, 1e-5);

  s.gripper.coupling = GripperCoupling::kParallelJaw;
  const SimulationResult jaw = SimulateOk(s);
  const TrajectorySample& end = jaw.samples.back();
  const double h = 0.05, a = 0.005 * 0.2, b = 0.008660254037844387 * 0.2;
  auto miss = [&](double th) {
    return (b + h * std::cos(th) - h) * std::tan(th) - h * std::sin(th) - a;
  };
  double lo = -0.2, hi = 0.0;  // miss(lo) > 0 > miss(hi)
  for (int i = 0; i < 200; ++i) (miss(0.5 * (lo + hi)) > 0 ? lo : hi) = 0.5 * (lo + hi);
  const double theta = 0.5 * (lo + hi);
  const double cz = b + h * std::cos(theta) - h, cx = cz * std::tan(theta);
  const Eigen::AngleAxisd turn(end.orientation);
  EXPECT_NEAR(turn.angle() * turn.axis().y(), theta, 1e-4 * std::abs(theta));
  EXPECT_NEAR(end.position.x(), cx, 1e-8);
  EXPECT_NEAR(end.position.z(), cz, 1e-8);
  EXPECT_EQ(end.contacts[2].mode, ContactMode::kStick);
  double fingers_x = 0;
  for (int i = 0; i < 2; ++i) {
    const ContactState& c = end.contacts[static_cast<size_t>(i)];
    fingers_x +=
        c.normal_force * s.fingers[static_cast<size_t>(i)].normal.x() + c.tangential_force.x();
  }
  EXPECT_GT(std::abs(end.pusher_force.x()), 1e-2);  // an axial push the jaw must take
  EXPECT_NEAR(fingers_x, -end.pusher_force.x(), 1e-6);
}

// Fixed contacts (the pads' points frozen in the gripper frame but for their
// travel) keep the jaw's rows: the same hold against gravity along the axis.
TEST(ParallelJaw, HoldsWithFixedContacts) {
  Scene s = testing::HeldBox(0.2, 10, 0.5);
  s.gravity = {-9.81, 0, 0};
  s.duration = 0.04;
  s.model.dt = 0.001;
  s.model.contacts = ContactTracking::kFixed;
  s.gripper.coupling = GripperCoupling::kParallelJaw;
  const SimulationResult jaw = SimulateOk(s);
  EXPECT_NEAR(jaw.samples.back().position.x(), 0, 1e-9);
  EXPECT_NEAR(jaw.samples.back().contacts[0].normal_force, 10 + 0.2 * 9.81 / 2, 1e-6);
}

}  // namespace
}  // namespace arena::mechanics
