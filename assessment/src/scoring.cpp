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
  error.samples_compared = static_cast<int>(n);
  error.contact_pairs = pairs;
  return error;
}

}  // namespace arena::assessment
