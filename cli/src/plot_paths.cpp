// `arena plot --db DB TRIAL --paths`: the trial seen from above (plot_trial.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/assessment/truth.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "command_error.hpp"
#include "plot_trial.hpp"
#include "plotted_trial.hpp"
#include "store_errors.hpp"
#include "svg_chart.hpp"

namespace arena::cli {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

const char* const kMeasured = "#222222";
const char* const kPredicted = "#e6550d";
const char* const kPusher = "#c0392b";

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
        out.emplace_back(o.radius * std::cos(2 * std::numbers::pi * k / 48),
                         o.radius * std::sin(2 * std::numbers::pi * k / 48), 0);
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
struct TopView {
  double x0, y0, w, h, scale;
  Vector2d centre;
  Vector2d Px(const Vector3d& p) const {
    return {x0 + w / 2 + (p.x() - centre.x()) * scale, y0 + h / 2 - (p.y() - centre.y()) * scale};
  }
};

std::string Polyline(const TopView& c, const std::vector<Vector3d>& pts, const std::string& color,
                     double width, bool dashed, bool closed, const std::string& fill = "none",
                     double opacity = 1) {
  std::string d;
  for (const auto& p : pts) d += SvgNum(c.Px(p).x()) + "," + SvgNum(c.Px(p).y()) + " ";
  return std::string("<") + (closed ? "polygon" : "polyline") + " points=\"" + d + "\" fill=\"" +
         fill + "\" fill-opacity=\"0.12\" stroke=\"" + color + "\" stroke-width=\"" +
         SvgNum(width) + "\" stroke-opacity=\"" + FormatNumber(opacity, 3) + "\"" +
         (dashed ? " stroke-dasharray=\"6,4\"" : "") + "/>";
}

std::string TextFrom(const Vector2d& at, const std::string& text, const std::string& color,
                     const char* anchor = "start", int size = 12) {
  return "<text x=\"" + SvgNum(at.x()) + "\" y=\"" + SvgNum(at.y()) + "\" font-size=\"" +
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

// Everything drawn, in the scene's frame, and the canvas it is drawn on.
struct PathsView {
  std::vector<Pose2> measured, predicted;
  std::vector<Vector3d> object_path, predicted_path;
  std::vector<Vector3d> pusher_centres;  // the pusher's drawn disk centre per sample
  double pusher_r = 0;
  std::vector<Vector3d> outline;
  std::vector<std::size_t> at;  // the instants whose outlines are drawn
  TopView c{};
  double width = 0, height = 0;
};

PathsView MakeView(const PlottedTrial& p, const mechanics::SimulationResult& prediction) {
  PathsView v;
  for (const auto& s : prediction.samples) v.predicted.push_back({s.position, s.orientation});
  for (const auto& s : p.gt.samples) {
    v.measured.push_back(
        {{s.object_pose[0], s.object_pose[1], s.object_pose[2]},
         Eigen::Quaterniond(s.object_pose[3], s.object_pose[4], s.object_pose[5], s.object_pose[6])
             .normalized()});
    v.object_path.push_back(v.measured.back().position);
  }
  for (const auto& q : v.predicted) v.predicted_path.push_back(q.position);
  // The pusher's drawn disk: a sphere's centre is its reference point moved
  // back along the start normal by its radius (the scene's convention).
  Vector3d to_centre = Vector3d::Zero();
  const auto& pusher = p.scene.pusher;
  if (pusher && pusher->type == mechanics::ContactType::kPoint && pusher->radius > 0) {
    v.pusher_r = pusher->radius;
    to_centre = -v.pusher_r * pusher->normal.normalized();
  }
  for (const auto& s : p.gt.samples)
    v.pusher_centres.push_back(Vector3d(s.pusher_pose[0], s.pusher_pose[1], s.pusher_pose[2]) +
                               to_centre);

  v.outline = Outline(p.scene.object);
  // Outlines at a few instants (samples paired by index, as the scorer pairs them).
  const std::size_t n = v.measured.size();
  v.at = {0, n / 3, 2 * n / 3, n - 1};
  v.at.erase(std::unique(v.at.begin(), v.at.end()), v.at.end());

  std::vector<Vector3d> all = v.object_path;
  for (std::size_t k : v.at)
    for (const auto& x : Placed(v.outline, v.measured[k])) all.push_back(x);
  for (std::size_t k : v.at)
    if (k < v.predicted.size())
      for (const auto& x : Placed(v.outline, v.predicted[k])) all.push_back(x);
  for (const auto& x : v.pusher_centres) all.push_back(x);
  Vector2d lo = Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& x : all) {
    lo = lo.cwiseMin(x.head<2>());
    hi = hi.cwiseMax(x.head<2>());
  }
  const double panel_w = 760, panel_h = 560, top = 78, margin = 20;
  const Vector2d extent = (hi - lo).cwiseMax(1e-3);
  const double scale = std::min(0.85 * panel_w / extent.x(), 0.85 * panel_h / extent.y());
  v.c = TopView{margin, top, panel_w, panel_h, scale, 0.5 * (lo + hi)};
  v.width = panel_w + 2 * margin;
  v.height = top + panel_h + 70;
  return v;
}

// Final errors at the last paired sample (the scorer's definition).
std::string FinalErrors(const PathsView& v, const TrialPlotInfo& inf, const std::string& note) {
  if (v.predicted.empty()) return "no prediction" + note;
  const std::size_t last = std::min(v.predicted.size(), v.measured.size()) - 1;
  const double dp = (v.predicted[last].position - v.measured[last].position).norm();
  const double da = v.predicted[last].orientation.angularDistance(v.measured[last].orientation);
  return "final error " + Mm(dp) + ", " + FormatNumber(da * 180 / std::numbers::pi, 3) + " deg" +
         (inf.prediction_status == db::PredictionStatus::kOk
              ? ""
              : " (" + std::string(db::ToString(inf.prediction_status)) + note + ")");
}

// The document's start: the two title lines and the panel's frame.
std::string HeaderSvg(const PlottedTrial& p, const PathsView& v, const TrialPlotInfo& inf,
                      const std::string& errors) {
  const std::string truth = p.gt.truth.empty() ? "unreported" : p.gt.truth;
  std::string svg = "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + SvgNum(v.width) +
                    "\" height=\"" + SvgNum(v.height) + "\" viewBox=\"0 0 " + SvgNum(v.width) +
                    " " + SvgNum(v.height) + "\" font-family=\"sans-serif\">";
  svg += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>";
  svg += TextFrom({v.width / 2, 24},
                  "trial " + std::to_string(p.trial.id) + " (campaign " +
                      std::to_string(p.campaign.id) + " '" + p.campaign.name +
                      "'), seen from above; truth: " + truth,
                  "#000", "middle", 15);
  svg += TextFrom(
      {v.width / 2, 46},
      "prediction " + (inf.model_key.empty() ? std::string("-") : inf.model_key) + ": " + errors +
          "; " + FormatNumber(p.gt.samples.back().t, 3) + " s, start yaw " +
          FormatNumber(Yaw(v.measured.front().orientation) * 180 / std::numbers::pi, 3) + " deg",
      "#333", "middle", 12);
  const TopView& c = v.c;
  svg += "<rect x=\"" + SvgNum(c.x0) + "\" y=\"" + SvgNum(c.y0) + "\" width=\"" + SvgNum(c.w) +
         "\" height=\"" + SvgNum(c.h) + "\" fill=\"none\" stroke=\"#bbb\"/>";
  svg += TextFrom({c.x0 + 8, c.y0 + 18}, "x right, y up (the scene's frame)", "#333");
  return svg;
}

// Outlines (drawn first, paths over them), the later ones darker; then the
// pusher: its centre path and its disk at the same instants.
std::string OutlinesAndPusherSvg(const PathsView& v) {
  const auto opacity = [&](std::size_t i) {
    return 0.35 + 0.65 * double(i) / std::max<std::size_t>(1, v.at.size() - 1);
  };
  std::string svg = "<g id=\"measured-outlines\">";
  for (std::size_t i = 0; i < v.at.size(); ++i)
    svg += Polyline(v.c, Placed(v.outline, v.measured[v.at[i]]), kMeasured, 1.3, false, true,
                    "#888", opacity(i));
  svg += "</g><g id=\"predicted-outlines\">";
  for (std::size_t i = 0; i < v.at.size(); ++i)
    if (v.at[i] < v.predicted.size())
      svg += Polyline(v.c, Placed(v.outline, v.predicted[v.at[i]]), kPredicted, 1.3, true, true,
                      "none", opacity(i));
  svg += "</g>";
  svg += "<g id=\"pusher-path\">";
  svg += Polyline(v.c, v.pusher_centres, kPusher, 1.6, false, false);
  if (v.pusher_r > 0)
    for (std::size_t k : v.at) {
      const Vector2d q = v.c.Px(v.pusher_centres[k]);
      svg += "<circle cx=\"" + SvgNum(q.x()) + "\" cy=\"" + SvgNum(q.y()) + "\" r=\"" +
             SvgNum(std::max(1.5, v.pusher_r * v.c.scale)) + "\" fill=\"none\" stroke=\"" +
             kPusher + "\" stroke-width=\"1.2\"/>";
    }
  svg += "</g>";
  return svg;
}

// What the black path is: the truth the trial's cell reported (a robot's
// measurement, an imported lab measurement, a dataset recorded elsewhere and
// replayed, a simulator's run, arena's own model), never "measured" for a
// simulated cell or for a replayed dataset that does not say it was measured.
std::string TruthWords(const std::string& truth) {
  if (truth.empty()) return "truth unreported";
  if (truth.rfind("measured", 0) == 0) return "here: measured";
  if (truth == "robot") return "here: measured, robot";
  if (truth == "recorded") return "here: recorded elsewhere, replayed";
  return "here: simulated, " + truth;
}

// A push out of the view (a gripper's push along its z) leaves the top view
// nearly empty: say how far the object went along z and where to see it.
std::string OutOfViewNote(const PathsView& v) {
  double in_plane = 0, along_z = 0;
  for (const auto& x : v.object_path) {
    in_plane = std::max(in_plane, (x - v.object_path.front()).head<2>().norm());
    along_z = std::max(along_z, std::abs(x.z() - v.object_path.front().z()));
  }
  if (along_z <= 2 * in_plane) return "";
  return "the object moved " + Mm(along_z) + " along z, out of this view, and " + Mm(in_plane) +
         " in it: plot without --paths shows every axis over time";
}

// The object's paths with start and end marks, the scale bar, the legend.
std::string PathsAndLegendSvg(const PathsView& v, const std::string& truth) {
  const TopView& c = v.c;
  std::string svg =
      "<g id=\"measured-path\">" + Polyline(c, v.object_path, kMeasured, 2, false, false) + "</g>";
  if (!v.predicted_path.empty())
    svg += "<g id=\"predicted-path\">" + Polyline(c, v.predicted_path, kPredicted, 2, true, false) +
           "</g>";
  const Vector2d s0 = c.Px(v.object_path.front()), s1 = c.Px(v.object_path.back());
  svg += "<circle cx=\"" + SvgNum(s0.x()) + "\" cy=\"" + SvgNum(s0.y()) + "\" r=\"3\" fill=\"" +
         kMeasured + "\"/>" + TextFrom(s0 + Vector2d(6, 14), "start", kMeasured, "start", 11);
  svg += "<circle cx=\"" + SvgNum(s1.x()) + "\" cy=\"" + SvgNum(s1.y()) + "\" r=\"3\" fill=\"" +
         kMeasured + "\"/>";
  const double bar = ScaleBarLength(c.w / c.scale);
  const Vector2d b0(c.x0 + 20, c.y0 + c.h - 20), b1 = b0 + Vector2d(bar * c.scale, 0);
  svg += "<g id=\"scale-bar\" data-metres=\"" + FormatNumber(bar, 6) + "\"><line x1=\"" +
         SvgNum(b0.x()) + "\" y1=\"" + SvgNum(b0.y()) + "\" x2=\"" + SvgNum(b1.x()) + "\" y2=\"" +
         SvgNum(b1.y()) + "\" stroke=\"#000\" stroke-width=\"3\"/>" +
         TextFrom(0.5 * (b0 + b1) + Vector2d(0, -7), Mm(bar), "#000", "middle") + "</g>";
  const std::string out_of_view = OutOfViewNote(v);
  if (!out_of_view.empty())
    svg += "<g id=\"out-of-view\">" +
           TextFrom({c.x0 + c.w / 2, c.y0 + 40}, out_of_view, "#a04000", "middle", 12) + "</g>";
  svg += TextFrom({v.width / 2, v.height - 36},
                  "black: the object's true (" + TruthWords(truth) +
                      ") path and outline; orange dashed: the prediction's",
                  "#555", "middle", 12);
  svg +=
      TextFrom({v.width / 2, v.height - 18},
               "outlines at the start, 1/3, 2/3 and the end (later ones darker); red: the pusher's "
               "centre path and its tip at those instants",
               "#555", "middle", 12);
  return svg;
}

}  // namespace

std::string TrialPathsSvg(const db::Store& store, std::int64_t trial_id, TrialPlotInfo* info) {
  const PlottedTrial p = LoadPlottedTrial(store, trial_id);
  // The prediction as the service made it (the campaign's "prediction" settings).
  TrialPlotInfo local;
  TrialPlotInfo& inf = info ? *info : local;
  inf.samples = p.gt.samples.size();
  std::string reason;
  const mechanics::SimulationResult prediction = PredictPlottedTrial(store, p, &inf, &reason);
  const std::string note = reason.empty() ? "" : ": " + reason;
  const PathsView v = MakeView(p, prediction);
  std::string svg = HeaderSvg(p, v, inf, FinalErrors(v, inf, note));
  svg += OutlinesAndPusherSvg(v);
  svg += PathsAndLegendSvg(v, p.gt.truth);
  svg += "</svg>\n";
  return svg;
}

}  // namespace arena::cli
