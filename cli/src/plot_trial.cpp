#include "plot_trial.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <memory>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/assessment/truth.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "commands.hpp"
#include "deadline_report.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kRadToDeg = 180.0 / M_PI;

// One quantity's three sources, same layout as the pose panels.
struct Triple {
  std::vector<double> t_true, v_true, t_obs, v_obs, t_pred, v_pred;
};

Eigen::Quaterniond Quat(const std::array<double, 7>& pose) {
  return Eigen::Quaterniond(pose[3], pose[4], pose[5], pose[6]).normalized();
}

// Signed rotation from the start orientation q0 about `axis` (rad): the
// angle of q0^-1 q, negative when its axis points against `axis`.
double SignedAngle(const Eigen::Quaterniond& q0, const Eigen::Quaterniond& q,
                   const Eigen::Vector3d& axis) {
  const Eigen::AngleAxisd aa(q0.inverse() * q);
  const double a = aa.angle() > M_PI ? aa.angle() - 2 * M_PI : aa.angle();
  return aa.axis().dot(axis) < 0 ? -a : a;
}

// Normal and tangential magnitude of a force on the object along `n`.
void Split(const Eigen::Vector3d& f, const Eigen::Vector3d& n, double* normal, double* tangential) {
  *normal = f.dot(n);
  *tangential = (f - *normal * n).norm();
}

Panel PosePanel(const std::string& title, const std::string& unit, double min_span,
                const Triple& d) {
  Panel p;
  p.title = title;
  p.y_label = unit;
  p.min_y_span = min_span;
  p.series.push_back({"observed", d.t_obs, d.v_obs, "#6baed6", true, false});
  p.series.push_back({"true", d.t_true, d.v_true, "#222222", false, false});
  p.series.push_back({"predicted", d.t_pred, d.v_pred, "#e6550d", false, true});
  return p;
}

}  // namespace

namespace {
std::unique_ptr<db::Store> OpenReadOnly(const std::string& path) {
  try {
    db::StoreOptions so;
    so.read_only = true;
    so.create = false;
    return db::Store::Open(path, so);
  } catch (const db::StoreError& e) {
    throw CommandError(
        ExitCodeFor(e),
        std::string(e.what()) + " (is --db the store `arena serve` or `arena run` uses?)");
  }
}

// Writes next to the target and renames, so a reader never sees half an SVG.
}  // namespace

void WriteSvgFile(const Chart& chart, const std::string& out) {
  const std::string svg = RenderSvg(chart);
  const std::string tmp = out + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f)
      throw CommandError(kExitFailure, "cannot write " + tmp +
                                           ": check that its directory exists and is writable");
    f.write(svg.data(), static_cast<std::streamsize>(svg.size()));
    f.close();
    if (!f) throw CommandError(kExitFailure, "cannot write " + tmp + " (disk full?)");
  }
  if (std::rename(tmp.c_str(), out.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw CommandError(kExitFailure, "cannot rename " + tmp + " to " + out);
  }
}

int PlotTrial(const std::string& db_path, std::int64_t trial, const std::string& out) {
  if (trial < 0)
    throw CommandError(kExitBadInput, "give a TRIAL id to plot (find ids with `arena query --db " +
                                          db_path + " --campaign ID`)");
  auto store = OpenReadOnly(db_path);
  TrialPlotInfo info;
  const Chart chart = MakeTrialChart(*store, trial, &info);
  WriteSvgFile(chart, out);
  std::fprintf(stderr, "trial %lld: %zu samples, prediction %s (%s) -> %s\n",
               static_cast<long long>(trial), info.samples,
               info.model_key.empty() ? "-" : info.model_key.c_str(),
               db::ToString(info.prediction_status), out.c_str());
  return kExitOk;
}

Chart MakeTrialChart(const db::Store& store, std::int64_t trial_id, TrialPlotInfo* info) {
  db::Trial trial;
  db::Campaign campaign;
  db::GroundTruth gt;
  try {
    trial = store.GetTrial(trial_id);
    campaign = store.GetCampaign(trial.campaign_id);
  } catch (const db::StoreError& e) {
    if (e.kind() == db::StoreError::Kind::kNotFound)
      throw CommandError(kExitBadInput, "no trial " + std::to_string(trial_id) + " in " +
                                            store.path() +
                                            " (find trial ids with `arena query --db " +
                                            store.path() + " --campaign ID`)");
    throw StoreCommandError(e);
  }
  if (!trial.gt_stream_id && db::IsTerminal(trial.state)) {
    // Failed or cancelled before any ground truth was kept: there is
    // nothing to plot now or later, and nothing to watch.
    std::string why;
    try {
      const auto history = store.ListTransitions(trial_id);
      if (!history.empty()) why = history.back().reason;
    } catch (const db::StoreError&) {
    }
    throw CommandError(kExitBadInput,
                       "trial " + std::to_string(trial_id) + " " + db::ToString(trial.state) +
                           " without ground truth" + (why.empty() ? "" : " (" + why + ")") +
                           "; there is nothing to plot (`arena query --db " + store.path() +
                           " \"select * from trial_transitions where trial_id = " +
                           std::to_string(trial_id) + "\"` shows its history)");
  }
  if (!trial.gt_stream_id) {
    throw CommandError(
        kExitBadInput,
        "trial " + std::to_string(trial_id) + " has no ground truth yet (state " +
            db::ToString(trial.state) +
            "); plot it once it has executed (`arena status` shows progress), or watch it live "
            "with `arena watch " +
            std::to_string(trial_id) + "`");
  }
  gt = store.ReadGroundTruth(trial_id);
  if (gt.samples.empty())
    throw CommandError(kExitFailure,
                       "trial " + std::to_string(trial_id) + ": its ground truth has no samples");

  mechanics::Scene scene;
  try {
    scene = mechanics::ParseScene(trial.scene_json);
  } catch (const std::exception& e) {
    throw CommandError(
        kExitStore, "trial " + std::to_string(trial_id) + ": stored scene unreadable: " + e.what());
  }
  const auto normals = assessment::ContactNormals(scene);

  // The prediction, exactly as the service makes it: the campaign's
  // "prediction" settings applied to the trial's scene, on its predictor.
  TrialPlotInfo local;
  TrialPlotInfo& inf = info ? *info : local;
  inf.samples = gt.samples.size();
  mechanics::SimulationResult predicted;
  std::string prediction_note;
  try {
    nlohmann::json model;
    const auto spec = nlohmann::json::parse(campaign.spec_json);
    if (spec.is_object() && spec.contains("prediction")) model = spec["prediction"];
    // A closed-loop trial (issue 19) is predicted by replaying its applied commands.
    assessment::RecordedCommands commands;
    if (scene.pusher && scene.pusher->controller) {
      if (auto applied = store.GetClosedLoop(trial_id)) commands = assessment::CommandsOf(*applied);
    }
    // From the start the service's prediction took (the cell's measured start).
    assessment::PredictedRun run = assessment::SimulatePrediction(
        scene, model, &commands, gt.samples.empty() ? nullptr : &gt.samples.front());
    inf.model_key = run.key;
    predicted = std::move(run.result);
    inf.prediction_status = assessment::StatusOf(predicted.status);
    if (predicted.status != mechanics::SimulationStatus::kOk)
      prediction_note = "; " + predicted.error;
  } catch (const std::exception& e) {
    inf.prediction_status = db::PredictionStatus::kError;
    prediction_note = std::string("; ") + e.what();
    predicted.samples.clear();
  }

  // Rotation axis: the true final rotation from the start (z when the object barely turns).
  const Eigen::Quaterniond q0 = Quat(gt.samples.front().object_pose);
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  {
    const Eigen::AngleAxisd aa(q0.inverse() * Quat(gt.samples.back().object_pose));
    if (aa.angle() > 1e-4) axis = aa.axis();
    // Prefer the conventional sign: the axis's largest component positive.
    Eigen::Index k;
    axis.cwiseAbs().maxCoeff(&k);
    if (axis[k] < 0) axis = -axis;
  }

  Triple pos[3], angle;
  const size_t n_contacts = normals.size();
  const size_t n_fingers = scene.fingers.size();
  std::vector<Triple> normal(n_contacts), tangential(n_contacts);
  for (const auto& s : gt.samples) {
    for (int k = 0; k < 3; ++k) {
      pos[k].t_true.push_back(s.t);
      pos[k].v_true.push_back(s.object_pose[k] * 1e3);
    }
    angle.t_true.push_back(s.t);
    angle.v_true.push_back(SignedAngle(q0, Quat(s.object_pose), axis) * kRadToDeg);
    for (size_t c = 0; c < n_contacts && c < s.contacts.size(); ++c) {
      double fn, ft;
      Split({s.contacts[c].force[0], s.contacts[c].force[1], s.contacts[c].force[2]}, normals[c],
            &fn, &ft);
      normal[c].t_true.push_back(s.t);
      normal[c].v_true.push_back(fn);
      tangential[c].t_true.push_back(s.t);
      tangential[c].v_true.push_back(ft);
    }
    // Observed: a dropped sample leaves a gap (NaN is skipped by the chart).
    const bool ok = s.observed_valid;
    for (int k = 0; k < 3; ++k) {
      pos[k].t_obs.push_back(s.t);
      pos[k].v_obs.push_back(ok ? s.observed_object_pose[k] * 1e3 : kNaN);
    }
    angle.t_obs.push_back(s.t);
    angle.v_obs.push_back(ok ? SignedAngle(q0, Quat(s.observed_object_pose), axis) * kRadToDeg
                             : kNaN);
    for (size_t c = 0; c < n_contacts; ++c) {
      Eigen::Vector3d f;
      bool have = ok;
      if (c < n_fingers) {
        have = have && s.observed_finger_wrenches.size() >= 6 * (c + 1);
        if (have)
          f = {s.observed_finger_wrenches[6 * c], s.observed_finger_wrenches[6 * c + 1],
               s.observed_finger_wrenches[6 * c + 2]};
      } else if (have) {
        f = {s.observed_pusher_wrench[0], s.observed_pusher_wrench[1], s.observed_pusher_wrench[2]};
      }
      double fn = kNaN, ft = kNaN;
      if (have) Split(f, normals[c], &fn, &ft);
      normal[c].t_obs.push_back(s.t);
      normal[c].v_obs.push_back(fn);
      tangential[c].t_obs.push_back(s.t);
      tangential[c].v_obs.push_back(ft);
    }
  }
  for (const auto& s : predicted.samples) {
    for (int k = 0; k < 3; ++k) {
      pos[k].t_pred.push_back(s.t);
      pos[k].v_pred.push_back(s.position[k] * 1e3);
    }
    angle.t_pred.push_back(s.t);
    angle.v_pred.push_back(SignedAngle(q0, s.orientation, axis) * kRadToDeg);
    for (size_t c = 0; c < n_contacts && c < s.contacts.size(); ++c) {
      normal[c].t_pred.push_back(s.t);
      normal[c].v_pred.push_back(s.contacts[c].normal_force);
      tangential[c].t_pred.push_back(s.t);
      tangential[c].v_pred.push_back(s.contacts[c].tangential_force.norm());
    }
  }

  Chart chart;
  chart.title = "trial " + std::to_string(trial.id) + " (campaign " + std::to_string(campaign.id) +
                " '" + campaign.name + "', attempt " + std::to_string(gt.attempt) +
                (gt.cell_id.empty() ? "" : ", cell " + gt.cell_id) + ")  prediction " +
                (inf.model_key.empty() ? "-" : inf.model_key) +
                (inf.prediction_status == db::PredictionStatus::kOk
                     ? ""
                     : " " + std::string(db::ToString(inf.prediction_status)) + prediction_note);
  // A closed-loop trial says how many control deadlines it missed.
  if (scene.pusher && scene.pusher->controller) {
    if (const auto run = store.GetClosedLoop(trial_id)) chart.title += "; " + DeadlineCaption(*run);
  }
  chart.x_label = "time since execute started (s)";
  chart.panel_height = 150;
  const char* names[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k)
    chart.panels.push_back(PosePanel(
        std::string("object position ") + names[k] + " (gripper frame)", "mm", 1.0, pos[k]));
  char axis_text[96];
  std::snprintf(axis_text, sizeof axis_text, "object rotation from start, about (%.2f, %.2f, %.2f)",
                axis.x(), axis.y(), axis.z());
  chart.panels.push_back(PosePanel(axis_text, "deg", 1.0, angle));
  for (size_t c = 0; c < n_contacts; ++c) {
    Panel p;
    p.title = (c < n_fingers ? "finger " + std::to_string(c) + " (" +
                                   mechanics::ToString(scene.fingers[c].type) + ")"
                             : std::string("pusher")) +
              " contact force on the object";
    p.y_label = "N";
    p.min_y_span = 1.0;
    p.series.push_back(
        {"normal observed", normal[c].t_obs, normal[c].v_obs, "#6baed6", true, false});
    p.series.push_back(
        {"tangential observed", tangential[c].t_obs, tangential[c].v_obs, "#fdae6b", true, false});
    p.series.push_back(
        {"normal true", normal[c].t_true, normal[c].v_true, "#08519c", false, false});
    p.series.push_back(
        {"tangential true", tangential[c].t_true, tangential[c].v_true, "#a63603", false, false});
    p.series.push_back(
        {"normal predicted", normal[c].t_pred, normal[c].v_pred, "#3182bd", false, true});
    p.series.push_back({"tangential predicted", tangential[c].t_pred, tangential[c].v_pred,
                        "#e6550d", false, true});
    chart.panels.push_back(std::move(p));
  }
  return chart;
}

}  // namespace arena::cli
