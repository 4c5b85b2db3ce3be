// Scoring a prediction against ground truth: how far the model's trajectory
// is from what the cell measured. Both are 250 Hz from t = 0 in the gripper
// frame; samples are paired by index, over the shorter of the two.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

// A push's outcome as planar pushing reports it: the object's final pose in
// its initial frame (dx, dy along the initial x and y axes, m; dtheta the
// rotation about the initial z axis, rad, in (-pi, pi]).
struct PlanarOutcome {
  double dx = 0, dy = 0, dtheta = 0;
};
PlanarOutcome PlanarOutcomeOf(const Eigen::Vector3d& start_position,
                              const Eigen::Quaterniond& start_orientation,
                              const Eigen::Vector3d& end_position,
                              const Eigen::Quaterniond& end_orientation);

// Normalised mean squared error of predicted outcomes against true ones over
// a set of trials: per output (dx, dy, dtheta), the mean squared error over
// the variance of the true output across the set (population variance,
// divided by n), and their mean. A model that always predicts the set's mean
// outcome scores 1; a perfect one 0.
struct OutcomeNmse {
  int trials = 0;
  double dx = 0, dy = 0, dtheta = 0;
  double mean = 0;
};
// Absent (with `why` set) for fewer than 2 trials or an output that does not
// vary across them (its NMSE would divide by zero).
std::optional<OutcomeNmse> ComputeNmse(const std::vector<PlanarOutcome>& predicted,
                                       const std::vector<PlanarOutcome>& truth,
                                       std::string* why = nullptr);

struct PredictionError {
  double final_position = 0;  // m, |p_pred - p_true| at the last paired sample
  double final_angle = 0;     // rad, rotation between predicted and true orientation there
  double force_rms = 0;       // N, RMS over samples and contacts of |f_pred - f_true|
                              //    (normal and tangential parts, on the object)
  double force_scale = 0;     // N, RMS of |f_true| over the same pairs (to normalise)
  double mode_agreement = 1;  // fraction of (sample, contact) pairs with the same mode
  int samples_compared = 0;
  // (sample, contact) pairs whose forces were compared; 0: the truth measured
  // no force (force_rms and mode_agreement then mean nothing: not scored).
  long contact_pairs = 0;
  // The outcome each made, each from its own first sample to the last paired one.
  PlanarOutcome predicted_outcome, true_outcome;
};

// @pre every sample of both has the same number of contacts.
// @throws std::invalid_argument if they do not (a scene mismatch).
PredictionError ScorePrediction(const std::vector<mechanics::TrajectorySample>& predicted,
                                const std::vector<mechanics::TrajectorySample>& truth);

}  // namespace arena::assessment
