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
#include "command_error.hpp"
#include "deadline_report.hpp"
#include "plotted_trial.hpp"
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

// Rotation axis: the true final rotation from the start (z when the object
// barely turns), with the conventional sign (its largest component positive).
Eigen::Vector3d RotationAxis(const db::GroundTruth& gt) {
  const Eigen::Quaterniond q0 = Quat(gt.samples.front().object_pose);
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  const Eigen::AngleAxisd aa(q0.inverse() * Quat(gt.samples.back().object_pose));
  if (aa.angle() > 1e-4) axis = aa.axis();
  Eigen::Index k;
  axis.cwiseAbs().maxCoeff(&k);
  if (axis[k] < 0) axis = -axis;
  return axis;
}

// The plotted quantities: object position (mm), rotation about the axis
// (deg), and each contact's normal and tangential force (N).
struct TrialSeries {
  Triple pos[3], angle;
  std::vector<Triple> normal, tangential;
};

// One contact's observed force on the object (false: not observed).
bool ObservedForce(const db::Sample& s, std::size_t c, std::size_t n_fingers, Eigen::Vector3d* f) {
  if (!s.observed_valid) return false;
  if (c < n_fingers) {
    if (s.observed_finger_wrenches.size() < 6 * (c + 1)) return false;
    *f = {s.observed_finger_wrenches[6 * c], s.observed_finger_wrenches[6 * c + 1],
          s.observed_finger_wrenches[6 * c + 2]};
  } else {
    *f = {s.observed_pusher_wrench[0], s.observed_pusher_wrench[1], s.observed_pusher_wrench[2]};
  }
  return true;
}

// The true and the observed series of one ground-truth sample.
void AddTruthSample(const db::Sample& s, const Eigen::Quaterniond& q0, const Eigen::Vector3d& axis,
                    const std::vector<Eigen::Vector3d>& normals, std::size_t n_fingers,
                    TrialSeries* d) {
  const std::size_t n_contacts = normals.size();
  for (int k = 0; k < 3; ++k) {
    d->pos[k].t_true.push_back(s.t);
    d->pos[k].v_true.push_back(s.object_pose[k] * 1e3);
  }
  d->angle.t_true.push_back(s.t);
  d->angle.v_true.push_back(SignedAngle(q0, Quat(s.object_pose), axis) * kRadToDeg);
  for (size_t c = 0; c < n_contacts && c < s.contacts.size(); ++c) {
    double fn, ft;
    Split({s.contacts[c].force[0], s.contacts[c].force[1], s.contacts[c].force[2]}, normals[c], &fn,
          &ft);
    d->normal[c].t_true.push_back(s.t);
    d->normal[c].v_true.push_back(fn);
    d->tangential[c].t_true.push_back(s.t);
    d->tangential[c].v_true.push_back(ft);
  }
  // Observed: a dropped sample leaves a gap (NaN is skipped by the chart).
  const bool ok = s.observed_valid;
  for (int k = 0; k < 3; ++k) {
    d->pos[k].t_obs.push_back(s.t);
    d->pos[k].v_obs.push_back(ok ? s.observed_object_pose[k] * 1e3 : kNaN);
  }
  d->angle.t_obs.push_back(s.t);
  d->angle.v_obs.push_back(ok ? SignedAngle(q0, Quat(s.observed_object_pose), axis) * kRadToDeg
                              : kNaN);
  for (size_t c = 0; c < n_contacts; ++c) {
    Eigen::Vector3d f;
    double fn = kNaN, ft = kNaN;
    if (ObservedForce(s, c, n_fingers, &f)) Split(f, normals[c], &fn, &ft);
    d->normal[c].t_obs.push_back(s.t);
    d->normal[c].v_obs.push_back(fn);
    d->tangential[c].t_obs.push_back(s.t);
    d->tangential[c].v_obs.push_back(ft);
  }
}

void AddPredictedSamples(const mechanics::SimulationResult& predicted, const Eigen::Quaterniond& q0,
                         const Eigen::Vector3d& axis, TrialSeries* d) {
  const std::size_t n_contacts = d->normal.size();
  for (const auto& s : predicted.samples) {
    for (int k = 0; k < 3; ++k) {
      d->pos[k].t_pred.push_back(s.t);
      d->pos[k].v_pred.push_back(s.position[k] * 1e3);
    }
    d->angle.t_pred.push_back(s.t);
    d->angle.v_pred.push_back(SignedAngle(q0, s.orientation, axis) * kRadToDeg);
    for (size_t c = 0; c < n_contacts && c < s.contacts.size(); ++c) {
      d->normal[c].t_pred.push_back(s.t);
      d->normal[c].v_pred.push_back(s.contacts[c].normal_force);
      d->tangential[c].t_pred.push_back(s.t);
      d->tangential[c].v_pred.push_back(s.contacts[c].tangential_force.norm());
    }
  }
}

Panel ContactPanel(const std::string& contact, const Triple& normal, const Triple& tangential) {
  Panel p;
  p.title = contact + " contact force on the object";
  p.y_label = std::string("N");  // not operator=(const char*): GCC 12 -Wrestrict false positive
  p.min_y_span = 1.0;
  p.series.push_back({"normal observed", normal.t_obs, normal.v_obs, "#6baed6", true, false});
  p.series.push_back(
      {"tangential observed", tangential.t_obs, tangential.v_obs, "#fdae6b", true, false});
  p.series.push_back({"normal true", normal.t_true, normal.v_true, "#08519c", false, false});
  p.series.push_back(
      {"tangential true", tangential.t_true, tangential.v_true, "#a63603", false, false});
  p.series.push_back({"normal predicted", normal.t_pred, normal.v_pred, "#3182bd", false, true});
  p.series.push_back(
      {"tangential predicted", tangential.t_pred, tangential.v_pred, "#e6550d", false, true});
  return p;
}

std::string ChartTitle(const db::Store& store, const PlottedTrial& p, const TrialPlotInfo& inf,
                       const std::string& reason) {
  std::string title = "trial " + std::to_string(p.trial.id) + " (campaign " +
                      std::to_string(p.campaign.id) + " '" + p.campaign.name + "', attempt " +
                      std::to_string(p.gt.attempt) +
                      (p.gt.cell_id.empty() ? "" : ", cell " + p.gt.cell_id) + ")  prediction " +
                      (inf.model_key.empty() ? "-" : inf.model_key) +
                      (inf.prediction_status == db::PredictionStatus::kOk
                           ? ""
                           : " " + std::string(db::ToString(inf.prediction_status)) +
                                 (reason.empty() ? "" : "; " + reason));
  // A closed-loop trial says how many control deadlines it missed.
  if (p.scene.pusher && p.scene.pusher->controller) {
    if (const auto run = store.GetClosedLoop(p.trial.id)) title += "; " + DeadlineCaption(*run);
  }
  return title;
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
  const PlottedTrial p = LoadPlottedTrial(store, trial_id);
  const auto normals = assessment::ContactNormals(p.scene);
  TrialPlotInfo local;
  TrialPlotInfo& inf = info ? *info : local;
  inf.samples = p.gt.samples.size();
  std::string reason;
  const mechanics::SimulationResult predicted = PredictPlottedTrial(store, p, &inf, &reason);

  const Eigen::Quaterniond q0 = Quat(p.gt.samples.front().object_pose);
  const Eigen::Vector3d axis = RotationAxis(p.gt);
  const std::size_t n_fingers = p.scene.fingers.size();
  TrialSeries d;
  d.normal.resize(normals.size());
  d.tangential.resize(normals.size());
  for (const auto& s : p.gt.samples) AddTruthSample(s, q0, axis, normals, n_fingers, &d);
  AddPredictedSamples(predicted, q0, axis, &d);

  Chart chart;
  chart.title = ChartTitle(store, p, inf, reason);
  chart.x_label = "time since execute started (s)";
  chart.panel_height = 150;
  const char* names[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k)
    chart.panels.push_back(PosePanel(
        std::string("object position ") + names[k] + " (gripper frame)", "mm", 1.0, d.pos[k]));
  char axis_text[96];
  std::snprintf(axis_text, sizeof axis_text, "object rotation from start, about (%.2f, %.2f, %.2f)",
                axis.x(), axis.y(), axis.z());
  chart.panels.push_back(PosePanel(axis_text, "deg", 1.0, d.angle));
  for (size_t c = 0; c < normals.size(); ++c) {
    const std::string contact = c < n_fingers
                                    ? "finger " + std::to_string(c) + " (" +
                                          mechanics::ToString(p.scene.fingers[c].type) + ")"
                                    : std::string("pusher");
    chart.panels.push_back(ContactPanel(contact, d.normal[c], d.tangential[c]));
  }
  return chart;
}

}  // namespace arena::cli
