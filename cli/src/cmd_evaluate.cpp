// arena evaluate --db FILE --campaign ID [--facets 4,8,16,32] [--points 2,3,5,9]
//                [--dt 0.004] [--reduce auto] [--budget 1mm ...] [--threads N] [--json]
// Replays a campaign's done trials through the model at every fidelity
// setting of the grid, stores the run (tables evaluations and
// evaluation_results) and prints the trade: a table or JSON.
#include <atomic>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/orchestrator/evaluation.hpp"
#include "commands.hpp"
#include "progress.hpp"
#include "signals.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

struct EvaluateOptions {
  std::string db_path;
  std::int64_t campaign = -1;
  std::vector<int> facets{4, 8, 16, 32};
  std::vector<int> points{2, 3, 5, 9};
  std::vector<double> dt{0.004};
  std::vector<std::string> reduce{"auto"};
  std::vector<std::string> budgets;
  int threads = 0;
  bool json = false;
};

std::string Milli(const std::optional<orchestrator::Distribution>& d, double scale,
                  const char* fmt) {
  if (!d) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, d->median * scale, d->p95 * scale);
  return buf;
}

std::string FormatTable(const orchestrator::EvaluationReport& r, std::int64_t evaluation_id) {
  std::ostringstream out;
  char line[512];
  std::snprintf(line, sizeof line,
                "campaign %lld: %d done trials replayed at %zu settings (evaluation %lld)\n",
                static_cast<long long>(r.campaign_id), r.trials, r.settings.size(),
                static_cast<long long>(evaluation_id));
  out << line;
  std::snprintf(line, sizeof line, "%-24s %6s %17s %17s %17s %9s %15s %s\n", "setting", "ok",
                "pos mm med/p95", "angle deg med/p95", "force N med/p95", "mode med",
                "ms/trial med/p95", "");
  out << line;
  for (std::size_t i = 0; i < r.settings.size(); ++i) {
    const auto& s = r.settings[i];
    std::string marks;
    if (s.pareto) marks += " pareto";
    if (s.within_budget && !r.budgets.empty()) marks += " in-budget";
    if (r.recommended && *r.recommended == i) marks += " <== recommended";
    char ok[32];
    std::snprintf(ok, sizeof ok, "%d/%d", s.ok, s.trials);
    char mode[32] = "-";
    if (s.mode_agreement) std::snprintf(mode, sizeof mode, "%.3f", s.mode_agreement->median);
    char time[48];
    std::snprintf(time, sizeof time, "%.3g/%.3g", s.time.median * 1e3, s.time.p95 * 1e3);
    std::snprintf(line, sizeof line, "%-24s %6s %17s %17s %17s %9s %15s%s\n", s.model_key.c_str(),
                  ok, Milli(s.position, 1e3, "%.3g/%.3g").c_str(),
                  Milli(s.angle, 180 / M_PI, "%.3g/%.3g").c_str(),
                  Milli(s.force, 1, "%.3g/%.3g").c_str(), mode, time, marks.c_str());
    out << line;
  }
  out << "Pareto front: " << orchestrator::ToString(r.primary)
      << " against median time per trial.\n";
  out << "recommendation: " << r.recommendation << "\n";
  return out.str();
}

int RunEvaluate(const EvaluateOptions& o) {
  orchestrator::EvaluationOptions eo;
  eo.grid.facets = o.facets;
  eo.grid.points = o.points;
  eo.grid.dt = o.dt;
  eo.grid.reduce.clear();
  for (const auto& r : o.reduce) {
    if (r == "auto")
      eo.grid.reduce.push_back(mechanics::Reduce::kAuto);
    else if (r == "full")
      eo.grid.reduce.push_back(mechanics::Reduce::kFull);
    else if (r == "planar")
      eo.grid.reduce.push_back(mechanics::Reduce::kPlanar);
    else
      throw CommandError(kExitBadInput, "--reduce: must be auto, full or planar, got '" + r + "'");
  }
  if (o.threads < 0) throw CommandError(kExitBadInput, "--threads: must be >= 0 (0: one per core)");
  eo.threads = o.threads;
  try {
    for (const auto& b : o.budgets) eo.budgets.push_back(orchestrator::ParseBudget(b));
    (void)orchestrator::ExpandGrid(eo.grid);
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, std::string("evaluate: ") + e.what());
  }

  // Signals first, so the worker threads inherit the blocked mask.
  std::atomic<bool> cancel{false};
  SignalWatcher signals([&cancel](int) { cancel.store(true); });
  eo.cancel = &cancel;

  orchestrator::EvaluationRun run;
  std::vector<db::Store::TruthCount> truths;  // what the errors are measured against
  try {
    db::StoreOptions so;
    so.create = false;
    auto store = db::Store::Open(o.db_path, so);
    std::unique_ptr<ProgressLine> progress;
    eo.progress = [&progress](long done, long failed, long total) {
      if (!progress) progress = std::make_unique<ProgressLine>(total, "replays");
      progress->Update(done, failed);
    };
    run = orchestrator::EvaluateCampaign(*store, o.campaign, eo);
    truths = store->CampaignTruths(o.campaign);
    if (progress) progress->Finish();
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, std::string("evaluate: ") + e.what());
  }
  if (run.cancelled) {
    std::fprintf(stderr, "evaluate: interrupted; nothing stored\n");
    return kExitInterrupted;
  }
  if (o.json) {
    nlohmann::json j = orchestrator::ToJson(run.report);
    j["evaluation_id"] = run.evaluation_id;
    j["truth"] = nlohmann::json::array();
    for (const auto& t : truths)
      j["truth"].push_back({{"truth", t.truth}, {"backend", t.backend}, {"trials", t.trials}});
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    const std::string text = FormatTable(run.report, run.evaluation_id);
    std::fwrite(text.data(), 1, text.size(), stdout);
    for (const auto& t : truths) {
      std::printf("truth: %s (%s backend), %lld trials%s\n",
                  t.truth.empty() ? "unreported" : t.truth.c_str(),
                  t.backend.empty() ? "?" : t.backend.c_str(), static_cast<long long>(t.trials),
                  t.truth == "self-consistency"
                      ? ": these errors are arena's model against itself, not accuracy"
                      : "");
    }
  }
  return kExitOk;
}

}  // namespace

void AddEvaluateCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<EvaluateOptions>();
  auto* cmd = app.add_subcommand("evaluate",
                                 "Replay a campaign's done trials at several model fidelities; "
                                 "report the speed/accuracy trade");
  cmd->add_option("--db", o->db_path, "Store file")->required();
  cmd->add_option("--campaign", o->campaign, "Campaign id")
      ->required()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--facets", o->facets, "Friction cone facets to try (comma separated)")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--points", o->points, "Constituent points per line/patch to try")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--dt", o->dt, "Time steps to try (s)")->delimiter(',')->capture_default_str();
  cmd->add_option("--reduce", o->reduce, "Model reductions to try (auto, full, planar)")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option(
      "--budget", o->budgets,
      "Error budget, repeatable (all must hold): '1mm' = median final position error <= 1 mm, "
      "or METRIC=VALUE[UNIT] with METRIC position_median|position_p95|angle_median|angle_p95|"
      "force_median|force_p95|mode_agreement_median (a minimum)");
  cmd->add_option("--threads", o->threads, "Worker threads (0: one per core)")
      ->capture_default_str();
  cmd->add_flag("--json", o->json, "Print the report as JSON");
  cmd->footer(
      "Example:\n"
      "  arena evaluate --db lab.db --campaign 3 --facets 4,8,16 --points 2,3,5 --budget 1mm\n"
      "Every done trial is replayed from its stored scene at each setting of the cross product\n"
      "facets x points x dt x reduce, scored against its stored ground truth, and the run is\n"
      "stored (tables evaluations, evaluation_results). Errors are medians and 95th percentiles\n"
      "over trials; model time is the predictor's wall time per trial. The Pareto front is the\n"
      "first budget's metric (default: median final position error) against median time; the\n"
      "recommendation is the cheapest setting that predicted every trial within every budget.\n"
      "Plot the trade with: arena plot --db FILE --campaign ID --tradeoff --out FILE.svg\n");
  cmd->callback([o, action] { *action = [o] { return RunEvaluate(*o); }; });
}

}  // namespace arena::cli
