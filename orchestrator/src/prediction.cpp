#include "arena/orchestrator/prediction.hpp"

#include "arena/db/prediction_status.hpp"

#include <chrono>
#include <cstdio>

#include <nlohmann/json.hpp>

#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/scoring.hpp"

namespace arena::orchestrator {

mechanics::Scene ApplyModelSettings(const mechanics::Scene& scene, const nlohmann::json& model) {
  mechanics::Scene out = scene;
  if (model.is_null()) return out;
  if (!model.is_object()) throw mechanics::SceneError("model", "must be an object");
  auto number = [&](const char* key) -> const nlohmann::json* {
    if (!model.contains(key)) return nullptr;
    const auto& v = model[key];
    if (!v.is_number())
      throw mechanics::SceneError(std::string("model.") + key, "must be a number");
    return &v;
  };
  if (const auto* v = number("facets")) {
    if (!v->is_number_integer()) throw mechanics::SceneError("model.facets", "must be an integer");
    out.model.facets = v->get<int>();
  }
  if (const auto* v = number("points")) {
    if (!v->is_number_integer()) throw mechanics::SceneError("model.points", "must be an integer");
    out.model.points = v->get<int>();
  }
  if (const auto* v = number("dt")) out.model.dt = v->get<double>();
  if (model.contains("reduce")) {
    const auto& r = model["reduce"];
    const std::string s = r.is_string() ? r.get<std::string>() : "";
    if (s == "auto")
      out.model.reduce = mechanics::Reduce::kAuto;
    else if (s == "full")
      out.model.reduce = mechanics::Reduce::kFull;
    else if (s == "planar")
      out.model.reduce = mechanics::Reduce::kPlanar;
    else
      throw mechanics::SceneError("model.reduce", "must be auto, full or planar");
  }
  mechanics::ValidateScene(out);
  return out;
}

std::string ModelKey(const mechanics::ModelOptions& m) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "g%d_k%d_dt%g_%s", m.facets, m.points, m.dt,
                mechanics::ToString(m.reduce));
  return buf;
}

db::Prediction PredictionFailure(const std::string& status, const std::string& reason) {
  db::Prediction p;
  p.model_key = "unknown";
  p.status = status;
  p.detail_json = nlohmann::json({{"error", reason}}).dump();
  return p;
}

db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth) {
  return PredictTrial(scene, truth, nullptr);
}

RecordedCommands CommandsOf(const db::ClosedLoopRun& run) {
  RecordedCommands out;
  for (const auto& c : run.commands) {
    if (c.sample < 0) continue;
    if (static_cast<std::size_t>(c.sample) >= out.size()) out.resize(c.sample + 1);
    out[c.sample].velocity = {c.commanded[0], c.commanded[1], c.commanded[2]};
  }
  return out;
}

db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth,
                            const RecordedCommands* commands) {
  const bool closed_loop = scene.pusher && scene.pusher->controller;
  if (closed_loop && (commands == nullptr || commands->empty())) {
    return PredictionFailure("error", "closed-loop trial without recorded pusher commands");
  }
  db::Prediction p;
  p.model_key = ModelKey(scene.model);
  p.model_json = nlohmann::json({{"facets", scene.model.facets},
                                 {"points", scene.model.points},
                                 {"dt", scene.model.dt},
                                 {"reduce", mechanics::ToString(scene.model.reduce)}})
                     .dump();
  const auto start = std::chrono::steady_clock::now();
  const mechanics::SimulationResult result =
      closed_loop ? mechanics::Simulate(
                        scene,
                        [commands](const std::vector<mechanics::TrajectorySample>& samples,
                                   std::string* why) -> std::optional<mechanics::PusherMotion> {
                          const std::size_t k = samples.size() - 1;
                          if (k >= commands->size()) {
                            *why = "the recorded commands end at sample " +
                                   std::to_string(commands->size());
                            return std::nullopt;
                          }
                          return (*commands)[k];
                        })
                  : mechanics::Simulate(scene);
  p.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  nlohmann::json detail = {{"residuals",
                            {{"force_balance", result.residuals.force_balance},
                             {"complementarity", result.residuals.complementarity},
                             {"cone", result.residuals.cone}}},
                           {"solver",
                            {{"steps", result.solver.steps},
                             {"max_pivots", result.solver.max_pivots},
                             {"failures", result.solver.failures}}},
                           {"unknowns", result.model.unknowns},
                           {"dof", result.model.dof}};
  if (closed_loop) detail["replayed_commands"] = commands->size();
  switch (result.status) {
    case mechanics::SimulationStatus::kOk:
      break;
    case mechanics::SimulationStatus::kSolverFailure:
      p.status = db::ToString(db::PredictionStatus::kSolverFailure);
      detail["error"] = result.error;
      p.detail_json = detail.dump();
      return p;
    case mechanics::SimulationStatus::kInvalidScene:
      p.status = db::ToString(db::PredictionStatus::kInvalidScene);
      detail["error"] = result.error;
      p.detail_json = detail.dump();
      return p;
  }
  try {
    const PredictionError e = ScorePrediction(result.samples, truth);
    p.final_position_error = e.final_position;
    p.final_angle_error = e.final_angle;
    p.force_error = e.force_rms;
    p.mode_agreement = e.mode_agreement;
    detail["samples_compared"] = e.samples_compared;
    detail["force_scale"] = e.force_scale;
  } catch (const std::exception& e) {
    p.status = db::ToString(db::PredictionStatus::kError);
    detail["error"] = e.what();
  }
  p.detail_json = detail.dump();
  return p;
}

}  // namespace arena::orchestrator
