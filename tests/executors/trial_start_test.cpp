// The cell's start-pose and pusher rules (executors/src/trial_start.hpp).
#include "trial_start.hpp"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace arena::executors
