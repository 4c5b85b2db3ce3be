// arena calibrate --db F --campaign ID --params mu_fingers,mu_pusher[,...]
//                 [--predictor arena|mujoco] [--holdout 0.3] [--bootstrap 20] ...
// Fits model parameters to a campaign's done trials (assessment/calibration.hpp),
// prints the fit with its uncertainty and the held-out error before/after,
// and stores it; a campaign's "prediction": {"calibration": ID} then uses it.

#include <atomic>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/simulators/simulator.hpp"
#include "commands.hpp"
#include "output_guard.hpp"
#include "progress.hpp"
#include "result_file.hpp"
#include "signals.hpp"
#include "store_errors.hpp"
#include "trial_parameters.hpp"

namespace arena::cli {
namespace {

struct CalibrateOptions {
  std::string db_path;
  std::int64_t campaign = 0;
  std::string params;
  std::string predictor = "arena";
  std::string predictor_settings;  // mujoco's knobs (JSON); "" = the campaign's, else defaults
  std::string bootstrap_method;    // refit | reuse; "" = the predictor's default
  double holdout = 0.3;
  int bootstrap = 20;
  int max_evaluations = 0;   // 0 = the predictor's default
  double force_window = -1;  // s; < 0 = the predictor's default
  std::uint64_t seed = 1;
  int threads = 1;
  double lower = 0.2, upper = 5.0;
  int profile_points = -1;  // < 0 = the predictor's default
  bool json = false;
  std::string out_path;           // --out: the result as JSON, besides the store
  std::string loss = "pose";      // --loss: pose (position, angle, force) or nmse
  std::string holdout_by;         // --holdout-by: a trial parameter
  std::string trial_parameters;   // --trial-parameters: a CSV with a seed column
  std::string from = "measured";  // --from: where predictions start (issue 26)
};

std::vector<assessment::CalibrationParam> ParseParams(const std::string& list) {
  std::vector<assessment::CalibrationParam> out;
  std::stringstream in(list);
  std::string name;
  while (std::getline(in, name, ',')) {
    if (name.empty()) continue;
    out.push_back(assessment::ParseCalibrationParam(name));
  }
  return out;
}

// MuJoCo costs ~0.1 s per trial: fewer evaluations and a bootstrap that
// reuses them unless asked otherwise (docs/adaptive.md).
constexpr int kArenaEvaluations = 150, kMujocoEvaluations = 40;
// The identifiability profile's scales over the bounds (six more near the fit).
constexpr int kArenaProfilePoints = 12, kMujocoProfilePoints = 6;
// MuJoCo's coupled sliding fingers hand the load back and forth from one
// sample to the next (calibration.hpp): its forces are compared as 40 ms means.
constexpr double kMujocoForceWindow = 0.04;

// The MuJoCo knobs a calibration runs with: --predictor-settings, else the
// campaign's own mujoco prediction knobs, else the simulator's defaults.
std::string MujocoKnobs(const CalibrateOptions& o, const nlohmann::json& prediction) {
  if (!o.predictor_settings.empty()) return o.predictor_settings;
  if (!prediction.is_object() || prediction.value("predictor", "arena") != "mujoco") return "{}";
  nlohmann::json knobs = prediction;
  for (const char* k : {"predictor", "calibration", "calibrated", "start"}) knobs.erase(k);
  return knobs.dump();
}

// The fit, its bootstrap interval, its profile range (the scales that fit
// as well), and a sentence for each parameter the data do not bound.
void PrintFittedTable(const assessment::CalibrationResult& r) {
  std::printf("%-12s %9s %9s %21s   %-26s %s\n", "parameter", "scale", "+-std",
              "95% CI (bootstrap)", "fits as well (profile)", "value");
  auto side = [](double v, bool bounded) {
    char buf[32];
    if (bounded)
      std::snprintf(buf, sizeof buf, "%8.4f", v);
    else
      std::snprintf(buf, sizeof buf, "%.4g bound", v);
    return std::string(buf);
  };
  for (const auto& f : r.fitted) {
    std::printf("%-12s %9.4f %9.4f   [%8.4f, %8.4f] ", f.name.c_str(), f.scale, f.std, f.ci_low,
                f.ci_high);
    std::string range = "-";
    if (f.profiled)
      range = "[" + side(f.profile_low, f.bounded_low) + ", " +
              side(f.profile_high, f.bounded_high) + "]";
    std::printf("  %-26s ", range.c_str());
    if (f.nominal)
      std::printf("%.4g -> %.4g\n", *f.nominal, *f.nominal * f.scale);
    else
      std::printf("(varies)\n");
  }
  for (const auto& f : r.fitted) {
    if (f.identified()) continue;
    std::printf(
        "\n%s: NOT IDENTIFIED by these trials: no scale from %.4g%s to %.4g%s fits them "
        "measurably worse than %.4g (by more than %.0f %% of its loss and a paired signed-rank "
        "test at %.0f standard deviations), so the "
        "fitted value is one of many and its bootstrap interval understates that. Trials in "
        "which it changes the outcome would bound it.\n",
        f.name.c_str(), f.profile_low, f.bounded_low ? "" : " (the lower bound)", f.profile_high,
        f.bounded_high ? "" : " (the upper bound)", f.scale, 100 * assessment::kProfileMinIncrease,
        assessment::kProfileStandardErrors);
  }
  for (const auto& f : r.fitted) {
    const std::string warning = assessment::BootstrapWarning(f);
    if (!warning.empty()) std::printf("\n%s\n", warning.c_str());
  }
}

// The arena model a calibration fits: the campaign's prediction settings,
// overridden by --predictor-settings (facets, points, dt, reduce, contacts),
// e.g. to fit at the cell's fidelity rather than the campaign's coarser one.
nlohmann::json ArenaModelSettings(const std::string& text, nlohmann::json model) {
  if (text.empty()) return model;
  nlohmann::json given;
  try {
    given = nlohmann::json::parse(text);
  } catch (const nlohmann::json::out_of_range& e) {  // 1e999: valid JSON, no double holds it
    throw CommandError(kExitBadInput,
                       std::string("--predictor-settings: a number out of range (beyond a "
                                   "double): ") +
                           e.what());
  } catch (const nlohmann::json::exception& e) {
    throw CommandError(kExitBadInput, std::string("--predictor-settings: not JSON: ") + e.what());
  }
  if (!given.is_object())
    throw CommandError(kExitBadInput, "--predictor-settings: must be a JSON object");
  if (!model.is_object()) model = nlohmann::json::object();
  for (const auto& [key, value] : given.items()) {
    if (key != "facets" && key != "points" && key != "dt" && key != "reduce" && key != "contacts")
      throw CommandError(kExitBadInput, "--predictor-settings: '" + key +
                                            "' is not an arena model setting (facets, points, "
                                            "dt, reduce, contacts)");
    model[key] = value;
  }
  return model;
}

std::string NmseText(const assessment::SetFigures& f) {
  if (!f.nmse) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f", f.nmse->mean);
  return buf;
}

std::string PairText(double median, double p95, double scale) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.3g/%.3g", median * scale, p95 * scale);
  return buf;
}

// The fitted and held-out trials' figures before and after, as `arena
// evaluate` gives them.
void PrintFigures(const assessment::CalibrationResult& r) {
  std::printf("%-22s %6s %7s %-20s %16s %18s\n", "", "trials", "NMSE", "dx/dy/dtheta",
              "pos mm med/p95", "angle deg med/p95");
  auto row = [](const char* name, const assessment::SetFigures& f) {
    if (f.trials == 0) return;
    char parts[64] = "-";
    if (f.nmse)
      std::snprintf(parts, sizeof parts, "%.3f/%.3f/%.3f", f.nmse->dx, f.nmse->dy, f.nmse->dtheta);
    char trials[32];
    std::snprintf(trials, sizeof trials, "%d/%d", f.predicted, f.trials);
    std::printf("%-22s %6s %7s %-20s %16s %18s\n", name, trials, NmseText(f).c_str(), parts,
                PairText(f.position_median, f.position_p95, 1e3).c_str(),
                PairText(f.angle_median, f.angle_p95, 180 / M_PI).c_str());
  };
  row("fitted, before", r.train_figures_before);
  row("fitted, after", r.train_figures_after);
  row("held out, before", r.heldout_figures_before);
  row("held out, after", r.heldout_figures_after);
}

// Stores one fit (waiting out a locked store; any other store failure
// keeps it in a file) and returns its id; *result: its JSON.
std::int64_t StoreResult(db::Store& store, const CalibrateOptions& o,
                         const assessment::CalibrationOptions& co, const nlohmann::json& model,
                         const simulators::Simulator* simulator,
                         const assessment::CalibrationResult& r, const nlohmann::json& split,
                         const nlohmann::json& start, nlohmann::json* result) {
  db::Calibration cal;
  cal.campaign_id = o.campaign;
  cal.params_json = assessment::ParamsJson(r);
  nlohmann::json predictor_settings = nullptr;
  if (simulator) predictor_settings = nlohmann::json::parse(simulator->settings_json());
  nlohmann::json settings{{"params", o.params},
                          {"predictor", o.predictor},
                          {"predictor_settings", predictor_settings},
                          {"bootstrap_method", r.bootstrap_method},
                          {"model", model},
                          {"holdout", o.holdout},
                          {"bootstrap", o.bootstrap},
                          {"max_evaluations", co.max_evaluations},
                          {"seed", o.seed},
                          {"bounds", {o.lower, o.upper}},
                          {"profile_points", co.profile_points},
                          {"loss", o.loss},
                          {"loss_scales",
                           {{"position_m", co.scales.position_m},
                            {"angle_rad", co.scales.angle_rad},
                            {"force_n", co.scales.force_n},
                            {"force_window_s", co.scales.force_window_s}}}};
  if (!split.is_null()) settings["split"] = split;
  settings["start"] = start;  // where the fit's predictions start (issue 26)
  cal.settings_json = settings.dump();
  cal.heldout_error_before = r.heldout_ids.empty() ? r.train_before : r.heldout_before;
  cal.heldout_error_after = r.heldout_ids.empty() ? r.train_after : r.heldout_after;
  cal.applied = r.improved;
  cal.report_json = assessment::ReportJson(r);
  std::int64_t id = 0;
  *result = {{"id", nullptr},
             {"campaign", o.campaign},
             {"applied", r.improved},
             {"predictor", o.predictor},
             {"start", start},
             {"params", nlohmann::json::parse(cal.params_json)},
             {"report", nlohmann::json::parse(cal.report_json)}};
  if (!split.is_null()) (*result)["split"] = split;
  // The fit is done: a store locked by another process is waited for (Ctrl-C
  // or any other store failure keeps the result in a file), never a reason
  // to throw it away.
  const std::string rescue =
      o.out_path.empty() ? RescuePath("calibration", o.campaign) : o.out_path;
  std::atomic<bool> cancel{false};
  SignalWatcher signals([&cancel](int) { cancel.store(true); });
  try {
    db::RetryWhileBusy([&] { id = store.RecordCalibration(cal); },
                       BusyStoreNotice("calibrate", rescue, [&cancel] { return cancel.load(); }));
  } catch (const db::StoreError& e) {
    (*result)["settings"] = nlohmann::json::parse(cal.settings_json);
    (*result)["heldout_error"] = {{"before", cal.heldout_error_before},
                                  {"after", cal.heldout_error_after}};
    (*result)["not_stored"] = e.what();
    WriteResultFile(rescue, result->dump(2) + "\n");
    throw CommandError(ExitCodeFor(e),
                       "calibrate: finished, but the store did not take the result (" +
                           UserMessage(e.what()) + "); the result is saved in " + rescue);
  }
  (*result)["id"] = id;
  return id;
}

// The fit's options from the command line (the predictor's defaults where unset).
assessment::CalibrationOptions FitOptions(const CalibrateOptions& o, bool mujoco) {
  assessment::CalibrationOptions co;
  if (o.bootstrap_method.empty()) {
    co.bootstrap_method =
        mujoco ? assessment::BootstrapMethod::kReuse : assessment::BootstrapMethod::kRefit;
  } else if (o.bootstrap_method == "refit" || o.bootstrap_method == "reuse") {
    co.bootstrap_method = o.bootstrap_method == "reuse" ? assessment::BootstrapMethod::kReuse
                                                        : assessment::BootstrapMethod::kRefit;
  } else {
    throw CommandError(kExitBadInput, "--bootstrap-method: must be refit or reuse, got '" +
                                          o.bootstrap_method + "'");
  }
  try {
    co.params = ParseParams(o.params);
  } catch (const assessment::CalibrationError& e) {
    throw CommandError(kExitBadInput, e.what());
  }
  if (o.loss != "pose" && o.loss != "nmse")
    throw CommandError(kExitBadInput, "--loss: must be pose or nmse, got '" + o.loss + "'");
  co.outcome_loss = o.loss == "nmse";
  co.holdout = o.holdout;
  co.bootstrap = o.bootstrap;
  co.scales.force_window_s =
      o.force_window >= 0 ? o.force_window : (mujoco ? kMujocoForceWindow : 0.0);
  co.max_evaluations =
      o.max_evaluations > 0 ? o.max_evaluations : (mujoco ? kMujocoEvaluations : kArenaEvaluations);
  co.profile_points = o.profile_points >= 0 ? o.profile_points
                                            : (mujoco ? kMujocoProfilePoints : kArenaProfilePoints);
  co.seed = o.seed;
  co.threads = o.threads;
  co.lower = o.lower;
  co.upper = o.upper;
  return co;
}

// What a calibration fits: the campaign's done trials, each scene with the
// campaign's prediction settings, started where `--from` says (issue 26: from
// the start pose each trial's cell measured, like evaluate; or planned).
struct FitInput {
  std::unique_ptr<db::Store> store;
  std::vector<assessment::CalibrationTrial> trials;
  nlohmann::json model;
  std::unique_ptr<simulators::Simulator> simulator;
  assessment::StartFrom from = assessment::StartFrom::kMeasured;
  int moved = 0;  // trials whose measured start is not the planned pose
};

// Each trial's scene placed at its measured start (the first sample of its
// stream, as evaluate takes it). @throws CommandError naming the trial when
// the start leaves the grasp.
void StartFromMeasured(FitInput& in) {
  for (auto& t : in.trials) {
    const auto gt = in.store->ReadGroundTruth(t.trial_id);
    const db::Sample* first = gt.samples.empty() ? nullptr : &gt.samples.front();
    const assessment::PredictionStart start = assessment::StartOf(t.scene, first, in.from);
    try {
      t.scene = assessment::StartedAt(t.scene, start);
    } catch (const std::exception& e) {
      throw CommandError(kExitBadInput, "trial " + std::to_string(t.trial_id) +
                                            ": its measured start: " + e.what() +
                                            " (--from planned fits from the planned pose)");
    }
    if (start.offset_m > 0 || start.offset_rad > 0) ++in.moved;
  }
}

FitInput LoadFitInput(const CalibrateOptions& o, bool mujoco) {
  FitInput in;
  const auto from = assessment::StartFromString(o.from);
  if (!from)
    throw CommandError(kExitBadInput, "--from: must be measured or planned, got '" + o.from + "'");
  in.from = *from;
  RefuseToOverwriteStore(o.out_path, "--out", o.db_path);
  auto& store = in.store;
  auto& model = in.model;
  auto& trials = in.trials;
  try {
    db::StoreOptions so;
    so.scene_facts = orchestrator::SceneFactsOfJson;  // an older store's migration reads scenes
    so.create = false;  // calibrating needs a campaign: a missing file is an error
    store = db::Store::Open(o.db_path, so);
    const db::Campaign campaign = store->GetCampaign(o.campaign);
    const auto spec = nlohmann::json::parse(campaign.spec_json);
    if (spec.contains("prediction")) model = spec["prediction"];
    // Fit against the uncalibrated model: a previous calibration is not stacked.
    if (model.is_object()) model.erase("calibrated");
    if (!mujoco) model = ArenaModelSettings(o.predictor_settings, model);
    trials = assessment::LoadCalibrationTrials(*store, o.campaign, [&](const mechanics::Scene& s) {
      mechanics::Scene fitted = assessment::ApplyModelSettings(s, model);
      mechanics::ValidateScene(fitted);
      return fitted;
    });
    if (in.from == assessment::StartFrom::kMeasured) StartFromMeasured(in);
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  } catch (const mechanics::SceneError& e) {
    throw CommandError(kExitBadInput, std::string("--predictor-settings: ") + e.what());
  }
  auto& simulator = in.simulator;
  if (mujoco) {
    try {
      simulator = simulators::MakeSimulator("mujoco", MujocoKnobs(o, model));
    } catch (const simulators::SimulatorError& e) {
      throw CommandError(kExitBadInput, std::string("--predictor-settings: ") + e.what());
    }
    for (const auto& t : trials) {  // refused up front, not a loss of 1e4 per trial
      if (std::string why = simulator->CheckScene(t.scene); !why.empty())
        throw CommandError(kExitBadInput,
                           "--predictor mujoco: trial " + std::to_string(t.trial_id) + ": " + why);
    }
  }

  return in;
}

using Splits = std::vector<std::pair<std::string, std::vector<std::int64_t>>>;

// A split by a trial parameter: one fit per value, its trials held out.
Splits SplitsOf(const CalibrateOptions& o, const FitInput& in) {
  const auto& store = in.store;
  const auto& trials = in.trials;
  std::vector<std::pair<std::string, std::vector<std::int64_t>>> splits;
  if (!o.holdout_by.empty()) {
    const TrialParameters parameters(o.trial_parameters, "--trial-parameters");
    std::map<std::int64_t, db::Trial> by_id;
    try {
      for (auto& t : store->ListTrials(o.campaign)) by_id.emplace(t.id, std::move(t));
    } catch (const db::StoreError& e) {
      throw StoreCommandError(e);
    }
    std::map<std::string, std::vector<std::int64_t>> groups;
    for (const auto& t : trials)
      groups[parameters.Value(by_id.at(t.trial_id), o.holdout_by, "--holdout-by")].push_back(
          t.trial_id);
    if (groups.size() < 2)
      throw CommandError(kExitBadInput, "--holdout-by: every trial has " + o.holdout_by + " = " +
                                            groups.begin()->first +
                                            ": a split needs at least two values");
    for (auto& [value, ids] : groups) splits.emplace_back(value, std::move(ids));
  } else if (!o.trial_parameters.empty()) {
    throw CommandError(kExitBadInput, "--trial-parameters: only with --holdout-by");
  }
  return splits;
}

std::vector<assessment::CalibrationResult> RunFits(const FitInput& in,
                                                   assessment::CalibrationOptions co,
                                                   const Splits& splits, bool mujoco) {
  const auto& trials = in.trials;
  const auto& simulator = in.simulator;
  // A bar over the main fit's evaluations on a terminal (silent otherwise).
  ProgressLine bar(co.max_evaluations, "loss evaluations");
  if (bar.enabled()) {
    co.on_evaluation = [&bar](int n, int, double loss, double best) {
      char extra[96];
      std::snprintf(extra, sizeof extra, "loss %.4g, best %.4g", loss, best);
      bar.Update(n, 0, extra);
    };
    co.progress = [&bar](const std::string& line) {
      bar.Finish();
      std::fprintf(stderr, "calibrate: %s\n", line.c_str());
    };
  }

  std::vector<assessment::CalibrationResult> results;
  try {
    const auto simulate = [](const mechanics::Scene& s) { return mechanics::Simulate(s); };
    if (splits.empty()) {
      results.push_back(mujoco ? assessment::Calibrate(trials, *simulator, co)
                               : assessment::Calibrate(trials, simulate, co));
    } else if (!mujoco) {
      std::vector<std::vector<std::int64_t>> sets;
      for (const auto& [value, ids] : splits) sets.push_back(ids);
      results = assessment::CalibrateSplits(trials, simulate, co, sets);
    } else {
      for (const auto& [value, ids] : splits) {
        assessment::CalibrationOptions so = co;
        so.heldout_ids = ids;
        results.push_back(assessment::Calibrate(trials, *simulator, so));
      }
    }
  } catch (const assessment::CalibrationError& e) {
    throw CommandError(kExitBadInput, e.what());
  }
  bar.Finish();
  return results;
}

void PrintSplitResults(const CalibrateOptions& o,
                       const std::vector<assessment::CalibrationResult>& results,
                       const Splits& splits, const std::vector<std::int64_t>& ids,
                       const assessment::SetFigures& pooled_before,
                       const assessment::SetFigures& pooled_after, std::size_t pooled_trials) {
  std::printf(
      "calibration of campaign %lld held out by %s: %zu fits (predictor %s), each on every "
      "trial but one %s's, scored on that %s's trials\n",
      static_cast<long long>(o.campaign), o.holdout_by.c_str(), results.size(), o.predictor.c_str(),
      o.holdout_by.c_str(), o.holdout_by.c_str());
  for (std::size_t k = 0; k < results.size(); ++k) {
    const auto& r = results[k];
    std::printf(
        "\n== held out: %s = %s (%zu trials; fitted on %zu; calibration %lld, %s; %d "
        "loss evaluations, %ld new simulations)\n",
        o.holdout_by.c_str(), splits[k].first.c_str(), r.heldout_ids.size(), r.train_ids.size(),
        static_cast<long long>(ids[k]),
        r.improved ? "applied" : "NOT applied: no lower held-out loss", r.evaluations,
        r.simulations);
    PrintFittedTable(r);
    std::printf("\n");
    PrintFigures(r);
  }
  std::printf("\nsummary, held out by %s:\n", o.holdout_by.c_str());
  std::printf("  %-10s %6s %-34s %16s %16s %18s %18s\n", "held out", "trials", "fitted",
              "NMSE before", "NMSE after", "pos mm med/p95", "angle deg med/p95");
  for (std::size_t k = 0; k < results.size(); ++k) {
    const auto& r = results[k];
    std::string fitted;
    for (const auto& f : r.fitted) {
      char buf[64];
      if (f.nominal)
        std::snprintf(buf, sizeof buf, "%s%s %.3g", fitted.empty() ? "" : ", ", f.name.c_str(),
                      *f.nominal * f.scale);
      else
        std::snprintf(buf, sizeof buf, "%s%s x%.3g", fitted.empty() ? "" : ", ", f.name.c_str(),
                      f.scale);
      fitted += buf;
    }
    std::printf(
        "  %-10s %6zu %-34s %16s %16s %18s %18s\n", splits[k].first.c_str(), r.heldout_ids.size(),
        fitted.c_str(), NmseText(r.heldout_figures_before).c_str(),
        NmseText(r.heldout_figures_after).c_str(),
        PairText(r.heldout_figures_after.position_median, r.heldout_figures_after.position_p95, 1e3)
            .c_str(),
        PairText(r.heldout_figures_after.angle_median, r.heldout_figures_after.angle_p95,
                 180 / M_PI)
            .c_str());
  }
  std::printf("  %-10s %6zu %-34s %16s %16s %18s %18s\n", "pooled", pooled_trials,
              "(each trial by the fit without it)", NmseText(pooled_before).c_str(),
              NmseText(pooled_after).c_str(),
              PairText(pooled_after.position_median, pooled_after.position_p95, 1e3).c_str(),
              PairText(pooled_after.angle_median, pooled_after.angle_p95, 180 / M_PI).c_str());
  std::printf(
      "  (NMSE: of dx, dy, dtheta in the object's initial frame over the held-out trials' own "
      "variance; pooled: over every trial, each predicted by the fit that did not see its %s)\n",
      o.holdout_by.c_str());
}

void PrintResult(const CalibrateOptions& o, const assessment::CalibrationResult& r, std::int64_t id,
                 bool mujoco) {
  std::printf(
      "calibration %lld of campaign %lld (predictor %s, %s, %d loss evaluations, %zu trials "
      "fitted, %zu held out)\n",
      static_cast<long long>(id), static_cast<long long>(o.campaign), o.predictor.c_str(),
      r.optimizer.c_str(), r.evaluations, r.train_ids.size(), r.heldout_ids.size());
  std::printf("%ld simulations", r.simulations);
  if (mujoco) std::printf(" (%ld on a model built once per trial)", r.models_reused);
  std::printf("; uncertainty: %d bootstrap resamples (%s)\n\n", o.bootstrap,
              r.bootstrap_method.c_str());
  PrintFittedTable(r);
  if (!r.heldout_ids.empty()) {
    std::printf("\nheld-out error       before      after\n");
    std::printf("  loss (weighted) %10.4g %10.4g\n", r.heldout_before, r.heldout_after);
    std::printf("  position (mm)   %10.4f %10.4f\n", r.heldout_position_before * 1e3,
                r.heldout_position_after * 1e3);
    std::printf("  angle (deg)     %10.4f %10.4f\n", r.heldout_angle_before * 57.29577951,
                r.heldout_angle_after * 57.29577951);
    std::printf("  force RMS (N)   %10.4f %10.4f\n", r.heldout_force_before, r.heldout_force_after);
  }
  std::printf("\n");
  PrintFigures(r);
  if (r.improved) {
    std::printf("\napplied: a campaign uses it with \"prediction\": {\"calibration\": %lld}\n",
                static_cast<long long>(id));
  } else {
    std::printf("\nNOT applied: the fit does not lower the %s error\n",
                r.heldout_ids.empty() ? "fitted trials'" : "held-out");
  }
}

const char* StartText(const FitInput& in) {
  return in.from == assessment::StartFrom::kPlanned
             ? "start: from the planned pose (--from planned): errors include the reset's "
               "placement"
             : "start: from the pose each trial's cell measured (as evaluate)";
}

int RunCalibrate(const CalibrateOptions& o) {
  if (o.predictor != "arena" && o.predictor != "mujoco") {
    throw CommandError(kExitBadInput,
                       "--predictor: '" + o.predictor + "' is not a predictor (arena or mujoco)");
  }
  const bool mujoco = o.predictor == "mujoco";
  const assessment::CalibrationOptions co = FitOptions(o, mujoco);
  FitInput in = LoadFitInput(o, mujoco);
  const Splits splits = SplitsOf(o, in);
  const std::vector<assessment::CalibrationResult> results = RunFits(in, co, splits, mujoco);
  const nlohmann::json start = {{"from", assessment::ToString(in.from)},
                                {"trials_moved", in.moved}};
  std::vector<std::int64_t> ids;
  nlohmann::json results_json = nlohmann::json::array();
  for (std::size_t k = 0; k < results.size(); ++k) {
    nlohmann::json split = nullptr;
    if (!splits.empty()) split = {{"holdout_by", o.holdout_by}, {"heldout_value", splits[k].first}};
    nlohmann::json result;
    ids.push_back(StoreResult(*in.store, o, co, in.model, in.simulator.get(), results[k], split,
                              start, &result));
    results_json.push_back(std::move(result));
  }
  bool all_improved = true;
  for (const auto& r : results) all_improved = all_improved && r.improved;
  nlohmann::json output = results_json.front();
  if (!splits.empty()) {
    // Every trial predicted by the fit that did not see its group.
    std::vector<assessment::TrialError> before, after;
    for (const auto& r : results) {
      before.insert(before.end(), r.heldout_errors_before.begin(), r.heldout_errors_before.end());
      after.insert(after.end(), r.heldout_errors_after.begin(), r.heldout_errors_after.end());
    }
    const auto pooled_before = assessment::FiguresOf(before);
    const auto pooled_after = assessment::FiguresOf(after);
    output = {{"campaign", o.campaign},
              {"holdout_by", o.holdout_by},
              {"start", start},
              {"splits", results_json},
              {"pooled_heldout",
               {{"before", assessment::ToJson(pooled_before)},
                {"after", assessment::ToJson(pooled_after)}}},
              {"all_improved", all_improved}};
    if (!o.out_path.empty()) WriteResultFile(o.out_path, output.dump(2) + "\n");
    if (o.json) {
      std::printf("%s\n", output.dump().c_str());
      return all_improved ? kExitOk : kExitFailure;
    }
    std::printf("%s\n", StartText(in));
    PrintSplitResults(o, results, splits, ids, pooled_before, pooled_after, before.size());
    return all_improved ? kExitOk : kExitFailure;
  }
  const auto& r = results.front();
  if (!o.out_path.empty()) WriteResultFile(o.out_path, output.dump(2) + "\n");
  if (o.json) {
    std::printf("%s\n", output.dump().c_str());
  } else {
    std::printf("%s\n", StartText(in));
    PrintResult(o, r, ids.front(), mujoco);
  }
  return r.improved ? kExitOk : kExitFailure;
}

}  // namespace

void AddCalibrateCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<CalibrateOptions>();
  auto* cmd = app.add_subcommand(
      "calibrate", "Fit model parameters (friction, ...) to a campaign's ground truth");
  cmd->add_option("--db", o->db_path, "Store file")->required();
  cmd->add_option("--campaign", o->campaign, "Campaign id whose done trials are fitted")
      ->required()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--params", o->params,
                  "Comma-separated: mu_fingers, mu_pusher, grip_force, object_mass, mu_support, "
                  "pressure_rim (scales)")
      ->required();
  cmd->add_option("--predictor", o->predictor, "The model fitted: arena or mujoco");
  cmd->add_option("--predictor-settings", o->predictor_settings,
                  "The fitted model's settings as JSON: mujoco's knobs ({\"timestep\": 0.001}), or "
                  "arena's (facets, points, dt, reduce, contacts: over the campaign's prediction "
                  "settings); default: the campaign's prediction settings");
  cmd->add_option("--bootstrap-method", o->bootstrap_method,
                  "refit (each resample refitted) or reuse (the main fit's evaluated points, no "
                  "simulation); default refit for arena, reuse for mujoco");
  cmd->add_option("--profile-points", o->profile_points,
                  "Scales over the bounds at which each parameter's loss is profiled to check "
                  "that the data identify it (0: no profile; default 12 for arena, 6 for mujoco)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--holdout", o->holdout,
                  "Fraction of trials held out to judge the fit (0: fit and judge every trial)")
      ->check(CLI::Range(0.0, 0.9));
  cmd->add_option("--loss", o->loss,
                  "pose: final position (1 mm), angle (0.01 rad) and contact force (0.5 N) "
                  "errors; nmse: the NMSE of the push's outcome (dx, dy, dtheta in the object's "
                  "initial frame, each over its variance across the fitted trials)")
      ->capture_default_str();
  cmd->add_option("--holdout-by", o->holdout_by,
                  "Split by this trial parameter instead (e.g. shape): one fit per value, that "
                  "value's trials held out and every other fitted; a table per held-out value "
                  "and their pooled figures");
  cmd->add_option("--trial-parameters", o->trial_parameters,
                  "A CSV with a seed column whose rows give the trials of those seeds more "
                  "parameters (an imported dataset's trials.csv)");
  cmd->add_option("--bootstrap", o->bootstrap, "Resamples for the uncertainty (0: none)")
      ->check(CLI::Range(0, 1000));
  cmd->add_option("--max-evaluations", o->max_evaluations,
                  "Loss evaluations of the main fit (default 150 for arena, 40 for mujoco)")
      ->check(CLI::Range(5, 100000));
  cmd->add_option("--force-window", o->force_window,
                  "Compare contact forces as means over windows this long (s; 0: per sample; "
                  "default 0 for arena, 0.04 for mujoco)")
      ->check(CLI::Range(0.0, 10.0));
  cmd->add_option("--seed", o->seed, "Seed of the hold-out split and the bootstrap");
  cmd->add_option("--from", o->from,
                  "Where the fit's predictions start: measured (the start pose each trial's cell "
                  "measured, as evaluate) or planned (the scene's pose: the fit then also absorbs "
                  "the reset's placement error)")
      ->capture_default_str();
  cmd->add_option("--threads", o->threads, "Simulations in parallel")->check(CLI::Range(1, 256));
  cmd->add_option("--lower", o->lower, "Lower bound of every scale")->check(CLI::Range(0.01, 0.99));
  cmd->add_option("--upper", o->upper, "Upper bound of every scale")
      ->check(CLI::Range(1.01, 100.0));
  cmd->add_flag("--json", o->json, "JSON instead of a table");
  cmd->add_option("--out", o->out_path,
                  "Also write the result (JSON) to this file; a fit the store cannot take "
                  "(locked until Ctrl-C, full) is saved there too");
  cmd->footer(
      "Example:\n"
      "  arena calibrate --db lab.db --campaign 1 --params mu_fingers,mu_pusher --holdout 0.3\n"
      "  arena calibrate --db real.db --campaign 1 --params mu_pusher,mu_support --holdout-by "
      "shape --trial-parameters DATASET/trials.csv\n"
      "  arena calibrate --db lab.db --campaign 1 --params mu_fingers --predictor mujoco "
      "--threads 2\n"
      "Exit 0: stored and applied; 1: stored, but it did not lower the held-out error (not "
      "applied).\nLoss weights and method: docs/adaptive.md.\n");
  cmd->callback([o, action] { *action = [o] { return RunCalibrate(*o); }; });
}

}  // namespace arena::cli
