// Scoring a prediction against ground truth: how far the model's trajectory
// is from what the cell measured. Both are 250 Hz from t = 0 in the gripper
// frame; samples are paired by index, over the shorter of the two.
#pragma once

#include <vector>

#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

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
};

// @pre every sample of both has the same number of contacts.
// @throws std::invalid_argument if they do not (a scene mismatch).
PredictionError ScorePrediction(const std::vector<mechanics::TrajectorySample>& predicted,
                                const std::vector<mechanics::TrajectorySample>& truth);

}  // namespace arena::assessment
