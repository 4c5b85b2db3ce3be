#include "arena/assessment/prediction.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <numbers>

#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "arena/assessment/predictor.hpp"
#include "arena/assessment/scoring.hpp"
#include "arena/mechanics/model.hpp"
#include "arena/mechanics/pusher_motion.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/simulators/simulator.hpp"

namespace arena::assessment {

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
  if (model.contains("contacts")) {
    const auto& m = model["contacts"];
    const auto mode =
        m.is_string() ? mechanics::ContactTrackingFromString(m.get<std::string>()) : std::nullopt;
    if (!mode) throw mechanics::SceneError("model.contacts", "must be tracked or fixed");
    out.model.contacts = *mode;
  }
  // Issue 31's choices; `cone` is arena's only for arena's model (MuJoCo's
  // predictor reads its own `cone`).
  const auto choice = [&](const char* key, const char* values, auto parse, auto* field) {
    if (!model.contains(key)) return;
    const auto& v = model[key];
    const auto parsed = v.is_string() ? parse(v.get<std::string>()) : std::nullopt;
    if (!parsed) throw mechanics::SceneError(std::string("model.") + key, values);
    *field = *parsed;
  };
  choice("pads", "must be elastic or rigid", mechanics::PadModelFromString, &out.model.pads);
  if (model.value("predictor", "arena") == "arena")
    choice("cone", "must be polyhedral or aligned", mechanics::ConeModelFromString,
           &out.model.cone);
  choice("inertia", "must be carried, quasi_static or auto", mechanics::InertiaModelFromString,
         &out.model.inertia);
  // A calibration (arena calibrate) resolved by SubmitCampaign: parameter scales.
  if (model.contains("calibrated")) {
    const auto& c = model["calibrated"];
    if (!c.is_object()) throw mechanics::SceneError("model.calibrated", "must be an object");
    std::map<std::string, double> scales;
    for (const auto& item : c.items()) {
      if (!item.value().is_number())
        throw mechanics::SceneError("model.calibrated." + item.key(), "must be a number");
      scales[item.key()] = item.value().get<double>();
    }
    try {
      out = ApplyScales(out, scales);
    } catch (const CalibrationError& e) {
      throw mechanics::SceneError("model.calibrated", e.what());
    }
  }
  mechanics::ValidateScene(out);
  return out;
}

std::string ModelKey(const mechanics::ModelOptions& m) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "g%d_k%d_dt%g_%s", m.facets, m.points, m.dt,
                mechanics::ToString(m.reduce));
  // Tracked contacts are the default; the frozen frame is named by a suffix
  // (stores written before tracking existed hold frozen-frame predictions
  // under the bare key).
  std::string key = buf;
  if (m.contacts == mechanics::ContactTracking::kFixed) key += "_fixed";
  // Every other knob that changes the answer is named when it is not the
  // key's baseline, so two settings that differ only there never share a
  // key (one would be taken for the other's stored prediction). The
  // baseline is fixed: elastic pads, the polyhedral cone and carried steps,
  // the defaults when the cone and the inertia were added (issue 31), so a
  // stored bare key keeps meaning them now that the aligned cone and "auto"
  // are the defaults (whose key names both).
  if (m.pads != mechanics::PadModel::kElastic)
    key += std::string("_pads-") + mechanics::ToString(m.pads);
  if (m.cone != mechanics::ConeModel::kPolyhedral)
    key += std::string("_cone-") + mechanics::ToString(m.cone);
  if (m.inertia != mechanics::InertiaModel::kCarried) {
    key += std::string("_inertia-") + mechanics::ToString(m.inertia);
  }
  return key;
}

std::string ModelSettingsJson(const mechanics::ModelOptions& model) {
  nlohmann::json settings({{"facets", model.facets},
                           {"points", model.points},
                           {"dt", model.dt},
                           {"reduce", mechanics::ToString(model.reduce)},
                           {"contacts", mechanics::ToString(model.contacts)},
                           // Whether the steps kept the momentum: it changes the answer.
                           {"inertia", mechanics::ToString(model.inertia)}});
  // Rigid pads where chosen, as ModelKey names them (earlier predictions'
  // settings stay the same), and the cone always since issue 31 made the
  // aligned cone the default: settings stored before without a "cone" are
  // the polyhedral cone's.
  if (model.pads != mechanics::PadModel::kElastic)
    settings["pads"] = mechanics::ToString(model.pads);
  settings["cone"] = mechanics::ToString(model.cone);
  return settings.dump();
}

const char* ToString(StartFrom from) {
  return from == StartFrom::kPlanned ? "planned" : "measured";
}

std::optional<StartFrom> StartFromString(std::string_view text) {
  if (text == "measured") return StartFrom::kMeasured;
  if (text == "planned") return StartFrom::kPlanned;
  return std::nullopt;
}

StartFrom StartFromOf(const nlohmann::json& prediction) {
  if (!prediction.is_object() || !prediction.contains("start")) return StartFrom::kMeasured;
  const auto& v = prediction["start"];
  const auto from = v.is_string() ? StartFromString(v.get<std::string>()) : std::nullopt;
  if (!from) throw mechanics::SceneError("prediction.start", "must be \"measured\" or \"planned\"");
  return *from;
}

PredictionStart StartOf(const mechanics::Scene& scene, const db::Sample* first, StartFrom from) {
  PredictionStart s;
  s.from = from;
  const Eigen::Vector3d planned_p = scene.object.pose.position;
  const Eigen::Quaterniond planned_q(mechanics::RotationFromRpy(scene.object.pose.rpy));
  s.position = planned_p;
  s.orientation = planned_q;
  if (from == StartFrom::kPlanned || first == nullptr) return s;
  const bool seen = first->observed_valid;
  const auto& pose = seen ? first->observed_object_pose : first->object_pose;
  s.source = seen ? "observed" : "first_sample";
  s.position = {pose[0], pose[1], pose[2]};
  s.orientation = Eigen::Quaterniond(pose[3], pose[4], pose[5], pose[6]).normalized();
  s.offset_m = (s.position - planned_p).norm();
  s.offset_rad = s.orientation.angularDistance(planned_q);
  return s;
}

mechanics::Scene StartedAt(const mechanics::Scene& scene, const PredictionStart& start) {
  // The planned pose, or a start the cell measured exactly there: the scene
  // as written (bit for bit, so such predictions stay shared and comparable).
  if (start.from == StartFrom::kPlanned || (start.offset_m == 0 && start.offset_rad == 0))
    return scene;
  mechanics::Scene out = scene;
  const Eigen::Matrix3d R = start.orientation.normalized().toRotationMatrix();
  out.object.pose.position = start.position;
  out.object.pose.rpy = {std::atan2(R(2, 1), R(2, 2)), std::asin(std::clamp(-R(2, 0), -1.0, 1.0)),
                         std::atan2(R(1, 0), R(0, 0))};
  try {
    mechanics::SeatFingers(&out);
  } catch (const mechanics::SceneError& e) {
    throw mechanics::SceneError(
        "start", std::string("the measured start pose (") + std::to_string(start.offset_m * 1e3) +
                     " mm, " + std::to_string(start.offset_rad * 180 / std::numbers::pi) +
                     " deg from the planned one) leaves the grasp: " + e.what());
  }
  return out;
}

void NoteStart(db::Prediction* p, const PredictionStart& start) {
  nlohmann::json detail = nlohmann::json::parse(p->detail_json, nullptr, false);
  if (!detail.is_object()) detail = nlohmann::json::object();
  detail["start"] = {{"from", ToString(start.from)},
                     {"source", start.source},
                     {"position_m", {start.position.x(), start.position.y(), start.position.z()}},
                     {"orientation_wxyz",
                      {start.orientation.w(), start.orientation.x(), start.orientation.y(),
                       start.orientation.z()}},
                     {"offset_m", start.offset_m},
                     {"offset_rad", start.offset_rad}};
  p->detail_json = detail.dump();
}

db::Prediction PredictionFailure(db::PredictionStatus status, const std::string& reason) {
  db::Prediction p;
  p.model_key = "unknown";
  p.status = status;
  p.detail_json = nlohmann::json({{"error", reason}}).dump();
  return p;
}

db::PredictionStatus StatusOf(mechanics::SimulationStatus status) {
  switch (status) {
    case mechanics::SimulationStatus::kOk:
      return db::PredictionStatus::kOk;
    case mechanics::SimulationStatus::kSolverFailure:
      return db::PredictionStatus::kSolverFailure;
    case mechanics::SimulationStatus::kInvalidScene:
      return db::PredictionStatus::kInvalidScene;
  }
  return db::PredictionStatus::kError;
}

namespace {

double LargestExtent(const mechanics::ObjectSpec& o) {
  if (o.shape == mechanics::ObjectShape::kCylinder) return std::max(2 * o.radius, o.height);
  return o.size.maxCoeff();
}

bool Finite(const mechanics::TrajectorySample& s) {
  if (!s.position.allFinite() || !s.velocity.allFinite() || !s.angular_velocity.allFinite() ||
      !s.orientation.coeffs().allFinite()) {
    return false;
  }
  for (const auto& c : s.contacts) {
    if (!std::isfinite(c.normal_force) || !c.tangential_force.allFinite()) return false;
  }
  return true;
}

// True when every finger (not the pusher) is separated.
bool AllFingersSeparated(const mechanics::TrajectorySample& s, std::size_t fingers) {
  if (fingers == 0 || s.contacts.size() < fingers) return false;
  for (std::size_t i = 0; i < fingers; ++i) {
    if (s.contacts[i].mode != mechanics::ContactMode::kSeparate) return false;
  }
  return true;
}

}  // namespace

std::optional<std::string> DivergenceReason(
    const mechanics::Scene& scene, const std::vector<mechanics::TrajectorySample>& predicted,
    const std::vector<mechanics::TrajectorySample>& truth) {
  if (predicted.empty()) return std::nullopt;
  double travel = 0, turn = 0;
  if (scene.pusher) {
    // A constant motion's speed, or a recorded path's fastest segment (its
    // velocity field is unused, zero): a bound on how far it can carry the
    // object.
    const mechanics::PusherTwist peak = mechanics::PusherPeakRates(*scene.pusher);
    travel = peak.velocity.norm() * scene.duration +
             peak.angular_velocity.norm() * scene.duration * LargestExtent(scene.object);
    turn = peak.angular_velocity.norm() * scene.duration;
  }
  const double reach = travel + LargestExtent(scene.object);
  const auto& start = predicted.front();
  char buf[200];
  for (const auto& s : predicted) {
    if (!Finite(s)) {
      std::snprintf(buf, sizeof buf, "diverged: a non-finite state at t = %.4g s", s.t);
      return std::string(buf);
    }
    const double moved = (s.position - start.position).norm();
    if (moved > reach) {
      std::snprintf(buf, sizeof buf,
                    "diverged: the object moved %.4g m by t = %.4g s, more than the pusher's "
                    "travel plus the object's extent (%.4g m)",
                    moved, s.t, reach);
      return std::string(buf);
    }
    const double turned =
        s.orientation.normalized().angularDistance(start.orientation.normalized());
    if (turned > M_PI / 2 + turn) {
      std::snprintf(buf, sizeof buf, "diverged: the object turned %.1f deg by t = %.4g s",
                    turned * 180 / M_PI, s.t);
      return std::string(buf);
    }
  }
  // Left the grasp: every finger separated over the last quarter of the
  // trajectory (at least 2 samples, so a contact flickering open at one
  // sample is not a drop) while the truth still held the object there.
  const std::size_t fingers = scene.fingers.size();
  const std::size_t n = truth.empty() ? 0 : std::min(truth.size(), predicted.size());
  const std::size_t tail = std::max<std::size_t>(2, n / 4);
  if (n >= tail) {
    bool dropped = true, held = false;
    for (std::size_t i = n - tail; i < n; ++i) {
      dropped = dropped && AllFingersSeparated(predicted[i], fingers);
      held = held || !AllFingersSeparated(truth[i], fingers);
    }
    if (dropped && held) {
      return std::string(
          "left the grasp: every finger separated over the last quarter while the truth still "
          "held it");
    }
  }
  return std::nullopt;
}

db::Prediction ScoreSimulation(const mechanics::Scene& scene,
                               const mechanics::SimulationResult& result,
                               const std::vector<mechanics::TrajectorySample>& truth) {
  db::Prediction p;
  nlohmann::json detail = {
      {"residuals",
       {{"force_balance", result.residuals.force_balance},
        {"complementarity", result.residuals.complementarity},
        {"cone", result.residuals.cone}}},
      {"solver", nlohmann::json::parse(mechanics::SolverStatisticsJson(result.solver))},
      {"unknowns", result.model.unknowns},
      {"dof", result.model.dof},
      // The inertia model the steps used ("auto" decided by the scene).
      {"inertia", mechanics::ToString(result.model.inertia)},
      {"grasp",
       {{"status", mechanics::ToString(result.grasp)},
        {"changed_t", result.grasp_changed_t},
        {"note", result.grasp_note}}}};
  // The final pose of a run that ends oscillating is one phase of it, and a
  // start that was an impact dt did not resolve may be on another branch:
  // said.
  detail.update(nlohmann::json::parse(mechanics::RunFlagsJson(result)));
  switch (result.status) {
    case mechanics::SimulationStatus::kOk:
      break;
    case mechanics::SimulationStatus::kSolverFailure:
    case mechanics::SimulationStatus::kInvalidScene:
      p.status = StatusOf(result.status);
      detail["error"] = result.error;
      p.detail_json = detail.dump();
      return p;
  }
  // A frozen-frame prediction whose fingers left the object ran outside the
  // model's validity: kept and listed like a divergence, never averaged in.
  std::optional<std::string> why;
  if (result.grasp == mechanics::GraspStatus::kLeftGeometry)
    why = "left the grasp geometry: " + result.grasp_note;
  else
    why = DivergenceReason(scene, result.samples, truth);
  if (why) {
    p.status = db::PredictionStatus::kDiverged;
    detail["error"] = *why;
    if (std::none_of(result.samples.begin(), result.samples.end(),
                     [](const auto& s) { return !Finite(s); })) {
      // Still scored (for the listing), never averaged in: status is not ok.
      try {
        const PredictionError e = ScorePrediction(result.samples, truth);
        p.final_position_error = e.final_position;
        p.final_angle_error = e.final_angle;
        if (e.contact_pairs > 0) {  // else the truth measured no force: not scored
          p.force_error = e.force_rms;
          p.mode_agreement = e.mode_agreement;
        }
      } catch (const std::exception&) {
      }
    }
    p.detail_json = detail.dump();
    return p;
  }
  try {
    const PredictionError e = ScorePrediction(result.samples, truth);
    p.final_position_error = e.final_position;
    p.final_angle_error = e.final_angle;
    if (e.contact_pairs > 0) {  // else the truth measured no force: not scored
      p.force_error = e.force_rms;
      p.mode_agreement = e.mode_agreement;
    } else {
      detail["force_not_scored"] = "the truth has no measured contact forces";
    }
    detail["samples_compared"] = e.samples_compared;
    // The push's outcome each made (initial frame), for the NMSE over trials.
    detail["outcome"] = {
        {"true", {e.true_outcome.dx, e.true_outcome.dy, e.true_outcome.dtheta}},
        {"predicted",
         {e.predicted_outcome.dx, e.predicted_outcome.dy, e.predicted_outcome.dtheta}}};
    detail["force_scale"] = e.force_scale;
  } catch (const std::exception& e) {
    p.status = db::PredictionStatus::kError;
    detail["error"] = e.what();
  }
  p.detail_json = detail.dump();
  return p;
}

db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth) {
  const auto start = std::chrono::steady_clock::now();
  const mechanics::SimulationResult result = mechanics::Simulate(scene);
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  db::Prediction p = ScoreSimulation(scene, result, truth);
  p.wall_s = wall;
  p.model_key = ModelKey(scene.model);
  p.model_json = ModelSettingsJson(scene.model);
  return p;
}

db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth,
                            const nlohmann::json& prediction) {
  return PredictTrial(scene, truth, prediction, nullptr);
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

mechanics::PusherCommandSource ReplayCommands(const RecordedCommands& commands) {
  return [&commands](const std::vector<mechanics::TrajectorySample>& samples,
                     std::string* why) -> std::optional<mechanics::PusherMotion> {
    const std::size_t k = samples.size() - 1;
    if (k >= commands.size()) {
      *why = "the recorded commands end at sample " + std::to_string(commands.size());
      return std::nullopt;
    }
    return commands[k];
  };
}

mechanics::Scene ReplayScoringScene(const mechanics::Scene& scene,
                                    const RecordedCommands& commands) {
  mechanics::Scene out = scene;
  if (!out.pusher) return out;
  for (const auto& c : commands) {
    if (c.velocity.norm() > out.pusher->motion.velocity.norm())
      out.pusher->motion.velocity = c.velocity;
  }
  return out;
}

db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth,
                            const nlohmann::json& prediction, const RecordedCommands* commands) {
  const bool mujoco = prediction.is_object() && prediction.value("predictor", "arena") == "mujoco";
  const bool closed_loop = scene.pusher && scene.pusher->controller;
  if (closed_loop && (commands == nullptr || commands->empty())) {
    return PredictionFailure(db::PredictionStatus::kError,
                             "closed-loop trial without recorded pusher commands");
  }
  if (closed_loop && !mujoco) {
    const auto start = std::chrono::steady_clock::now();
    const mechanics::SimulationResult result =
        mechanics::Simulate(scene, ReplayCommands(*commands));
    const double wall =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    db::Prediction p = ScoreSimulation(ReplayScoringScene(scene, *commands), result, truth);
    p.wall_s = wall;
    p.model_key = ModelKey(scene.model);
    p.model_json = ModelSettingsJson(scene.model);
    auto detail = nlohmann::json::parse(p.detail_json, nullptr, false);
    if (detail.is_object()) {
      detail["replayed_commands"] = commands->size();
      if (!result.stopped.empty()) detail["replay_stopped"] = result.stopped;
      p.detail_json = detail.dump();
    }
    return p;
  }
  if (!mujoco) return PredictTrial(scene, truth);
  nlohmann::json knobs = prediction;
  // A calibration's scales are already in `scene` (ApplyModelSettings).
  for (const char* k : {"predictor", "calibration", "calibrated", "start"}) knobs.erase(k);
  std::unique_ptr<simulators::Simulator> sim;
  try {
    sim = simulators::MakeSimulator("mujoco", knobs.dump());
  } catch (const std::exception& e) {
    return PredictionFailure(db::PredictionStatus::kError, e.what());
  }
  const auto start = std::chrono::steady_clock::now();
  mechanics::SimulationResult result;
  const std::string why = sim->CheckScene(scene);
  if (why.empty()) {
    result = closed_loop ? sim->SimulateClosedLoop(scene, ReplayCommands(*commands))
                         : sim->Simulate(scene);
  } else {
    result.status = mechanics::SimulationStatus::kInvalidScene;
    result.error = why;
  }
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  db::Prediction p =
      ScoreSimulation(closed_loop ? ReplayScoringScene(scene, *commands) : scene, result, truth);
  p.wall_s = wall;
  nlohmann::json stored = nlohmann::json::parse(sim->settings_json(), nullptr, false);
  if (!stored.is_object()) stored = nlohmann::json::object();
  stored["predictor"] = "mujoco";
  p.model_json = stored.dump();
  p.model_key = MujocoSettingKey(knobs);  // knobs were checked by MakeSimulator above
  return p;
}

PredictedRun SimulatePrediction(const mechanics::Scene& trial_scene,
                                const nlohmann::json& prediction, const RecordedCommands* commands,
                                const db::Sample* first) {
  PredictedRun run;
  run.start = StartOf(trial_scene, first, StartFromOf(prediction));
  run.scene = ApplyModelSettings(StartedAt(trial_scene, run.start), prediction);
  const bool mujoco = prediction.is_object() && prediction.value("predictor", "arena") == "mujoco";
  const bool closed_loop = run.scene.pusher && run.scene.pusher->controller;
  const bool replay = closed_loop && commands != nullptr && !commands->empty();
  const auto no_commands = [&run] {
    run.result.status = mechanics::SimulationStatus::kInvalidScene;
    run.result.error = "closed-loop trial without recorded pusher commands";
  };
  if (!mujoco) {
    run.predictor = "arena";
    run.key = ModelKey(run.scene.model);
    run.settings_json = ModelSettingsJson(run.scene.model);
    if (closed_loop && !replay)
      no_commands();
    else
      run.result = replay ? mechanics::Simulate(run.scene, ReplayCommands(*commands))
                          : mechanics::Simulate(run.scene);
    return run;
  }
  nlohmann::json knobs = prediction;
  // A calibration's scales are already in run.scene (ApplyModelSettings).
  for (const char* k : {"predictor", "calibration", "calibrated", "start"}) knobs.erase(k);
  const std::unique_ptr<simulators::Simulator> sim =
      simulators::MakeSimulator("mujoco", knobs.dump());
  run.predictor = "mujoco";
  run.key = MujocoSettingKey(knobs);
  nlohmann::json stored = nlohmann::json::parse(sim->settings_json(), nullptr, false);
  if (!stored.is_object()) stored = nlohmann::json::object();
  stored["predictor"] = "mujoco";
  run.settings_json = stored.dump();
  if (const std::string why = sim->CheckScene(run.scene); !why.empty()) {
    run.result.status = mechanics::SimulationStatus::kInvalidScene;
    run.result.error = why;
    return run;
  }
  if (closed_loop && !replay)
    no_commands();
  else
    run.result = replay ? sim->SimulateClosedLoop(run.scene, ReplayCommands(*commands))
                        : sim->Simulate(run.scene);
  return run;
}

}  // namespace arena::assessment
