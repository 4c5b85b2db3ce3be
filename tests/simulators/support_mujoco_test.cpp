// Issue 30 in the MuJoCo backend: the support (a plane and feet on the
// resting face), a recorded pusher path, a sphere pusher that starts apart
// and a non-convex prism (convex pieces), each against a closed form within
// what soft contact allows (said next to each check).
#include <cmath>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/simulators/simulator.hpp"
#include "mechanics/scenes.hpp"

namespace arena::simulators {
namespace {

using mechanics::ContactType;
using mechanics::Scene;
using mechanics::SimulationStatus;

constexpr double kHalf = 0.045, kHeight = 0.013, kMass = 0.8374, kG = 9.81, kMu = 0.3;

// The push dataset's free push (table frame, z up): a 90 mm square prism on
// a support of friction μ, a frictionless 4.75 mm sphere pusher at
// mid-height starting 5 mm from the -x face at y = offset.
Scene FreePush(double offset, double speed, double duration) {
  Scene s;
  s.object.shape = mechanics::ObjectShape::kPrism;
  s.object.polygon = {{-kHalf, -kHalf}, {kHalf, -kHalf}, {kHalf, kHalf}, {-kHalf, kHalf}};
  s.object.height = kHeight;
  s.object.mass = kMass;
  s.object.pose.position = {0, 0, kHeight / 2};
  s.gravity = {0, 0, -kG};
  s.duration = duration;
  mechanics::PusherSpec p;
  p.name = "pusher";
  p.type = ContactType::kPoint;
  p.radius = 0.00475;
  p.position = {-kHalf - 0.005, offset, kHeight / 2};
  p.normal = {1, 0, 0};
  p.mu = 0;
  p.motion.velocity = {speed, 0, 0};
  s.pusher = p;
  mechanics::SupportSpec support;
  support.mu = kMu;
  s.support = support;
  return s;
}

// The same motion as a recorded path: 4 ms samples of the constant motion.
void RecordPath(Scene* s) {
  mechanics::PusherPath path;
  for (int k = 0; 0.004 * k <= s->duration + 1e-12; ++k) {
    path.t.push_back(0.004 * k);
    path.position.push_back(s->pusher->position + s->pusher->motion.velocity * (0.004 * k));
  }
  s->pusher->path = path;
  s->pusher->motion = mechanics::PusherMotion{};
}

// A face-centred push: the object translates along x and the pusher's force
// is the support's sliding friction μ m g. Soft contact: MuJoCo's elliptic
// friction with impratio 30 reaches μ N only approximately (measured:
// +0.25 %), so the force is checked within 1 % and the heading within
// 1 mrad. Both as a constant velocity and as the same motion recorded as a
// path.
TEST(MujocoSupport, FaceCentredPushNeedsMuMgAndTranslatesStraight) {
  const auto sim = MakeMujocoSimulator({});
  for (const bool recorded : {false, true}) {
    Scene s = FreePush(0, 0.02, 0.6);
    if (recorded) RecordPath(&s);
    mechanics::ValidateScene(s);
    ASSERT_EQ(sim->CheckScene(s), "");
    const std::string xml = MujocoModelXml(s, {});
    EXPECT_NE(xml.find("type=\"plane\""), std::string::npos);
    EXPECT_NE(xml.find("name=\"foot0\""), std::string::npos);
    const auto r = sim->Simulate(s);
    ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
    // Before contact (t < 0.25 s) the object rests: no force, no motion.
    const auto& before = r.samples.at(50);
    EXPECT_LT(before.pusher_force.norm(), 1e-6);
    EXPECT_LT((before.position - r.samples.front().position).norm(), 2e-5);
    double fx = 0;
    int n = 0;
    for (const auto& sample : r.samples) {
      if (sample.t < 0.4) continue;
      fx += sample.pusher_force.x();
      ++n;
      EXPECT_NEAR(sample.velocity.x(), 0.02, 0.02 * 0.05) << recorded << " t " << sample.t;
    }
    EXPECT_NEAR(fx / n, kMu * kMass * kG, 0.01 * kMu * kMass * kG) << "recorded " << recorded;
    const auto& last = r.samples.back();
    const Eigen::Vector3d heading = last.orientation * Eigen::Vector3d::UnitX();
    EXPECT_LT(std::abs(heading.y()), 1e-3);
    EXPECT_LT(std::abs(last.position.y()), 1e-4);
    // The pusher is driven along the path: its reported position is the path's.
    EXPECT_NEAR(last.pusher_position.x(), -kHalf - 0.005 + 0.02 * 0.6, 1e-9);
  }
}

// A recorded path that stops: the object stops with it (the support holds
// it), where the constant motion would have carried it on.
TEST(MujocoSupport, RecordedPathThatStopsLeavesTheObjectAtRest) {
  Scene s = FreePush(0, 0.02, 0.8);
  mechanics::PusherPath path;
  path.t = {0, 0.5, 0.8};
  const Eigen::Vector3d p0 = s.pusher->position;
  path.position = {p0, p0 + Eigen::Vector3d(0.01, 0, 0), p0 + Eigen::Vector3d(0.01, 0, 0)};
  s.pusher->path = path;
  s.pusher->motion = mechanics::PusherMotion{};
  mechanics::ValidateScene(s);
  const auto r = MakeMujocoSimulator({})->Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  // Pushed 5 mm (contact after 5 of the path's 10 mm), then at rest.
  EXPECT_NEAR(r.samples.back().position.x(), 0.005, 5e-4);
  EXPECT_LT(r.samples.back().velocity.norm(), 1e-3);
  EXPECT_EQ(r.samples.back().pusher_position, path.position.back());
}

// Weighted pressure points are arena's model only: refused by name.
TEST(MujocoSupport, WeightedPressureIsRefusedByName) {
  Scene s = FreePush(0, 0.02, 0.1);
  s.support->pressure_points = {{0.01, 0, 1}, {-0.01, 0, 1}};
  const auto sim = MakeMujocoSimulator({});
  EXPECT_EQ(sim->CheckScene(s).rfind("support.pressure.points", 0), 0u) << sim->CheckScene(s);
  EXPECT_EQ(sim->Simulate(s).status, SimulationStatus::kInvalidScene);
}

// A non-convex prism (an L of 60 mm arms, 30 mm wide) is cut into convex
// pieces; a face-centred push on its long -x face translates it as a
// whole: the pieces move together and every piece meets the pusher's pads.
TEST(MujocoSupport, NonConvexPrismIsCutIntoConvexPieces) {
  Scene s = FreePush(0, 0.02, 0.5);
  s.object.polygon = {{0, 0}, {0.06, 0}, {0.06, 0.03}, {0.03, 0.03}, {0.03, 0.06}, {0, 0.06}};
  // The L's centroid is (0.025, 0.025): put it at the origin.
  s.object.pose.position = {-0.025, -0.025, kHeight / 2};
  s.pusher->position = {-0.025 - 0.003, 0.0, kHeight / 2};
  mechanics::ValidateScene(s);
  const auto sim = MakeMujocoSimulator({});
  ASSERT_EQ(sim->CheckScene(s), "");
  const std::string xml = MujocoModelXml(s, {});
  EXPECT_NE(xml.find("name=\"object_piece3\""), std::string::npos);  // 4 triangles
  EXPECT_EQ(xml.find("name=\"object_piece4\""), std::string::npos);
  const auto r = sim->Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  // The push passes through the centroid's y (0): it translates and the
  // pusher's force is μ m g (1 % as above; measured +0.28 %).
  double fx = 0;
  int n = 0;
  for (const auto& sample : r.samples) {
    if (sample.t < 0.3) continue;
    fx += sample.pusher_force.x();
    ++n;
  }
  EXPECT_NEAR(fx / n, kMu * kMass * kG, 0.01 * kMu * kMass * kG);
  EXPECT_GT(r.samples.back().position.x(), 0.005);
}

}  // namespace
}  // namespace arena::simulators
