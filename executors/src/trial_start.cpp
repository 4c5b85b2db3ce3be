// A cell's start-pose and pusher rules; the contract is in trial_start.hpp.
#include "trial_start.hpp"

#include <algorithm>
#include <cmath>

#include "arena/mechanics/frames.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace arena::executors {

PusherChange ChangeOfPusher(const std::optional<mechanics::PusherSpec>& now,
                            const std::optional<mechanics::PusherSpec>& next) {
  if (now.has_value() != next.has_value()) return {true, 0};
  if (!now) return {};
  const bool same_tool = now->type == next->type && now->length == next->length &&
                         now->radius == next->radius && now->axis == next->axis &&
                         now->normal == next->normal;
  if (!same_tool) return {true, 0};
  return {false, (next->position - now->position).norm()};
}

double EmulatedChangeSeconds(const std::vector<schemas::FixtureChange>& changes, bool in_reset) {
  double s = 0;
  for (const auto& c : changes) {
    if (in_reset && c.what == "pusher") continue;  // the reset plan's swap_pusher primitive
    s += c.seconds;
  }
  return s;
}

bool ChangesPusher(const std::vector<schemas::FixtureChange>& changes) {
  return std::any_of(changes.begin(), changes.end(),
                     [](const schemas::FixtureChange& c) { return c.what == "pusher"; });
}

void TrialStart::ResetEnded(std::uint64_t seed, const reset::Pose& target,
                            const reset::Pose& pose) {
  left_ = Left{seed, target, pose};
}

std::optional<reset::Pose> TrialStart::StartPose(std::uint64_t seed, const reset::Pose& target,
                                                 const reset::ResetParams& params,
                                                 bool emulated) const {
  if (!emulated) return std::nullopt;
  if (left_ && left_->seed == seed && left_->target.position == target.position &&
      left_->target.orientation.coeffs() == target.orientation.coeffs()) {
    return left_->pose;
  }
  return reset::PlacementForTrial(target, params, seed).true_pose;
}

mechanics::Scene TrialStart::PlacedAt(mechanics::Scene scene,
                                      const std::optional<reset::Pose>& start) {
  if (!start) return scene;  // the planned pose
  const Eigen::Matrix3d R = start->orientation.normalized().toRotationMatrix();
  scene.object.pose.position = start->position;
  scene.object.pose.rpy = mechanics::RpyFromRotation(R);
  mechanics::SeatFingers(&scene);  // throws SceneError when a finger misses the object
  return scene;
}

}  // namespace arena::executors
