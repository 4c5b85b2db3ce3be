#include "arena/assessment/convergence.hpp"

#include <cmath>

#include <Eigen/Geometry>

#include "arena/mechanics/scene_json.hpp"

namespace arena::assessment {

std::optional<mechanics::Scene> RestartScene(const mechanics::Scene& scene,
                                             const mechanics::TrajectorySample& from,
                                             double duration) {
  mechanics::Scene s = scene;
  s.duration = duration;
  s.object.pose.position = from.position;
  // rpy about fixed x, y, z: R = Rz(yaw) Ry(pitch) Rx(roll).
  const Eigen::Matrix3d r = from.orientation.normalized().toRotationMatrix();
  const Eigen::Vector3d ypr = r.eulerAngles(2, 1, 0);
  s.object.pose.rpy = {ypr[2], ypr[1], ypr[0]};
  if (s.pusher) s.pusher->position = from.pusher_position;
  if (s.model.dt > duration) s.model.dt = duration;
  try {
    mechanics::ValidateScene(s);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  return s;
}

namespace {

Distribution Spread(std::vector<double> v) {
  Distribution d;
  if (v.empty()) return d;
  d.median = Percentile(v, 0.5);
  d.p95 = Percentile(v, 0.95);
  d.max = *std::max_element(v.begin(), v.end());
  return d;
}

}  // namespace

std::vector<std::optional<Convergence>> ConvergenceTable(
    const Predictor& predictor, const std::vector<ConvergenceTrial>& trials, int pieces) {
  const auto& settings = predictor.settings();
  const std::size_t finest = FinestSetting(predictor);
  std::vector<std::vector<double>> position(settings.size()), angle(settings.size());
  for (const auto& t : trials) {
    if (t.truth.size() < 2 || pieces < 1) continue;
    const double total = t.truth.back().t;
    const double piece = total / pieces;
    if (!(piece > 0)) continue;
    for (int k = 0; k < pieces; ++k) {
      const auto from_index = static_cast<std::size_t>(
          std::min<double>(std::round(k * piece / total * (t.truth.size() - 1)),
                           static_cast<double>(t.truth.size() - 1)));
      const auto restart = RestartScene(t.scene, t.truth[from_index], piece);
      if (!restart) continue;
      const auto reference = predictor.Run(*restart, finest);
      if (reference.status != mechanics::SimulationStatus::kOk || reference.samples.empty())
        continue;
      const auto& ref_end = reference.samples.back();
      for (std::size_t i = 0; i < settings.size(); ++i) {
        if (i == finest) {
          position[i].push_back(0);
          angle[i].push_back(0);
          continue;
        }
        const auto r = predictor.Run(*restart, i);
        if (r.status != mechanics::SimulationStatus::kOk || r.samples.empty()) continue;
        const auto& end = r.samples[std::min(r.samples.size(), reference.samples.size()) - 1];
        const auto& ref =
            reference.samples[std::min(r.samples.size(), reference.samples.size()) - 1];
        (void)ref_end;
        if (!end.position.allFinite()) continue;
        position[i].push_back((end.position - ref.position).norm());
        angle[i].push_back(
            end.orientation.normalized().angularDistance(ref.orientation.normalized()));
      }
    }
  }
  std::vector<std::optional<Convergence>> out(settings.size());
  for (std::size_t i = 0; i < settings.size(); ++i) {
    if (position[i].empty()) continue;
    out[i] =
        Convergence{static_cast<int>(position[i].size()), Spread(position[i]), Spread(angle[i])};
  }
  return out;
}

}  // namespace arena::assessment
