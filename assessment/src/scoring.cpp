#include "arena/assessment/scoring.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace arena::assessment {

namespace {
// A contact's normal direction is the same in prediction and truth, so the
// force difference is the normal magnitudes' difference plus the tangential
// vectors' difference, squared.
double ForceDifferenceSquared(const mechanics::ContactState& a, const mechanics::ContactState& b) {
  const double dn = a.normal_force - b.normal_force;
  return dn * dn + (a.tangential_force - b.tangential_force).squaredNorm();
}
double ForceSquared(const mechanics::ContactState& c) {
  return c.normal_force * c.normal_force + c.tangential_force.squaredNorm();
}
}  // namespace

PlanarOutcome PlanarOutcomeOf(const Eigen::Vector3d& start_position,
                              const Eigen::Quaterniond& start_orientation,
                              const Eigen::Vector3d& end_position,
                              const Eigen::Quaterniond& end_orientation) {
  const Eigen::Matrix3d r0 = start_orientation.normalized().toRotationMatrix();
  const Eigen::Vector3d d = r0.transpose() * (end_position - start_position);
  // The relative rotation's turn about the initial z axis (exact for a
  // planar push; the yaw of the relative rotation otherwise).
  const Eigen::Matrix3d rel = r0.transpose() * end_orientation.normalized().toRotationMatrix();
  return PlanarOutcome{d.x(), d.y(), std::atan2(rel(1, 0), rel(0, 0))};
}

std::optional<OutcomeNmse> ComputeNmse(const std::vector<PlanarOutcome>& predicted,
                                       const std::vector<PlanarOutcome>& truth, std::string* why) {
  if (predicted.size() != truth.size())
    throw std::invalid_argument("ComputeNmse: predicted and true outcome counts differ");
  const std::size_t n = truth.size();
  if (n < 2) {
    if (why) *why = "NMSE needs at least 2 trials, got " + std::to_string(n);
    return std::nullopt;
  }
  double out[3];
  static constexpr const char* kNames[3] = {"dx", "dy", "dtheta"};
  for (int k = 0; k < 3; ++k) {
    auto get = [k](const PlanarOutcome& o) { return k == 0 ? o.dx : k == 1 ? o.dy : o.dtheta; };
    double mean = 0;
    for (const auto& t : truth) mean += get(t) / static_cast<double>(n);
    double var = 0, mse = 0;
    for (std::size_t i = 0; i < n; ++i) {
      var += (get(truth[i]) - mean) * (get(truth[i]) - mean) / static_cast<double>(n);
      const double e = get(predicted[i]) - get(truth[i]);
      mse += e * e / static_cast<double>(n);
    }
    if (!(var > 0)) {
      if (why) *why = std::string("the true ") + kNames[k] + " does not vary across the trials";
      return std::nullopt;
    }
    out[k] = mse / var;
  }
  OutcomeNmse r;
  r.trials = static_cast<int>(n);
  r.dx = out[0];
  r.dy = out[1];
  r.dtheta = out[2];
  r.mean = (out[0] + out[1] + out[2]) / 3;
  return r;
}

PredictionError ScorePrediction(const std::vector<mechanics::TrajectorySample>& predicted,
                                const std::vector<mechanics::TrajectorySample>& truth) {
  PredictionError error;
  const size_t n = std::min(predicted.size(), truth.size());
  if (n == 0) return error;
  double force_diff = 0, force_sum = 0;
  long pairs = 0, agreeing = 0;
  for (size_t i = 0; i < n; ++i) {
    const auto& p = predicted[i];
    const auto& t = truth[i];
    // A truth sample without any contact is a measurement whose forces were
    // not recorded or failed their check (arena import; a simulated truth
    // always reports every contact): forces and modes are not scored, poses are.
    if (t.contacts.empty()) continue;
    if (p.contacts.size() != t.contacts.size()) {
      throw std::invalid_argument("ScorePrediction: sample " + std::to_string(i) + " has " +
                                  std::to_string(p.contacts.size()) + " predicted contacts but " +
                                  std::to_string(t.contacts.size()) + " measured");
    }
    for (size_t c = 0; c < p.contacts.size(); ++c) {
      force_diff += ForceDifferenceSquared(p.contacts[c], t.contacts[c]);
      force_sum += ForceSquared(t.contacts[c]);
      agreeing += p.contacts[c].mode == t.contacts[c].mode;
      ++pairs;
    }
  }
  const auto& p = predicted[n - 1];
  const auto& t = truth[n - 1];
  error.final_position = (p.position - t.position).norm();
  error.final_angle = p.orientation.normalized().angularDistance(t.orientation.normalized());
  if (pairs > 0) {
    error.force_rms = std::sqrt(force_diff / pairs);
    error.force_scale = std::sqrt(force_sum / pairs);
    error.mode_agreement = double(agreeing) / pairs;
  }
  error.predicted_outcome =
      PlanarOutcomeOf(predicted[0].position, predicted[0].orientation, p.position, p.orientation);
  error.true_outcome =
      PlanarOutcomeOf(truth[0].position, truth[0].orientation, t.position, t.orientation);
  error.samples_compared = static_cast<int>(n);
  error.contact_pairs = pairs;
  return error;
}

}  // namespace arena::assessment
