// arena plot --db FILE --campaign ID --tradeoff --out FILE.svg [--evaluation ID]
// Charts from the store as standalone SVG (svg_chart.hpp).
//
// Modes (one per plot; add a mode as: an option/flag below, a chart builder
// in plot_charts.hpp, a branch in RunPlot):
//   --tradeoff   the speed/accuracy trade of an evaluation run (arena evaluate)
//   TRIAL        one trial's pose and contact forces, true vs observed vs
//                predicted (PlotTrial, plot_trial.hpp)
#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "commands.hpp"
#include "output_guard.hpp"
#include "plot_charts.hpp"
#include "plot_trial.hpp"
#include "store_errors.hpp"

namespace arena::cli {

Chart TradeoffChart(const nlohmann::json& report) {
  if (!report.is_object() || !report.contains("settings") || !report["settings"].is_array()) {
    throw std::invalid_argument("evaluation report has no settings list");
  }
  const std::string metric = report.value("primary_metric", "position_median");
  const std::string recommended =
      report["recommended"].is_string() ? report["recommended"].get<std::string>() : "";
  Series all{"settings", {}, {}, "#1f77b4", true};
  Series failed{"failed settings", {}, {}, "#d62728", true};
  Series recommend{"recommended", {}, {}, "#2ca02c", true};
  std::vector<std::pair<double, double>> front;
  int hidden = 0;
  for (const auto& s : report["settings"]) {
    if (!s.contains("time_s") || !s["time_s"].is_object() || !s["primary_error"].is_number()) {
      ++hidden;
      continue;
    }
    const double t_ms = s["time_s"]["median"].get<double>() * 1e3;
    const double err = s["primary_error"].get<double>();
    if (!(err > 0) || !(t_ms > 0)) {
      ++hidden;
      continue;
    }
    const bool ok = s.value("failures", 0) == 0;
    Series& into = ok ? all : failed;
    into.x.push_back(t_ms);
    into.y.push_back(err);
    if (ok && s.value("pareto", false)) front.emplace_back(t_ms, err);
    if (s.value("model_key", "") == recommended) {
      recommend.x.push_back(t_ms);
      recommend.y.push_back(err);
    }
  }
  std::sort(front.begin(), front.end());
  Series pareto{"pareto front", {}, {}, "#ff7f0e"};
  for (const auto& [x, y] : front) {
    pareto.x.push_back(x);
    pareto.y.push_back(y);
  }
  Chart chart;
  chart.title =
      "campaign " + std::to_string(report.value("campaign_id", 0)) + ": " + metric +
      " vs model time (" + std::to_string(report.value("trials", 0)) + " trials" +
      (hidden ? ", " + std::to_string(hidden) + " settings with zero or no error not shown" : "") +
      ")";
  chart.x_label = "median model time per trial (ms)";
  chart.log_x = true;
  const bool angle = metric.rfind("angle", 0) == 0, force = metric.rfind("force", 0) == 0;
  const std::string unit = angle                          ? "rad"
                           : force                        ? "N"
                           : metric.rfind("mode", 0) == 0 ? "fraction"
                                                          : "m";
  Panel panel{"prediction error against predictor time", metric + " (" + unit + ")", true, {}};
  panel.series = {all, failed, pareto, recommend};
  chart.panels = {panel};
  return chart;
}

namespace {

struct PlotOptions {
  std::string db_path;
  std::int64_t campaign = -1;
  std::int64_t evaluation = -1;
  std::int64_t trial = -1;
  bool tradeoff = false;
  std::string out;
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

int RunPlot(const PlotOptions& o) {
  RefuseToOverwriteStore(o.out, "--out", o.db_path);
  if (o.tradeoff && o.trial >= 0) {
    throw CommandError(kExitBadInput, "plot: give either a TRIAL or --tradeoff, not both");
  }
  if (o.trial >= 0) return PlotTrial(o.db_path, o.trial, o.out);
  try {
    db::StoreOptions so;
    so.read_only = true;
    auto store = db::Store::Open(o.db_path, so);
    if (o.tradeoff) return PlotTradeoff(*store, o);
    throw CommandError(kExitBadInput,
                       "plot: choose a plot: a TRIAL id, or --campaign ID --tradeoff");
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  }
}

}  // namespace

void AddPlotCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<PlotOptions>();
  auto* cmd = app.add_subcommand(
      "plot", "Draw charts from the store as SVG: a trial, or the speed/accuracy trade");
  cmd->add_option("trial", o->trial, "Trial id (see `arena query`)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--db", o->db_path, "Store file (opened read-only)")->required();
  cmd->add_option("--out", o->out, "SVG file to write")->required();
  cmd->add_option("--campaign", o->campaign, "Campaign id")->check(CLI::NonNegativeNumber);
  cmd->add_flag(
      "--tradeoff", o->tradeoff,
      "Prediction error against model time per fidelity setting, from the campaign's latest "
      "evaluation (arena evaluate); log axes, Pareto front highlighted");
  cmd->add_option("--evaluation", o->evaluation,
                  "With --tradeoff: this evaluation run instead of the latest")
      ->check(CLI::NonNegativeNumber);
  cmd->footer(
      "Examples:\n"
      "  arena plot --db lab.db 12 --out trial12.svg\n"
      "  arena plot --db lab.db --campaign 3 --tradeoff --out tradeoff.svg\n"
      "A trial's prediction is re-run with the campaign's \"prediction\" settings, as `arena "
      "serve` ran it.\n"
      "View the SVG in a browser, or convert it: rsvg-convert trial12.svg -o trial12.png\n");
  cmd->callback([o, action] { *action = [o] { return RunPlot(*o); }; });
}

}  // namespace arena::cli
