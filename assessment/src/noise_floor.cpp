#include "arena/assessment/noise_floor.hpp"

#include <cmath>
#include <map>

#include "arena/assessment/evaluation.hpp"

namespace arena::assessment {

std::vector<ConditionSpread> ReplicateSpreads(const std::vector<FinalPose>& finals) {
  std::map<int, std::vector<const FinalPose*>> by_condition;
  for (const auto& f : finals) by_condition[f.condition].push_back(&f);
  std::vector<ConditionSpread> out;
  for (const auto& [condition, poses] : by_condition) {
    const std::size_t n = poses.size();
    if (n < 2) continue;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    Eigen::Vector4d q_sum = Eigen::Vector4d::Zero();
    const Eigen::Quaterniond first = poses.front()->orientation.normalized();
    for (const auto* p : poses) {
      mean += p->position;
      Eigen::Quaterniond q = p->orientation.normalized();
      if (q.dot(first) < 0) q.coeffs() = -q.coeffs();  // q and -q are one rotation
      q_sum += q.coeffs();
    }
    mean /= static_cast<double>(n);
    Eigen::Quaterniond q_mean;
    q_mean.coeffs() = q_sum.normalized();
    double position_sq = 0, angle_sq = 0;
    for (const auto* p : poses) {
      position_sq += (p->position - mean).squaredNorm();
      const double a = p->orientation.normalized().angularDistance(q_mean);
      angle_sq += a * a;
    }
    const double dof = static_cast<double>(n - 1);
    out.push_back(ConditionSpread{condition, static_cast<int>(n), std::sqrt(position_sq / dof),
                                  std::sqrt(angle_sq / dof)});
  }
  return out;
}

std::optional<NoiseFloor> ComputeNoiseFloor(const std::vector<FinalPose>& finals) {
  const auto spreads = ReplicateSpreads(finals);
  if (spreads.empty()) return std::nullopt;
  std::vector<double> position, angle;
  NoiseFloor floor;
  for (const auto& s : spreads) {
    position.push_back(s.position);
    angle.push_back(s.angle);
    floor.trials += s.replicates;
  }
  floor.conditions = static_cast<int>(spreads.size());
  floor.position_median = Percentile(position, 0.5);
  floor.position_p95 = Percentile(position, 0.95);
  floor.angle_median = Percentile(angle, 0.5);
  floor.angle_p95 = Percentile(angle, 0.95);
  return floor;
}

}  // namespace arena::assessment
