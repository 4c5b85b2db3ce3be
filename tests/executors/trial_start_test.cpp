// The cell's start-pose and pusher rules (executors/src/trial_start.hpp).
#include "trial_start.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "arena/executors/defects.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace arena::executors {
namespace {

reset::Pose At(double x, double y, double z, double yaw = 0) {
  reset::Pose p;
  p.position = {x, y, z};
  p.orientation = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ());
  return p;
}

mechanics::PusherSpec Pusher() {
  mechanics::PusherSpec p;
  p.type = mechanics::ContactType::kPoint;
  p.position = {0, -0.015, 0};
  p.normal = {0, 1, 0};
  return p;
}

TEST(TrialStart, AResetAimedAtThisTrialIsWhereItStarts) {
  TrialStart start;
  const reset::ResetParams params;
  const reset::Pose target = At(0, 0, 0);
  const reset::Pose left = At(0.001, -0.002, 0, 0.01);
  start.ResetEnded(7, target, left);
  const auto pose = start.StartPose(7, target, params, true);
  ASSERT_TRUE(pose);
  EXPECT_EQ(pose->position, left.position);
  EXPECT_EQ(pose->orientation.coeffs(), left.orientation.coeffs());
}

TEST(TrialStart, AnotherTrialStartsFromItsOwnPureDrawWhatEverRanBefore) {
  const reset::ResetParams params;
  const reset::Pose target = At(0, 0, 0);
  const reset::Pose own = reset::PlacementForTrial(target, params, 9).true_pose;
  TrialStart fresh, used;
  used.ResetEnded(7, target, At(0.01, 0, 0));  // aimed at trial 7, not 9
  for (const TrialStart* s : {&fresh, &used}) {
    const auto pose = s->StartPose(9, target, params, true);
    ASSERT_TRUE(pose);
    EXPECT_EQ(pose->position, own.position);
  }
  // The same seed aimed at another target is another trial.
  used.ResetEnded(9, At(0.02, 0, 0), At(0.5, 0, 0));
  EXPECT_EQ(used.StartPose(9, target, params, true)->position, own.position);
}

TEST(TrialStart, ARanTrialForgetsTheResetAndARealBackendIsLeftAlone) {
  TrialStart start;
  const reset::ResetParams params;
  const reset::Pose target = At(0, 0, 0);
  start.ResetEnded(7, target, At(0.003, 0, 0));
  start.TrialRan();
  EXPECT_EQ(start.StartPose(7, target, params, true)->position,
            reset::PlacementForTrial(target, params, 7).true_pose.position);
  EXPECT_FALSE(start.StartPose(7, target, params, false).has_value());
}

TEST(TrialStart, PlacedAtMovesTheObjectAndLeavesAPlannedSceneAlone) {
  const mechanics::Scene scene = mechanics::ParseScene(R"({
    "object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2},
    "gravity": [0, 0, -9.81], "duration": 0.1, "grip_force": 10.0,
    "fingers": [
      {"name": "l", "type": "point", "position": [-0.025, 0, 0], "normal": [1, 0, 0], "mu": 0.5},
      {"name": "r", "type": "point", "position": [0.025, 0, 0], "normal": [-1, 0, 0], "mu": 0.5}]})");
  const mechanics::Scene same = TrialStart::PlacedAt(scene, std::nullopt);
  EXPECT_EQ(same.object.pose.position, scene.object.pose.position);
  const mechanics::Scene moved = TrialStart::PlacedAt(scene, At(0, 0.001, 0.002, 0.02));
  EXPECT_NEAR(moved.object.pose.position.y(), 0.001, 1e-12);
  EXPECT_NEAR(moved.object.pose.position.z(), 0.002, 1e-12);
  EXPECT_NEAR(moved.object.pose.rpy.z(), 0.02, 1e-12);
}

TEST(TrialStart, ThePusherIsMovedWhenOnlyItsContactPointDiffersOtherwiseSwapped) {
  const auto a = Pusher();
  auto moved = a;
  moved.position.y() += 0.01;
  auto turned = a;
  turned.normal = {1, 0, 0};
  auto other_tool = a;
  other_tool.type = mechanics::ContactType::kLine;
  EXPECT_FALSE(ChangeOfPusher(a, a).swap);
  EXPECT_EQ(ChangeOfPusher(a, a).move_m, 0);
  EXPECT_FALSE(ChangeOfPusher(a, moved).swap);
  EXPECT_NEAR(ChangeOfPusher(a, moved).move_m, 0.01, 1e-12);
  EXPECT_TRUE(ChangeOfPusher(a, turned).swap);
  EXPECT_TRUE(ChangeOfPusher(a, other_tool).swap);
  EXPECT_TRUE(ChangeOfPusher(a, std::nullopt).swap);
  EXPECT_TRUE(ChangeOfPusher(std::nullopt, a).swap);
  EXPECT_FALSE(ChangeOfPusher(std::nullopt, std::nullopt).swap);
}

// Issue 29: the fixtures a scene needs, and what a change costs the cell.
mechanics::Scene FixtureScene() {
  mechanics::Scene s;
  s.object.shape = mechanics::ObjectShape::kBox;
  s.object.size = {0.05, 0.03, 0.1};
  s.object.mass = 0.2;
  mechanics::ContactSpec f;
  f.type = mechanics::ContactType::kLine;
  f.length = 0.02;
  f.mu = 0.5;
  s.fingers = {f, f};
  s.pusher = Pusher();
  return s;
}

TEST(FixtureChanges, EachFixtureIsItsOwnChangeAndOnlyToolsCount) {
  const schemas::ChangeCosts costs{30, 5, 10};
  const mechanics::Scene base = FixtureScene();
  const schemas::Fixtures mounted = schemas::FixturesOf(base);
  auto changes_to = [&](const mechanics::Scene& next) {
    return schemas::ChangesBetween(mounted, schemas::FixturesOf(next), costs);
  };
  EXPECT_TRUE(changes_to(base).empty());
  // Where things are is not a fixture: a moved pusher, a placed object.
  mechanics::Scene moved = base;
  moved.pusher->position.x() += 0.01;
  moved.object.pose.position.y() += 0.002;
  EXPECT_TRUE(changes_to(moved).empty());
  EXPECT_FALSE(ChangeOfPusher(base.pusher, moved.pusher).swap);
  // Finger pads: type, size, friction each make another pad.
  mechanics::Scene patch = base;
  for (auto& f : patch.fingers) f.type = mechanics::ContactType::kPatch;
  mechanics::Scene grippy = base;
  grippy.fingers[1].mu = 0.8;
  for (const auto& s : {patch, grippy}) {
    const auto c = changes_to(s);
    ASSERT_EQ(c.size(), 1u);
    EXPECT_EQ(c[0].what, "finger");
    EXPECT_EQ(c[0].from, mounted.finger);
    EXPECT_DOUBLE_EQ(c[0].seconds, 30);
  }
  // The pusher changes exactly when a reset swaps it.
  mechanics::Scene line = base;
  line.pusher->type = mechanics::ContactType::kLine;
  line.pusher->length = 0.01;
  line.pusher->axis = {1, 0, 0};
  const auto c = changes_to(line);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c[0].what, "pusher");
  EXPECT_TRUE(ChangeOfPusher(base.pusher, line.pusher).swap);
  EXPECT_TRUE(ChangesPusher(c));
  // The object: its mass makes another object.
  mechanics::Scene heavy = base;
  heavy.object.mass = 0.3;
  ASSERT_EQ(changes_to(heavy).size(), 1u);
  EXPECT_EQ(changes_to(heavy)[0].what, "object");
  // All three; a simulated reset spends fingers and object besides its plan
  // (the plan's swap primitive is the pusher's), a trial's own change all three.
  mechanics::Scene all = patch;
  all.pusher = line.pusher;
  all.object.mass = 0.3;
  const auto every = changes_to(all);
  ASSERT_EQ(every.size(), 3u);
  EXPECT_DOUBLE_EQ(schemas::ChangeSeconds(every), 45);
  EXPECT_DOUBLE_EQ(EmulatedChangeSeconds(every, true), 40);
  EXPECT_DOUBLE_EQ(EmulatedChangeSeconds(every, false), 45);
  // A fresh cell is set up for its first trial.
  EXPECT_TRUE(schemas::ChangesBetween(std::nullopt, schemas::FixturesOf(all), costs).empty());
}

TEST(FixtureChanges, CostsMustBeFiniteAndNonNegative) {
  EXPECT_EQ(schemas::CheckChangeCosts({0, 5, 0}), "");
  EXPECT_EQ(schemas::CheckChangeCosts({-1, 5, 0}), "finger_s: must be finite and >= 0");
  EXPECT_EQ(schemas::CheckChangeCosts({0, std::nan(""), 0}), "pusher_s: must be finite and >= 0");
  EXPECT_EQ(schemas::CheckChangeCosts({0, 0, INFINITY}), "object_s: must be finite and >= 0");
}

TEST(FixtureChanges, ASimulatedCellReadsItsChangeTimesFromItsProfile) {
  const DefectProfile d = ParseDefectProfile(R"({"changes": {"finger_s": 6, "object_s": 4}})");
  EXPECT_DOUBLE_EQ(d.finger_change_s, 6);
  EXPECT_DOUBLE_EQ(d.object_change_s, 4);
  EXPECT_DOUBLE_EQ(ParseDefectProfile("{}").finger_change_s, 0);  // only the pusher swap
  auto error_of = [](const char* text) {
    try {
      ParseDefectProfile(text);
    } catch (const DefectError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of(R"({"changes": {"finger_s": -1}})").find("changes.finger_s"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"changes": {"pusher_s": 3}})").find("reset.swap_time"), std::string::npos);
  EXPECT_NE(error_of(R"({"changes": {"gripper_s": 3}})").find("gripper_s"), std::string::npos);
}

}  // namespace
}  // namespace arena::executors
