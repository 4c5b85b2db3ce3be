// The closed-loop hook of mechanics (issue 19): Simulate(scene, commands)
// and ContactModel::SetPusherMotion, and the {"controller": NAME} motion in
// scene JSON.
#include <string>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::mechanics {
namespace {

const char* kPivot = R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2},
  "gravity": [0, 0, -9.81], "duration": 0.3, "grip_force": 10.0,
  "fingers": [
    {"name": "left", "type": "patch", "radius": 0.005, "position": [-0.025, 0, 0],
     "normal": [1, 0, 0], "mu": 0.5},
    {"name": "right", "type": "patch", "radius": 0.005, "position": [0.025, 0, 0],
     "normal": [-1, 0, 0], "mu": 0.5}],
  "pusher": {"type": "point", "position": [0, -0.015, -0.04], "normal": [0, 1, 0], "mu": 0.3,
             "motion": MOTION},
  "model": {"facets": 8, "points": 3, "dt": 0.004, "reduce": "auto"}})";

std::string Pivot(const std::string& motion) {
  std::string s = kPivot;
  s.replace(s.find("MOTION"), 6, motion);
  return s;
}

TEST(ClosedLoopHook, ConstantCommandsReproduceTheOpenLoopTrajectory) {
  const Scene open = ParseScene(Pivot(R"({"velocity": [0, 0.01, 0]})"));
  const SimulationResult expected = Simulate(open);
  ASSERT_EQ(expected.status, SimulationStatus::kOk) << expected.error;
  int calls = 0;
  const SimulationResult got =
      Simulate(open, [&](const std::vector<TrajectorySample>& samples, std::string*) {
        EXPECT_EQ(samples.size(), static_cast<std::size_t>(++calls));
        return std::optional<PusherMotion>(open.pusher->motion);
      });
  ASSERT_EQ(got.status, SimulationStatus::kOk) << got.error;
  ASSERT_EQ(got.samples.size(), expected.samples.size());
  for (std::size_t i = 0; i < got.samples.size(); ++i) {
    EXPECT_LT((got.samples[i].position - expected.samples[i].position).norm(), 1e-12) << i;
    EXPECT_LT(got.samples[i].orientation.angularDistance(expected.samples[i].orientation), 1e-12);
    EXPECT_LT((got.samples[i].pusher_position - expected.samples[i].pusher_position).norm(), 1e-12);
  }
}

TEST(ClosedLoopHook, ACommandMovesThePusherFromTheNextStepOnAndItStopsWhenToldTo) {
  Scene scene = ParseScene(Pivot(R"({"controller": "pivot_to_angle"})"));
  ASSERT_TRUE(scene.pusher->controller);
  const SimulationResult r =
      Simulate(scene, [](const std::vector<TrajectorySample>& samples, std::string* why) {
        if (samples.size() > 50) {
          *why = "enough";
          return std::optional<PusherMotion>();
        }
        PusherMotion m;
        m.velocity = {0, samples.size() > 25 ? 0.0 : 0.02, 0};
        return std::optional<PusherMotion>(m);
      });
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_EQ(r.stopped, "enough");
  ASSERT_EQ(r.samples.size(), 51u);
  // The pusher moved 0.02 m/s while commanded, then held still: continuous.
  const double moved = r.samples[25].pusher_position.y() - r.samples[0].pusher_position.y();
  EXPECT_GT(moved, 0.0);
  EXPECT_NEAR(r.samples[50].pusher_position.y(), r.samples[26].pusher_position.y(), 1e-12);
  EXPECT_GT(r.samples[50].orientation.angularDistance(r.samples[0].orientation), 0.01);
}

TEST(ClosedLoopHook, ACommandThatTurnsThePusherEndsTheRunWithTheReason) {
  Scene scene = ParseScene(Pivot(R"({"controller": "pivot_to_angle"})"));
  const SimulationResult r =
      Simulate(scene, [](const std::vector<TrajectorySample>&, std::string*) {
        PusherMotion m;
        m.angular_velocity = {1, 0, 0};
        return std::optional<PusherMotion>(m);
      });
  EXPECT_EQ(r.status, SimulationStatus::kInvalidScene);
  EXPECT_NE(r.error.find("angular velocity"), std::string::npos) << r.error;
}

TEST(ClosedLoopHook, ControllerMotionRoundTripsAndBadValuesAreNamed) {
  const Scene scene = ParseScene(Pivot(
      R"({"controller": "lab.pivot-1", "target": 0.3, "gain": 2, "tolerance": 0.01, "hold_s": 0.1})"));
  ASSERT_TRUE(scene.pusher->controller);
  EXPECT_EQ(scene.pusher->controller->name, "lab.pivot-1");
  EXPECT_EQ(scene.pusher->controller->target, 0.3);
  const Scene again = ParseScene(SceneToJson(scene));
  ASSERT_TRUE(again.pusher->controller);
  EXPECT_EQ(again.pusher->controller->gain, 2);
  EXPECT_EQ(again.pusher->controller->hold_s, 0.1);
  EXPECT_EQ(SceneToJson(again), SceneToJson(scene));
  auto field = [](const std::string& motion) {
    try {
      ParseScene(Pivot(motion));
    } catch (const SceneError& e) {
      return e.field();
    }
    return std::string("(accepted)");
  };
  EXPECT_EQ(field(R"({"controller": "x", "hold_s": 0})"), "pusher.motion.hold_s");
  EXPECT_EQ(field(R"({"controller": "x", "tolerance": -1})"), "pusher.motion.tolerance");
  EXPECT_EQ(field(R"({"controller": "a b"})"), "pusher.motion.controller");
  EXPECT_EQ(field(R"({"controller": "x", "velocity": [0, 1, 0]})"), "pusher.motion.velocity");
}

}  // namespace
}  // namespace arena::mechanics
