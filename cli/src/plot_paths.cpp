// `arena plot --db DB TRIAL --paths`: the trial seen from above (plot_trial.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/assessment/truth.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "commands.hpp"
#include "plot_trial.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;
const char* const kMeasured = "#222222";
const char* const kPredicted = "#e6550d";
const char* const kPusher = "#c0392b";

std::string F(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f", v);
  return b;
}

std::string Mm(double m, int digits = 3) { return FormatNumber(m * 1e3, digits) + " mm"; }

// The object's outline in its own frame, in its x-y plane (a prism's
// polygon, a box's rectangle, a cylinder's circle).
std::vector<Vector3d> Outline(const mechanics::ObjectSpec& o) {
  std::vector<Vector3d> out;
  switch (o.shape) {
    case mechanics::ObjectShape::kBox:
      out = {{-o.size.x() / 2, -o.size.y() / 2, 0},
             {o.size.x() / 2, -o.size.y() / 2, 0},
             {o.size.x() / 2, o.size.y() / 2, 0},
             {-o.size.x() / 2, o.size.y() / 2, 0}};
      break;
    case mechanics::ObjectShape::kCylinder:
      for (int k = 0; k < 48; ++k)
        out.emplace_back(o.radius * std::cos(2 * kPi * k / 48),
                         o.radius * std::sin(2 * kPi * k / 48), 0);
      break;
    default:
      for (const auto& v : o.polygon) out.emplace_back(v.x(), v.y(), 0);
      break;
  }
  return out;
}

struct Pose2 {
  Vector3d position;
  Eigen::Quaterniond orientation;
};

// Top view: x right, y up, at one scale.
struct Canvas {
  double x0, y0, w, h, scale;
  Vector2d centre;
  Vector2d Px(const Vector3d& p) const {
    return {x0 + w / 2 + (p.x() - centre.x()) * scale, y0 + h / 2 - (p.y() - centre.y()) * scale};
  }
};

std::string Polyline(const Canvas& c, const std::vector<Vector3d>& pts, const std::string& color,
                     double width, bool dashed, bool closed, const std::string& fill = "none",
                     double opacity = 1) {
  std::string d;
  for (const auto& p : pts) d += F(c.Px(p).x()) + "," + F(c.Px(p).y()) + " ";
  return std::string("<") + (closed ? "polygon" : "polyline") + " points=\"" + d + "\" fill=\"" +
         fill + "\" fill-opacity=\"0.12\" stroke=\"" + color + "\" stroke-width=\"" + F(width) +
         "\" stroke-opacity=\"" + FormatNumber(opacity, 3) + "\"" +
         (dashed ? " stroke-dasharray=\"6,4\"" : "") + "/>";
}

std::string Text(const Vector2d& at, const std::string& text, const std::string& color,
                 const char* anchor = "start", int size = 12) {
  return "<text x=\"" + F(at.x()) + "\" y=\"" + F(at.y()) + "\" font-size=\"" +
         std::to_string(size) + "\" text-anchor=\"" + anchor + "\" fill=\"" + color + "\">" +
         SvgEscape(text) + "</text>";
}

std::vector<Vector3d> Placed(const std::vector<Vector3d>& outline, const Pose2& pose) {
  std::vector<Vector3d> out;
  for (const auto& v : outline) out.push_back(pose.position + pose.orientation * v);
  return out;
}

double Yaw(const Eigen::Quaterniond& q) {
  const Eigen::Matrix3d r = q.normalized().toRotationMatrix();
  return std::atan2(r(1, 0), r(0, 0));
}

// A round length of about a quarter of `view_m`.
double ScaleBarLength(double view_m) {
  const double target = view_m / 4;
  const double p = std::pow(10.0, std::floor(std::log10(target)));
  for (double m : {5.0, 2.0, 1.0})
    if (m * p <= target) return m * p;
  return p;
}

}  // namespace

std::string TrialPathsSvg(const db::Store& store, std::int64_t trial_id, TrialPlotInfo* info) {
  db::Trial trial;
  db::Campaign campaign;
  db::GroundTruth gt;
  try {
    trial = store.GetTrial(trial_id);
    campaign = store.GetCampaign(trial.campaign_id);
    if (!trial.gt_stream_id)
      throw CommandError(kExitBadInput, "trial " + std::to_string(trial_id) + " (" +
                                            db::ToString(trial.state) +
                                            ") has no ground truth: there is no path to plot");
    gt = store.ReadGroundTruth(trial_id);
  } catch (const db::StoreError& e) {
    if (e.kind() == db::StoreError::Kind::kNotFound)
      throw CommandError(kExitBadInput, "no trial " + std::to_string(trial_id) + " in " +
                                            store.path() + " (find trial ids with `arena query`)");
    throw StoreCommandError(e);
  }
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

  // The prediction as the service made it (the campaign's "prediction" settings).
  TrialPlotInfo local;
  TrialPlotInfo& inf = info ? *info : local;
  inf.samples = gt.samples.size();
  std::vector<Pose2> predicted;
  std::string note;
  try {
    nlohmann::json model;
    const auto spec = nlohmann::json::parse(campaign.spec_json);
    if (spec.is_object() && spec.contains("prediction")) model = spec["prediction"];
    assessment::RecordedCommands commands;
    if (scene.pusher && scene.pusher->controller) {
      if (auto applied = store.GetClosedLoop(trial_id)) commands = assessment::CommandsOf(*applied);
    }
    const assessment::PredictedRun run = assessment::SimulatePrediction(scene, model, &commands);
    inf.model_key = run.key;
    inf.prediction_status = assessment::StatusOf(run.result.status);
    if (run.result.status != mechanics::SimulationStatus::kOk) note = ": " + run.result.error;
    for (const auto& s : run.result.samples) predicted.push_back({s.position, s.orientation});
  } catch (const std::exception& e) {
    inf.prediction_status = db::PredictionStatus::kError;
    note = std::string(": ") + e.what();
  }

  std::vector<Pose2> measured;
  std::vector<Vector3d> object_path, pusher_path, predicted_path;
  for (const auto& s : gt.samples) {
    measured.push_back(
        {{s.object_pose[0], s.object_pose[1], s.object_pose[2]},
         Eigen::Quaterniond(s.object_pose[3], s.object_pose[4], s.object_pose[5], s.object_pose[6])
             .normalized()});
    object_path.push_back(measured.back().position);
    pusher_path.emplace_back(s.pusher_pose[0], s.pusher_pose[1], s.pusher_pose[2]);
  }
  for (const auto& p : predicted) predicted_path.push_back(p.position);
  // The pusher's drawn disk: a sphere's centre is its reference point moved
  // back along the start normal by its radius (the scene's convention).
  double pusher_r = 0;
  Vector3d to_centre = Vector3d::Zero();
  if (scene.pusher && scene.pusher->type == mechanics::ContactType::kPoint &&
      scene.pusher->radius > 0) {
    pusher_r = scene.pusher->radius;
    to_centre = -pusher_r * scene.pusher->normal.normalized();
  }

  const std::vector<Vector3d> outline = Outline(scene.object);
  // Outlines at a few instants (samples paired by index, as the scorer pairs them).
  const std::size_t n = measured.size();
  std::vector<std::size_t> at = {0, n / 3, 2 * n / 3, n - 1};
  at.erase(std::unique(at.begin(), at.end()), at.end());

  std::vector<Vector3d> all = object_path;
  for (std::size_t k : at)
    for (const auto& v : Placed(outline, measured[k])) all.push_back(v);
  for (std::size_t k : at)
    if (k < predicted.size())
      for (const auto& v : Placed(outline, predicted[k])) all.push_back(v);
  for (const auto& p : pusher_path) all.push_back(p + to_centre);
  Vector2d lo = Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : all) {
    lo = lo.cwiseMin(p.head<2>());
    hi = hi.cwiseMax(p.head<2>());
  }
  const double panel_w = 760, panel_h = 560, top = 78, margin = 20;
  const Vector2d extent = (hi - lo).cwiseMax(1e-3);
  const double scale = std::min(0.85 * panel_w / extent.x(), 0.85 * panel_h / extent.y());
  const Canvas c{margin, top, panel_w, panel_h, scale, 0.5 * (lo + hi)};
  const double width = panel_w + 2 * margin, height = top + panel_h + 70;

  // Final errors at the last paired sample (the scorer's definition).
  std::string errors = "no prediction" + note;
  if (!predicted.empty()) {
    const std::size_t last = std::min(predicted.size(), measured.size()) - 1;
    const double dp = (predicted[last].position - measured[last].position).norm();
    const double da = predicted[last].orientation.angularDistance(measured[last].orientation);
    errors = "final error " + Mm(dp) + ", " + FormatNumber(da * 180 / kPi, 3) + " deg" +
             (inf.prediction_status == db::PredictionStatus::kOk
                  ? ""
                  : " (" + std::string(db::ToString(inf.prediction_status)) + note + ")");
  }
  const std::string truth = gt.truth.empty() ? "unreported" : gt.truth;
  std::string svg = "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + F(width) +
                    "\" height=\"" + F(height) + "\" viewBox=\"0 0 " + F(width) + " " + F(height) +
                    "\" font-family=\"sans-serif\">";
  svg += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>";
  svg += Text({width / 2, 24},
              "trial " + std::to_string(trial.id) + " (campaign " + std::to_string(campaign.id) +
                  " '" + campaign.name + "'), seen from above; truth: " + truth,
              "#000", "middle", 15);
  svg += Text({width / 2, 46},
              "prediction " + (inf.model_key.empty() ? std::string("-") : inf.model_key) + ": " +
                  errors + "; " + FormatNumber(gt.samples.back().t, 3) + " s, start yaw " +
                  FormatNumber(Yaw(measured.front().orientation) * 180 / kPi, 3) + " deg",
              "#333", "middle", 12);
  svg += "<rect x=\"" + F(c.x0) + "\" y=\"" + F(c.y0) + "\" width=\"" + F(c.w) + "\" height=\"" +
         F(c.h) + "\" fill=\"none\" stroke=\"#bbb\"/>";
  svg += Text({c.x0 + 8, c.y0 + 18}, "x right, y up (the scene's frame)", "#333");

  // Outlines first (paths drawn over them), the later ones darker.
  svg += "<g id=\"measured-outlines\">";
  for (std::size_t i = 0; i < at.size(); ++i)
    svg += Polyline(c, Placed(outline, measured[at[i]]), kMeasured, 1.3, false, true, "#888",
                    0.35 + 0.65 * double(i) / std::max<std::size_t>(1, at.size() - 1));
  svg += "</g><g id=\"predicted-outlines\">";
  for (std::size_t i = 0; i < at.size(); ++i)
    if (at[i] < predicted.size())
      svg += Polyline(c, Placed(outline, predicted[at[i]]), kPredicted, 1.3, true, true, "none",
                      0.35 + 0.65 * double(i) / std::max<std::size_t>(1, at.size() - 1));
  svg += "</g>";
  // The pusher: its path (centre) and its disk at the same instants.
  svg += "<g id=\"pusher-path\">";
  std::vector<Vector3d> centres;
  for (const auto& p : pusher_path) centres.push_back(p + to_centre);
  svg += Polyline(c, centres, kPusher, 1.6, false, false);
  if (pusher_r > 0)
    for (std::size_t k : at) {
      const Vector2d q = c.Px(centres[k]);
      svg += "<circle cx=\"" + F(q.x()) + "\" cy=\"" + F(q.y()) + "\" r=\"" +
             F(std::max(1.5, pusher_r * scale)) + "\" fill=\"none\" stroke=\"" + kPusher +
             "\" stroke-width=\"1.2\"/>";
    }
  svg += "</g>";
  svg += "<g id=\"measured-path\">" + Polyline(c, object_path, kMeasured, 2, false, false) + "</g>";
  if (!predicted_path.empty())
    svg += "<g id=\"predicted-path\">" + Polyline(c, predicted_path, kPredicted, 2, true, false) +
           "</g>";
  // Start and end marks.
  const Vector2d s0 = c.Px(object_path.front()), s1 = c.Px(object_path.back());
  svg += "<circle cx=\"" + F(s0.x()) + "\" cy=\"" + F(s0.y()) + "\" r=\"3\" fill=\"" + kMeasured +
         "\"/>" + Text(s0 + Vector2d(6, 14), "start", kMeasured, "start", 11);
  svg += "<circle cx=\"" + F(s1.x()) + "\" cy=\"" + F(s1.y()) + "\" r=\"3\" fill=\"" + kMeasured +
         "\"/>";
  // The scale bar.
  const double bar = ScaleBarLength(c.w / scale);
  const Vector2d b0(c.x0 + 20, c.y0 + c.h - 20), b1 = b0 + Vector2d(bar * scale, 0);
  svg += "<g id=\"scale-bar\" data-metres=\"" + FormatNumber(bar, 6) + "\"><line x1=\"" +
         F(b0.x()) + "\" y1=\"" + F(b0.y()) + "\" x2=\"" + F(b1.x()) + "\" y2=\"" + F(b1.y()) +
         "\" stroke=\"#000\" stroke-width=\"3\"/>" +
         Text(0.5 * (b0 + b1) + Vector2d(0, -7), Mm(bar), "#000", "middle") + "</g>";
  svg += Text({width / 2, height - 36},
              "black: the object's true (here: measured) path and outline; orange dashed: the "
              "prediction's",
              "#555", "middle", 12);
  svg += Text({width / 2, height - 18},
              "outlines at the start, 1/3, 2/3 and the end (later ones darker); red: the pusher's "
              "centre path and its tip then",
              "#555", "middle", 12);
  svg += "</svg>\n";
  return svg;
}

}  // namespace arena::cli
