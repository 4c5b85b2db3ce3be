// Elastic finger pads (a line or patch finger's "stiffness", N/m): the point
// forces of a pad follow its penetration, so a flush pad shares its grip
// evenly where a rigid one's sharing is undetermined (Lemke's method returns
// a vertex of that set), and a rigid pad stays exactly as it was.
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "mechanics/scenes.hpp"

namespace arena::mechanics {
namespace {

using testing::HeldBox;

// Two patch fingers (radius 5 mm) pressing a 5 x 3 x 10 cm box along x.
Scene PatchGrip(double stiffness, double grip = 10) {
  Scene s = HeldBox(0.2, grip, 0.5);
  for (auto& f : s.fingers) {
    f.type = ContactType::kPatch;
    f.radius = 0.005;
    f.stiffness = stiffness;
  }
  s.model.points = 5;
  s.duration = 0.1;
  return s;
}

// A flush elastic pad with no load but the grip: every point presses equally
// (the same penetration), so the normal forces' moment about the pad's
// centre vanishes and their force-weighted centre is the pad's centre. The
// grip is the sum, as for a rigid pad. (The same scene with rigid pads:
// the moment is 0.033 N m and the centre 3.3 mm off: the vertex Lemke's
// method picks.)
TEST(ElasticPad, AFlushPadSharesItsGripEvenly) {
  Scene s = PatchGrip(2e4);
  s.gravity.setZero();
  ValidateScene(s);
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  const TrajectorySample& last = r.samples.back();
  const double grip = s.grip_force, radius = 0.005;
  for (size_t f = 0; f < 2; ++f) {
    const ContactState& c = last.contacts[f];
    EXPECT_NEAR(c.normal_force, grip, 1e-9 * grip);
    EXPECT_LT(c.torque.norm(), 1e-9 * grip * radius) << "finger " << f;
    EXPECT_LT((c.point - s.fingers[f].position).norm(), 1e-9) << "finger " << f;
    EXPECT_EQ(c.touching_points, 5);
  }
  EXPECT_LT(last.position.norm(), 1e-12);
}

// A pad of stiffness k pressed with the grip F sinks in by F/k, but the pads
// follow the object along their normals (force-controlled fingers), so two
// pads of different stiffness, soft or stiff, hold the object exactly where
// it was: the grip balances whatever the sinks.
TEST(ElasticPad, StiffnessDoesNotMoveABalancedGrip) {
  for (double k : {2e3, 2e4, 2e6}) {
    Scene s = PatchGrip(k);
    s.gravity.setZero();
    s.fingers[1].stiffness = 3 * k;
    const SimulationResult r = Simulate(s);
    ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
    EXPECT_LT(r.samples.back().position.norm(), 1e-12) << "k " << k;
    EXPECT_LT(r.samples.back().orientation.vec().norm(), 1e-12) << "k " << k;
  }
}

// Held under gravity, off-centre: the grip axis 12 mm above the centre of
// mass, so gravity turns the box about the grip axis against the pads'
// torsional friction (0.5 x 10 N x the ring's 5 mm per pad: 0.05 N m, the
// gravity torque 0.024 N m). Elastic pads hold it (as rigid ones do here:
// the swing of a rigid pad needs the object tilted off the pads' plane,
// docs/live_control.md).
TEST(ElasticPad, HoldsAnOffCentreBoxByTorsionalFriction) {
  Scene s = PatchGrip(2e4);
  for (auto& f : s.fingers) f.position.z() = 0.012;
  s.duration = 0.5;
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  const double angle = 2 * std::asin(std::min(1.0, r.samples.back().orientation.vec().norm()));
  EXPECT_LT(angle, 1e-3) << "turned " << angle << " rad";
}

TEST(ElasticPad, SceneFieldIsReadCheckedAndWrittenBack) {
  const char* base = R"({
    "object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2},
    "grip_force": 10, "duration": 0.1,
    "fingers": [
      {"name": "l", "type": "patch", "radius": 0.005, "position": [-0.025, 0, 0],
       "normal": [1, 0, 0], "mu": 0.5, "stiffness": STIFF},
      {"name": "r", "type": TYPE, "position": [0.025, 0, 0], "normal": [-1, 0, 0], "mu": 0.5}
    ]})";
  auto scene = [&](const std::string& stiff, const std::string& type) {
    std::string t = base;
    t.replace(t.find("STIFF"), 5, stiff);
    t.replace(t.find("TYPE"), 4, type);
    return t;
  };
  const Scene s = ParseScene(scene("20000", R"("point")"));
  EXPECT_EQ(s.fingers[0].stiffness, 20000);
  EXPECT_EQ(s.fingers[1].stiffness, 0);  // absent: rigid
  EXPECT_EQ(ParseScene(SceneToJson(s)).fingers[0].stiffness, 20000);
  EXPECT_EQ(SceneToJson(s).find("\"stiffness\"", SceneToJson(s).find("\"r\"")), std::string::npos);
  auto error_of = [&](const std::string& text) {
    try {
      ParseScene(text);
    } catch (const SceneError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(error_of(scene("0", R"("point")")).find("fingers[0].stiffness"), std::string::npos);
  EXPECT_NE(error_of(scene("-5", R"("point")")).find("must be > 0"), std::string::npos);
  EXPECT_NE(error_of(scene(R"("soft")", R"("point")")).find("fingers[0].stiffness"),
            std::string::npos);
  // A point finger has no pad to compress.
  std::string point = scene("20000", R"("point")");
  const std::string patch = R"("type": "patch", "radius": 0.005)";
  point.replace(point.find(patch), patch.size(), R"("type": "point")");
  EXPECT_NE(error_of(point).find("only for a line or patch finger"), std::string::npos)
      << error_of(point);
  // Built in code: the same checks.
  Scene bad = PatchGrip(2e4);
  bad.fingers[0].stiffness = NAN;
  EXPECT_THROW(ValidateScene(bad), SceneError);
  bad = PatchGrip(2e4);
  bad.pusher.emplace();
  bad.pusher->type = ContactType::kPoint;
  bad.pusher->position = {0, 0, -0.05};
  bad.pusher->normal = {0, 0, 1};
  bad.pusher->stiffness = 1e4;
  EXPECT_THROW(ValidateScene(bad), SceneError);
}

// A push along a stiff line pad's own axis in fixed contact frames (the
// frames frozen in the gripper): the object slides up with the pusher and
// nothing turns it, the pad's load split uniform as it started. The pad
// points' penetration was not carried from step to step in fixed frames,
// so the compliance acted as a damper (λ = -k dt v_n), which resists no
// tilt: the object turned at up to 1.1e-2 rad/s. Carried, a start
// transient remained (|ω| 1.1e-4 rad/s, decaying to 3e-14): a sunk pad
// point's friction acted 1e-5 m inside the surface, an arm longer than the
// opposite finger's. Applied on the surface, |ω| stays below 1e-9 (the
// limit of validation_test's LinearPush) from the first step.
TEST(ElasticPad, FixedFramesKeepTheLinePadsPenetration) {
  Scene s = HeldBox(0.2, 10, 0.5);
  s.fingers[1].type = ContactType::kLine;
  s.fingers[1].axis = {0, 0, 1};
  s.fingers[1].length = 0.02;
  s.fingers[1].stiffness = 10 / (1e-4 * 0.1);
  s.model.contacts = ContactTracking::kFixed;
  s.pusher.emplace();
  s.pusher->name = "pusher";
  s.pusher->type = ContactType::kPoint;
  s.pusher->position = {0, 0, -0.05};
  s.pusher->normal = {0, 0, 1};
  s.pusher->mu = 0.3;
  s.pusher->motion.velocity = {0, 0, 0.01};
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  double worst = 0;
  for (const TrajectorySample& x : r.samples) worst = std::max(worst, x.angular_velocity.norm());
  EXPECT_LT(worst, 1e-9);
  EXPECT_NEAR(r.samples.back().pusher_force.z(), 10 + 0.2 * 9.81, 1e-6);
}

}  // namespace
}  // namespace arena::mechanics
