// The noise floor: how much replicates of one condition differ. Replicates
// run exactly the same scene; their true final poses still differ (sensing
// and actuation noise, friction variability, reset error), and no
// deterministic predictor can beat that spread. Every error of `arena
// evaluate` is reported beside it and as a multiple of it.
//
// Per condition with n >= 2 replicates: the spread is the root mean square
// distance of the replicates' final positions from their mean, with
// Bessel's correction, s = sqrt(Σ|p_i − p̄|² / (n − 1)); likewise for the
// orientation with the angle to the mean orientation (the normalised sum of
// the quaternions, signs aligned). It estimates the error of an ideal
// predictor that predicts each condition's mean. The floor is the median and
// 95th percentile of the spreads over conditions.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace arena::assessment {

struct FinalPose {
  std::int64_t trial_id = 0;
  int condition = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
};

struct ConditionSpread {
  int condition = 0;
  int replicates = 0;
  double position = 0;  // m
  double angle = 0;     // rad
};

struct NoiseFloor {
  int conditions = 0;                            // with >= 2 replicates
  int trials = 0;                                // in those conditions
  double position_median = 0, position_p95 = 0;  // m
  double angle_median = 0, angle_p95 = 0;        // rad
};

// One spread per condition that has >= 2 finals, in condition order.
std::vector<ConditionSpread> ReplicateSpreads(const std::vector<FinalPose>& finals);

// Absent when no condition has two replicates.
std::optional<NoiseFloor> ComputeNoiseFloor(const std::vector<FinalPose>& finals);

}  // namespace arena::assessment
