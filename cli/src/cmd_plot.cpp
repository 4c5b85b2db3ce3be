// arena plot --db FILE --campaign ID --tradeoff --out FILE.svg [--evaluation ID]
// Charts from the store as standalone SVG (svg_chart.hpp).
//
// Modes (one per plot; add a mode as: an option/flag below, a chart builder
// in plot_charts.hpp, a branch in RunPlot):
//   --tradeoff   the speed/accuracy trade of an evaluation run (arena evaluate)
//   --map X,Y    a metric over two varied parameters of a campaign
//                (BuildCampaignMap, plot_map_data.hpp; RenderMapSvg)
//   TRIAL        one trial's pose and contact forces, true vs observed vs
//                predicted (PlotTrial, plot_trial.hpp)
//   --calibration ID  a calibration's loss profiles (CalibrationProfileChart,
//                plot_profile.cpp)
//   --scene FILE (or TRIAL --scene) the set-up a scene describes, in two
//                views with a scale bar (SceneSvg, plot_scene.hpp)
#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "commands.hpp"
#include "output_guard.hpp"
#include "plot_charts.hpp"
#include "plot_map_data.hpp"
#include "plot_scene.hpp"
#include "plot_trial.hpp"
#include "store_errors.hpp"
#include "truth_relation.hpp"

namespace arena::cli {

namespace {

const char* const kPredictorColors[] = {"#1f77b4", "#9467bd", "#8c564b", "#17becf", "#bcbd22"};

// The unit a person reads a metric in, and the factor from its SI value:
// one unit per quantity in human output (mm, degrees, N).
std::pair<std::string, double> HumanUnit(const std::string& metric) {
  if (metric.rfind("angle", 0) == 0) return {"deg", 180 / M_PI};
  if (metric.rfind("force", 0) == 0) return {"N", 1};
  if (metric.rfind("mode", 0) == 0) return {"fraction", 1};
  return {"mm", 1e3};
}

std::string UnitOf(const std::string& metric) {
  if (metric.rfind("angle", 0) == 0) return "rad";
  if (metric.rfind("force", 0) == 0) return "N";
  if (metric.rfind("mode", 0) == 0) return "fraction";
  return "m";
}

// The cost axis: wall time per simulated second; reports written before it
// existed give the median time per trial instead.
std::optional<double> Cost(const nlohmann::json& s, bool per_sim_s) {
  const char* key = per_sim_s ? "time_per_simulated_s" : "time_s";
  if (!s.contains(key) || !s[key].is_object() || !s[key]["median"].is_number()) return {};
  return s[key]["median"].get<double>();
}

// The time per trial's p95 (the time budget's metric).
std::optional<double> Cost95(const nlohmann::json& s) {
  if (!s.contains("time_s") || !s["time_s"].is_object() || !s["time_s"]["p95"].is_number())
    return {};
  return s["time_s"]["p95"].get<double>();
}

// The error-against-duration panel (reports since duration_curves exist).
Panel DurationPanel(const nlohmann::json& report) {
  Panel panel{"final position error against ground-truth duration (how fast the error grows)",
              "final position error p95 (mm)",
              true,
              {}};
  panel.own_x = true;
  panel.log_x = true;
  panel.x_label = "ground-truth duration of the trial (s)";
  std::size_t color = 0;
  for (const auto& c : report["duration_curves"]) {
    Series s{c.value("predictor", "?") + " " + c.value("model_key", "") + " p95",
             {},
             {},
             kPredictorColors[color++ % 5],
             true};
    s.connect = true;
    for (const auto& p : c["points"]) {
      s.x.push_back(p.value("duration_s", 0.0));
      s.y.push_back(p["position_error_m"].value("p95", 0.0) * 1e3);
      s.labels.push_back(std::to_string(p.value("trials", 0)) + " trials");
    }
    panel.series.push_back(std::move(s));
  }
  return panel;
}

// A time budget is on the time per trial (p95): then that is the x axis,
// so the budget line, the front and the recommendation share it.
struct TradeoffBudgets {
  std::optional<double> time, error;  // s; the metric's human unit
  std::string time_text, error_text;
};

TradeoffBudgets ReadBudgets(const nlohmann::json& report, const std::string& metric) {
  TradeoffBudgets out;
  if (!report.contains("budgets") || !report["budgets"].is_array()) return out;
  for (const auto& b : report["budgets"]) {
    if (!b.is_object() || !b.contains("limit") || !b["limit"].is_number()) continue;
    const std::string m = b.value("metric", "");
    if (m == "time_p95") {
      out.time = b["limit"].get<double>();
      out.time_text = b.value("text", "");
    } else if (m == metric) {
      out.error = b["limit"].get<double>() * HumanUnit(metric).second;
      out.error_text = b.value("text", "");
    }
  }
  return out;
}

// The report's settings sorted into what the chart draws.
struct TradeoffPoints {
  // One curve per predictor through its settings: (-step, cost, error, key).
  std::map<std::string, std::vector<std::tuple<double, double, double, std::string>>> curves;
  std::vector<std::string> order;                                // predictors, as first seen
  std::vector<std::pair<double, std::string>> failed;            // cost, label
  std::vector<std::tuple<double, double, std::string>> plotted;  // cost, error, key
  Series recommend{"recommended", {}, {}, "#2ca02c", true};
  double max_error = 0;
  int hidden = 0;  // settings with zero or no error
};

TradeoffPoints CollectSettings(const nlohmann::json& report, double unit_scale, bool time_budget,
                               bool per_sim_s) {
  const std::string recommended =
      report.contains("recommended") && report["recommended"].is_string()
          ? report["recommended"].get<std::string>()
          : "";
  TradeoffPoints out;
  for (const auto& s : report["settings"]) {
    const auto cost = time_budget ? Cost95(s) : Cost(s, per_sim_s);
    const std::string predictor = s.value("predictor", "arena");
    const std::string key = s.value("model_key", "");
    if (std::find(out.order.begin(), out.order.end(), predictor) == out.order.end())
      out.order.push_back(predictor);
    const int bad = s.value("failures", 0) + s.value("diverged", 0);
    if (bad > 0 && cost && *cost > 0) {
      // Drawn apart, above every error: its error leaves out what it failed on.
      out.failed.emplace_back(*cost, key + ": " + std::to_string(s.value("diverged", 0)) +
                                         " diverged, " + std::to_string(s.value("failures", 0)) +
                                         " failed");
      continue;
    }
    if (!cost || !s.contains("primary_error") || !s["primary_error"].is_number()) {
      ++out.hidden;
      continue;
    }
    const double err = s["primary_error"].get<double>() * unit_scale;
    if (!(err > 0) || !(*cost > 0)) {
      ++out.hidden;
      continue;
    }
    out.max_error = std::max(out.max_error, err);
    out.curves[predictor].emplace_back(-s.value("step_s", 0.0), *cost, err, key);
    out.plotted.emplace_back(*cost, err, key);
    if (key == recommended) {
      out.recommend.x.push_back(*cost);
      out.recommend.y.push_back(err);
      out.recommend.labels.push_back("recommended: " + key);
    }
  }
  return out;
}

// Per predictor: every setting as a labelled marker (into the panel), and
// its curve: the predictor's own lower envelope (what more time buys it),
// by cost (returned, drawn later).
std::vector<Series> AddPredictorSettings(TradeoffPoints& points, const std::string& truth_source,
                                         Panel* panel) {
  std::size_t color = 0;
  std::vector<Series> envelopes;
  for (const auto& name : points.order) {
    // The truth's own engine predicting it measures self-consistency.
    Series c{SelfConsistent(name, truth_source)
                 ? name + " (self-consistency: the truth's own engine)"
                 : name,
             {},
             {},
             kPredictorColors[color % 5],
             true};
    auto curve = points.curves[name];
    std::stable_sort(curve.begin(), curve.end(),
                     [](const auto& a, const auto& b) { return std::get<1>(a) < std::get<1>(b); });
    Series envelope{name + " curve", {}, {}, kPredictorColors[color++ % 5]};
    double best = std::numeric_limits<double>::infinity();
    for (const auto& [step, x, y, key] : curve) {
      c.x.push_back(x);
      c.y.push_back(y);
      c.labels.push_back(key);
      if (y < best) {
        best = y;
        envelope.x.push_back(x);
        envelope.y.push_back(y);
      }
    }
    panel->series.push_back(std::move(c));
    envelopes.push_back(std::move(envelope));
  }
  return envelopes;
}

// The front on the axis drawn: the settings no other beats on both cost and error.
Series ParetoFront(std::vector<std::tuple<double, double, std::string>> plotted) {
  std::sort(plotted.begin(), plotted.end());
  Series pareto{"pareto front", {}, {}, "#ff7f0e"};
  pareto.dashed = true;
  double best = std::numeric_limits<double>::infinity();
  for (const auto& [x, y, key] : plotted) {
    if (y < best) {
      best = y;
      pareto.x.push_back(x);
      pareto.y.push_back(y);
    }
  }
  return pareto;
}

// The noise floor: the error no deterministic predictor can beat.
void AddNoiseFloor(const nlohmann::json& report, const std::string& metric, double unit_scale,
                   Panel* panel) {
  const auto& floor = report.contains("noise_floor") ? report["noise_floor"] : nlohmann::json();
  if (!floor.is_object() || UnitOf(metric) != "m" || panel->series.empty()) return;
  // The median spread, as the table's floor multiples and the 1.5floor
  // budget use it ("within 1.5x the replicate spread on 95 % of trials").
  const double f = floor["position_m"].value("median", 0.0) * unit_scale;
  double lo = 0, hi = 0;
  for (const auto& se : panel->series)
    for (double x : se.x) {
      lo = lo > 0 ? std::min(lo, x) : x;
      hi = std::max(hi, x);
    }
  if (f > 0 && lo > 0) {
    Series line{"noise floor (median replicate spread)", {lo, hi}, {f, f}, "#7f7f7f"};
    line.dashed = true;
    panel->series.push_back(line);
  }
}

// The budget, as a line on the axis it limits.
void AddBudgetLines(const TradeoffBudgets& budgets, Panel* panel) {
  double lo = 0, hi = 0, ylo = 0, yhi = 0;
  for (const auto& se : panel->series)
    for (size_t i = 0; i < se.x.size() && i < se.y.size(); ++i) {
      lo = lo > 0 ? std::min(lo, se.x[i]) : se.x[i];
      hi = std::max(hi, se.x[i]);
      ylo = ylo > 0 ? std::min(ylo, se.y[i]) : se.y[i];
      yhi = std::max(yhi, se.y[i]);
    }
  if (budgets.error && *budgets.error > 0 && lo > 0) {
    Series line{
        "budget " + budgets.error_text, {lo, hi}, {*budgets.error, *budgets.error}, "#2ca02c"};
    line.dashed = true;
    panel->series.push_back(line);
  }
  if (budgets.time && *budgets.time > 0 && ylo > 0) {
    Series line{
        "budget " + budgets.time_text, {*budgets.time, *budgets.time}, {ylo, yhi}, "#2ca02c"};
    line.dashed = true;
    panel->series.push_back(line);
  }
}

std::string TradeoffTitle(const nlohmann::json& report, const std::string& metric,
                          const std::string& truth_source, int hidden) {
  // Reports before the truth statement say nothing about it: claim nothing.
  const bool independent = !report.contains("truth") || !report["truth"].is_object() ||
                           report["truth"].value("independent", true);
  const std::string truth =
      truth_source.empty() ? ""
                           : truth_source + (independent ? "" : ": self-consistency, not accuracy");
  return "campaign " + std::to_string(report.value("campaign_id", 0)) + ": " + metric +
         " vs cost (" + std::to_string(report.value("trials", 0)) + " trials" +
         (truth.empty() ? "" : ", truth: " + truth) +
         (hidden ? ", " + std::to_string(hidden) + " settings with zero or no error not shown"
                 : "") +
         ")";
}

}  // namespace

Chart TradeoffChart(const nlohmann::json& report) {
  if (!report.is_object() || !report.contains("settings") || !report["settings"].is_array()) {
    throw std::invalid_argument("evaluation report has no settings list");
  }
  const std::string metric = report.value("primary_metric", "position_median");
  const auto unit = HumanUnit(metric);
  const TradeoffBudgets budgets = ReadBudgets(report, metric);
  const bool per_sim_s =
      !budgets.time && std::any_of(report["settings"].begin(), report["settings"].end(),
                                   [](const nlohmann::json& s) { return Cost(s, true); });
  const std::string truth_source = report.contains("truth") && report["truth"].is_object()
                                       ? report["truth"].value("source", "")
                                       : "";
  TradeoffPoints points = CollectSettings(report, unit.second, budgets.time.has_value(), per_sim_s);
  Panel panel{"prediction error against predictor cost, one curve per predictor",
              metric + " (" + unit.first + ")",
              true,
              {}};
  std::vector<Series> envelopes = AddPredictorSettings(points, truth_source, &panel);
  Series failed{"failed settings", {}, {}, "#d62728", true};
  for (const auto& [x, label] : points.failed) {
    failed.x.push_back(x);
    failed.y.push_back(points.max_error > 0 ? 3 * points.max_error : 1);
    failed.labels.push_back(label);
  }
  panel.series.push_back(failed);
  for (auto& e : envelopes) panel.series.push_back(std::move(e));
  panel.series.push_back(ParetoFront(points.plotted));  // over the curves it may coincide with
  AddNoiseFloor(report, metric, unit.second, &panel);
  AddBudgetLines(budgets, &panel);
  // The recommendation last: drawn over every other point, a ring with its label.
  Series recommend = points.recommend;
  if (recommend.x.empty()) recommend.name = "recommended: none within the budget";
  recommend.marker_radius = 8;
  recommend.hollow = true;
  panel.series.push_back(recommend);
  Chart chart;
  chart.title = TradeoffTitle(report, metric, truth_source, points.hidden);
  chart.x_label = budgets.time ? "p95 predictor time per trial (s)"
                  : per_sim_s  ? "predictor wall time per simulated second (s/s)"
                               : "median model time per trial (s)";
  chart.log_x = true;
  chart.panels = {panel};
  if (report.contains("duration_curves") && report["duration_curves"].is_array() &&
      !report["duration_curves"].empty()) {
    chart.panels.push_back(DurationPanel(report));
  }
  chart.width = 1000;
  chart.panel_height = 320;
  return chart;
}

namespace {

struct PlotOptions {
  std::string db_path;
  std::int64_t campaign = -1;
  std::int64_t evaluation = -1;
  std::int64_t trial = -1;
  bool tradeoff = false;
  std::int64_t calibration = -1;
  std::vector<std::string> map;  // X, Y
  std::string metric;
  std::string out;
  bool paths = false;      // --paths: a TRIAL seen from above (TrialPathsSvg)
  bool scene = false;      // --scene given: a picture of the set-up
  std::string scene_file;  // its file; "" = the TRIAL's stored scene
};

void WriteFile(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw CommandError(kExitFailure, "plot: cannot write '" + path + "'");
  f << text;
  f.close();
  if (!f) throw CommandError(kExitFailure, "plot: cannot write '" + path + "'");
}

int PlotTradeoff(const db::Store& store, const PlotOptions& o) {
  if (o.campaign < 0) throw CommandError(kExitBadInput, "plot --tradeoff: needs --campaign ID");
  db::Evaluation run;
  if (o.evaluation >= 0) {
    run = store.GetEvaluation(o.evaluation);
    if (run.campaign_id != o.campaign) {
      throw CommandError(kExitBadInput, "plot --tradeoff: evaluation " +
                                            std::to_string(o.evaluation) + " is of campaign " +
                                            std::to_string(run.campaign_id));
    }
  } else {
    (void)store.GetCampaign(o.campaign);
    const auto runs = store.ListEvaluations(o.campaign);
    if (runs.empty()) {
      throw CommandError(kExitBadInput, "plot --tradeoff: campaign " + std::to_string(o.campaign) +
                                            " has no evaluation; run `arena evaluate --db " +
                                            o.db_path + " --campaign " +
                                            std::to_string(o.campaign) + "` first");
    }
    run = runs.back();
  }
  Chart chart;
  try {
    chart = TradeoffChart(nlohmann::json::parse(run.report_json));
  } catch (const std::exception& e) {
    throw CommandError(kExitStore, "plot --tradeoff: evaluation " + std::to_string(run.id) +
                                       " has an unreadable report: " + e.what());
  }
  WriteFile(o.out, RenderSvg(chart));
  return kExitOk;
}

int PlotCalibration(const db::Store& store, const PlotOptions& o) {
  const db::Calibration cal = store.GetCalibration(o.calibration);
  std::string predictor = "arena";
  try {
    predictor = nlohmann::json::parse(cal.settings_json).value("predictor", predictor);
  } catch (const nlohmann::json::exception&) {
  }
  Chart chart;
  try {
    chart = CalibrationProfileChart(nlohmann::json::parse(cal.params_json),
                                    "calibration " + std::to_string(cal.id) + " of campaign " +
                                        std::to_string(cal.campaign_id) + " (predictor " +
                                        predictor + "): the training loss along each parameter");
  } catch (const std::exception& e) {
    throw CommandError(kExitBadInput, "plot --calibration: calibration " + std::to_string(cal.id) +
                                          ": " + e.what());
  }
  WriteFile(o.out, RenderSvg(chart));
  return kExitOk;
}

int PlotMap(const db::Store& store, const PlotOptions& o) {
  if (o.campaign < 0) throw CommandError(kExitBadInput, "plot --map: needs --campaign ID");
  if (o.map.size() != 2 || o.map[0].empty() || o.map[1].empty()) {
    throw CommandError(kExitBadInput, "plot --map: give two varied parameters, X,Y");
  }
  if (o.metric.empty()) {
    throw CommandError(kExitBadInput,
                       "plot --map: needs --metric M (one of " + MapMetricNames() + ")");
  }
  MapData map;
  try {
    map = BuildCampaignMap(store, o.campaign, o.map[0], o.map[1], o.metric);
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, std::string("plot ") + e.what());
  }
  WriteFile(o.out, RenderMapSvg(map));
  return kExitOk;
}

int PlotScene(const PlotOptions& o) {
  if (o.tradeoff || o.calibration >= 0 || !o.map.empty())
    throw CommandError(kExitBadInput,
                       "plot: --scene is a plot of its own (no --tradeoff, --map, --calibration)");
  mechanics::Scene scene;
  std::string title;
  if (!o.scene_file.empty()) {
    if (o.trial >= 0)
      throw CommandError(kExitBadInput,
                         "plot --scene FILE: give a scene file or a TRIAL, not both");
    try {
      scene = mechanics::LoadSceneFile(o.scene_file);
    } catch (const mechanics::SceneError& e) {
      throw CommandError(kExitBadInput, o.scene_file + ": " + e.what());
    }
    title = o.scene_file;
  } else {
    if (o.trial < 0 || o.db_path.empty())
      throw CommandError(kExitBadInput,
                         "plot --scene: give a scene file (--scene FILE) or --db F TRIAL --scene");
    try {
      db::StoreOptions so;
      so.read_only = true;
      auto store = db::Store::Open(o.db_path, so);
      const db::Trial t = store->GetTrial(o.trial);
      scene = mechanics::ParseScene(t.scene_json);
      title = "trial " + std::to_string(t.id) + " of campaign " + std::to_string(t.campaign_id) +
              " (" + o.db_path + ")";
    } catch (const db::StoreError& e) {
      throw StoreCommandError(e);
    } catch (const mechanics::SceneError& e) {
      throw CommandError(kExitStore, "plot --scene: trial " + std::to_string(o.trial) +
                                         " has an unreadable scene: " + e.what());
    }
  }
  WriteFile(o.out, SceneSvg(scene, title));
  return kExitOk;
}

int RunPlot(const PlotOptions& o) {
  RefuseToOverwriteStore(o.out, "--out", o.db_path);
  if (o.scene) return PlotScene(o);
  if (o.db_path.empty())
    throw CommandError(kExitBadInput, "plot: --db is required (or --scene FILE)");
  if (!o.map.empty() && (o.tradeoff || o.trial >= 0)) {
    throw CommandError(kExitBadInput, "plot: --map is a plot of its own (no TRIAL, no --tradeoff)");
  }
  if (o.tradeoff && o.trial >= 0) {
    throw CommandError(kExitBadInput, "plot: give either a TRIAL or --tradeoff, not both");
  }
  if (o.calibration >= 0 && (o.tradeoff || o.trial >= 0 || !o.map.empty())) {
    throw CommandError(kExitBadInput,
                       "plot: --calibration is a plot of its own (no TRIAL, --tradeoff or --map)");
  }
  if (o.paths && o.trial < 0)
    throw CommandError(kExitBadInput, "plot --paths: give a TRIAL (--db F TRIAL --paths)");
  if (o.trial >= 0 && o.paths) {
    try {
      db::StoreOptions so;
      so.read_only = true;
      so.create = false;
      auto store = db::Store::Open(o.db_path, so);
      TrialPlotInfo info;
      WriteFile(o.out, TrialPathsSvg(*store, o.trial, &info));
      std::fprintf(stderr, "trial %lld: %zu samples, prediction %s (%s) -> %s\n",
                   static_cast<long long>(o.trial), info.samples,
                   info.model_key.empty() ? "-" : info.model_key.c_str(),
                   db::ToString(info.prediction_status), o.out.c_str());
      return kExitOk;
    } catch (const db::StoreError& e) {
      throw StoreCommandError(e);
    }
  }
  if (o.trial >= 0) return PlotTrial(o.db_path, o.trial, o.out);
  {
    db::StoreOptions so;
    so.read_only = true;
    auto store = db::Store::Open(o.db_path, so);
    if (o.calibration >= 0) return PlotCalibration(*store, o);
    if (o.tradeoff) return PlotTradeoff(*store, o);
    if (!o.map.empty()) return PlotMap(*store, o);
    throw CommandError(kExitBadInput,
                       "plot: choose a plot: a TRIAL id, --campaign ID --tradeoff, "
                       "--campaign ID --map X,Y --metric M, or --calibration ID");
  }
}

}  // namespace

void AddPlotCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<PlotOptions>();
  auto* cmd = app.add_subcommand(
      "plot",
      "Draw charts from the store as SVG: a trial, the speed/accuracy trade, a map, or a "
      "calibration's loss profile");
  cmd->add_option("trial", o->trial, "Trial id (see `arena query`)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--db", o->db_path, "Store file (opened read-only); not needed for --scene FILE");
  cmd->add_option("--out", o->out, "SVG file to write")->required();
  cmd->add_option("--campaign", o->campaign, "Campaign id")->check(CLI::NonNegativeNumber);
  cmd->add_flag(
      "--tradeoff", o->tradeoff,
      "Prediction error against model time per fidelity setting, from the campaign's latest "
      "evaluation (arena evaluate); log axes, Pareto front highlighted");
  cmd->add_option("--evaluation", o->evaluation,
                  "With --tradeoff: this evaluation run instead of the latest")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--map", o->map,
                  "A map over two varied parameters of the campaign, X,Y (e.g. "
                  "grip_force,pivot_offset)")
      ->delimiter(',');
  cmd->add_option("--metric", o->metric, "With --map: the colour, one of " + MapMetricNames());
  cmd->add_option("--calibration", o->calibration,
                  "A calibration's loss profile (arena calibrate): the training loss along each "
                  "fitted parameter, the fit, and what the data rule out")
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--paths", o->paths,
                "With a TRIAL: the trial seen from above: the object's true (measured, or the "
                "simulated cell's) and "
                "predicted paths with its outline at a few instants, and the pusher's path");
  auto* scene = cmd->add_option("--scene", o->scene_file,
                                "A picture of the set-up: a scene file's (or, with no FILE, "
                                "the TRIAL's) object, fingers, pusher and its push, in two views "
                                "with a scale bar")
                    ->expected(0, 1);
  cmd->footer(
      "Examples:\n"
      "  arena plot --db lab.db 12 --out trial12.svg\n"
      "  arena plot --db lab.db 12 --paths --out paths12.svg\n"
      "  arena plot --db lab.db --campaign 3 --map grip_force,pivot_offset --metric unstable "
      "--out map.svg\n"
      "  arena plot --db lab.db --campaign 3 --tradeoff --out tradeoff.svg\n"
      "  arena plot --db lab.db --calibration 1 --out profile.svg\n"
      "  arena plot --scene examples/scenes/canonical.json --out scene.svg\n"
      "  arena plot --db lab.db 12 --scene --out scene12.svg\n"
      "A trial's prediction is re-run with the campaign's \"prediction\" settings, as `arena "
      "serve` ran it.\n"
      "View the SVG in a browser, or convert it: rsvg-convert trial12.svg -o trial12.png\n");
  cmd->callback([o, scene, action] {
    o->scene = scene->count() > 0;
    *action = [o] { return RunPlot(*o); };
  });
}

}  // namespace arena::cli
