// arena evaluate --db FILE --campaign ID [--predictors arena] [--facets 4,8,16,32] [--points 3]
//                [--dt 0.008,0.004,0.002,0.001] [--reduce auto] [--contacts tracked]
//                [--pads elastic] [--cone polyhedral] [--inertia carried]
//                [--budget 1mm|2ms|1.5floor ...]
//                [--convergence-trials 8] [--threads N] [--from measured|planned] [--json]
// Replays a campaign's done trials through the model at every fidelity
// setting of the grid, stores the run (tables evaluations and
// evaluation_results) and prints the trade: a table or JSON.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "arena/assessment/evaluation.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "commands.hpp"
#include "output_guard.hpp"
#include "progress.hpp"
#include "result_file.hpp"
#include "signals.hpp"
#include "store_errors.hpp"
#include "trial_parameters.hpp"
#include "truth_relation.hpp"

namespace arena::cli {
namespace {

struct EvaluateOptions {
  std::string db_path;
  std::int64_t campaign = -1;
  std::vector<std::string> predictors{"arena"};
  std::vector<int> facets{4, 8, 16, 32};
  std::vector<int> points{3};
  std::vector<double> dt{0.008, 0.004, 0.002, 0.001};
  std::vector<std::string> reduce{"auto"};
  std::vector<std::string> contacts{"tracked"};
  std::vector<std::string> pads{mechanics::ToString(mechanics::ModelOptions{}.pads)};
  std::vector<std::string> cone{mechanics::ToString(mechanics::ModelOptions{}.cone)};
  std::vector<std::string> inertia{mechanics::ToString(mechanics::ModelOptions{}.inertia)};
  bool grid_given =
      false;  // any of --facets/--points/--dt/--reduce/--contacts/--pads/--cone/--inertia
  std::vector<double> mujoco_timestep{0.004, 0.002, 0.001, 0.0005};
  std::vector<std::string> mujoco_cone{"elliptic"};
  std::vector<int> mujoco_noslip{0};
  std::vector<std::string> mujoco_solref;  // "timeconst:dampratio" each
  std::vector<std::string> mujoco_solimp;  // "dmin:dmax:width:mid:power" each
  bool mujoco_grid_given = false;
  std::vector<std::string> budgets;
  int threads = 0;
  int convergence_trials = 8;
  bool json = false;
  std::string out_path;             // --out: the report as JSON, besides the store
  std::string from = "measured";    // --from: where predictions start (issue 26)
  std::int64_t calibration = 0;     // --calibration: its scales applied (0: none)
  std::vector<std::string> scales;  // --scale NAME=FACTOR, over --calibration's
  std::string group_by;             // --group-by: a trial parameter
  std::string trial_parameters;     // --trial-parameters: a CSV with a seed column
};

// The setting column's width: 24, or the longest key (a key naming opt-in
// choices, "..._cone-aligned_inertia-auto", would push its row's columns).
template <typename Settings>
int SettingWidth(const Settings& settings) {
  std::size_t w = 24;
  for (const auto& s : settings) w = std::max(w, s.model_key.size());
  return static_cast<int>(w);
}

// "start: ..." lines: where the predictions started and how much of the
// error the start pose explains (mm, degrees).
std::string FormatStart(const assessment::StartReport& r) {
  const int w = SettingWidth(r.settings);
  std::string out;
  char line[512];
  if (r.from == assessment::StartFrom::kPlanned) {
    return "start: predictions start from the planned pose (--from planned): their errors "
           "include the reset's placement error\n";
  }
  if (r.offset_position) {
    std::snprintf(line, sizeof line,
                  "start: predictions start from the pose each trial's cell measured (%d of the "
                  "trials' streams gave one), median %.3g mm and %.3g deg from the planned pose "
                  "(max %.3g mm, %.3g deg)\n",
                  r.measured_trials, r.offset_position->median * 1e3,
                  r.offset_angle->median * 180 / M_PI, r.offset_position->max * 1e3,
                  r.offset_angle->max * 180 / M_PI);
    out += line;
  }
  bool head = false;
  for (const auto& s : r.settings) {
    if (s.trials == 0) continue;
    if (!head) {
      out +=
          "start pose's share of the error (median final error from the planned start minus "
          "from the measured one):\n";
      std::snprintf(line, sizeof line, "  %-8s %-*s %6s %26s %26s\n", "predictor", w, "setting",
                    "trials", "pos mm planned/measured/+", "angle deg planned/measured/+");
      out += line;
      head = true;
    }
    char pos[64], ang[64];
    std::snprintf(pos, sizeof pos, "%.3g/%.3g/%+.3g", s.position_planned * 1e3,
                  s.position_measured * 1e3, (s.position_planned - s.position_measured) * 1e3);
    std::snprintf(ang, sizeof ang, "%.3g/%.3g/%+.3g", s.angle_planned * 180 / M_PI,
                  s.angle_measured * 180 / M_PI, (s.angle_planned - s.angle_measured) * 180 / M_PI);
    std::snprintf(line, sizeof line, "  %-8s %-*s %6d %26s %26s\n", s.predictor.c_str(), w,
                  s.model_key.c_str(), s.trials, pos, ang);
    out += line;
  }
  return out;
}

// "0.002:1" -> {0.002, 1}; exactly N finite numbers or a bad-input error
// naming the flag.
template <std::size_t N>
std::array<double, N> ParseColonList(const char* flag, const std::string& text) {
  std::array<double, N> out{};
  std::size_t start = 0, n = 0;
  while (true) {
    const std::size_t end = text.find(':', start);
    const std::string part = text.substr(start, end == std::string::npos ? end : end - start);
    std::size_t used = 0;
    double v = 0;
    try {
      v = std::stod(part, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != part.size() || !std::isfinite(v) || n >= N) break;
    out[n++] = v;
    if (end == std::string::npos) {
      if (n == N) return out;
      break;
    }
    start = end + 1;
  }
  throw CommandError(kExitBadInput, std::string(flag) + ": '" + text + "' must be " +
                                        std::to_string(N) + " numbers separated by ':'");
}

std::string Tail(const std::optional<assessment::Distribution>& d, double scale) {
  if (!d) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3g/%.3g/%.3g", d->median * scale, d->p95 * scale,
                d->max * scale);
  return buf;
}

std::string TrialIds(const std::vector<assessment::TrialNote>& notes, std::size_t limit) {
  std::string out;
  for (std::size_t i = 0; i < notes.size() && i < limit; ++i) {
    if (!out.empty()) out += ' ';
    out += std::to_string(notes[i].trial_id);
  }
  if (notes.size() > limit) out += " ...";
  return out;
}

std::string MedianP95(const std::optional<assessment::Distribution>& d, double scale) {
  if (!d) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3g/%.3g", d->median * scale, d->p95 * scale);
  return buf;
}

// The outcome table: per setting, the NMSE of (dx, dy, dtheta) and the final
// pose, force and time figures beside it.
std::string OutcomeTable(const std::vector<assessment::SettingSummary>& settings) {
  const int w = SettingWidth(settings);
  std::ostringstream out;
  char line[640];
  std::snprintf(line, sizeof line, "  %-8s %-*s %6s %6s %-20s %16s %16s %20s %13s\n", "predictor",
                w, "setting", "scored", "NMSE", "dx/dy/dtheta", "pos mm med/p95",
                "angle deg med/p95", "force N med/p95 (n)", "ms/trial med");
  out << line;
  for (const auto& s : settings) {
    char nmse[24] = "-", parts[48] = "-", force[64] = "-";
    if (s.nmse) {
      std::snprintf(nmse, sizeof nmse, "%.3f", s.nmse->mean);
      std::snprintf(parts, sizeof parts, "%.3f/%.3f/%.3f", s.nmse->dx, s.nmse->dy, s.nmse->dtheta);
    }
    if (s.force)
      std::snprintf(force, sizeof force, "%s (%d)", MedianP95(s.force, 1).c_str(), s.force_trials);
    char scored[24];
    std::snprintf(scored, sizeof scored, "%d/%d", s.ok, s.trials);
    std::snprintf(line, sizeof line, "  %-8s %-*s %6s %6s %-20s %16s %16s %20s %13.3g\n",
                  s.predictor.c_str(), w, s.model_key.c_str(), scored, nmse, parts,
                  MedianP95(s.position, 1e3).c_str(), MedianP95(s.angle, 180 / M_PI).c_str(), force,
                  s.time.median * 1e3);
    out << line;
    if (!s.nmse && !s.nmse_note.empty()) out << "    (no NMSE: " << s.nmse_note << ")\n";
  }
  return out.str();
}

// The settings whose predictions carry a run flag (`count` of a setting's
// ok trials): a section headed `heading`, one line each, only when any does.
void PrintFlagged(std::ostream& out, const assessment::EvaluationReport& r, int w,
                  int assessment::SettingSummary::*count, const char* heading) {
  bool any = false;
  for (const auto& s : r.settings) any = any || s.*count > 0;
  if (!any) return;
  out << "\n" << heading << ", of the ok trials:\n";
  char line[256];
  for (const auto& s : r.settings) {
    std::snprintf(line, sizeof line, "  %-8s %-*s %d of %d\n", s.predictor.c_str(), w,
                  s.model_key.c_str(), s.*count, s.ok);
    out << line;
  }
}

// The settings whose predictions the friction cones steered (their answer
// moves with the facets), and those that ended swinging (their final pose
// a phase of it).
void PrintSteered(std::ostream& out, const assessment::EvaluationReport& r, int w) {
  PrintFlagged(out, r, w, &assessment::SettingSummary::steered,
               "steered slip (a cone's friction acted across a slide and turned it towards the "
               "cone's edges, so the answer moves with facets; \"cone\": \"aligned\" models a "
               "free slide)");
  PrintFlagged(out, r, w, &assessment::SettingSummary::oscillating,
               "oscillating (the run ended in a swing nothing damps, so its final pose is a phase "
               "of it; \"inertia\": \"auto\" follows the balanced path of a held object)");
}

std::string FormatTable(const assessment::EvaluationReport& r, std::int64_t evaluation_id) {
  const int w = SettingWidth(r.settings);
  std::ostringstream out;
  char line[640];
  std::snprintf(line, sizeof line,
                "campaign %lld: %d done trials replayed at %zu settings of %zu predictor(s) "
                "(evaluation %lld)\n",
                static_cast<long long>(r.campaign_id), r.trials, r.settings.size(),
                r.predictors.size(), static_cast<long long>(evaluation_id));
  out << line;
  out << "truth: " << r.truth.source << " -- " << r.truth.statement << "\n";
  if (!r.scales.empty()) {
    out << "calibrated: every scene scaled before prediction:";
    for (const auto& [name, k] : r.scales) {
      std::snprintf(line, sizeof line, " %s x%.4g", name.c_str(), k);
      out << line;
    }
    out << "\n";
  }
  const double floor_m = r.floor ? r.floor->position_median : 0;
  if (r.floor) {
    std::snprintf(line, sizeof line,
                  "noise floor (replicate spread of the true final pose, %d conditions with >= 2 "
                  "replicates): position median %.3g mm, p95 %.3g mm; angle median %.3g deg, p95 "
                  "%.3g deg\n",
                  r.floor->conditions, r.floor->position_median * 1e3, r.floor->position_p95 * 1e3,
                  r.floor->angle_median * 180 / M_PI, r.floor->angle_p95 * 180 / M_PI);
  } else {
    std::snprintf(line, sizeof line,
                  "noise floor: none (no condition has 2 replicates; errors cannot be judged "
                  "against replicate spread)\n");
  }
  out << line;
  std::snprintf(line, sizeof line, "%-8s %-*s %9s %20s %9s %20s %17s %15s %15s %s\n", "predictor",
                w, "setting", "ok/div/fail", "pos mm med/p95/max", "p95/floor",
                "angle deg med/p95/max", "mode med/p5/min", "ms/trial med/p95", "ms per sim s", "");
  out << line;
  for (std::size_t i = 0; i < r.settings.size(); ++i) {
    const auto& s = r.settings[i];
    std::string marks;
    if (s.pareto) marks += " front";
    if (s.within_budget) marks += " in-budget";
    if (r.recommended && *r.recommended == i) marks += " <== recommended";
    char counts[48];
    std::snprintf(counts, sizeof counts, "%d/%d/%d", s.ok, s.diverged, s.failures);
    char multiple[32] = "-";
    if (s.position && floor_m > 0)
      std::snprintf(multiple, sizeof multiple, "%.2fx", s.position->p95 / floor_m);
    char mode[48] = "-";
    if (s.mode_agreement) {
      std::snprintf(mode, sizeof mode, "%.3f/%.3f/%.3f", s.mode_agreement->median,
                    s.mode_agreement->p95, s.mode_agreement->max);
    }
    char time[48];
    std::snprintf(time, sizeof time, "%.3g/%.3g", s.time.median * 1e3, s.time.p95 * 1e3);
    char per_sim[32] = "-";
    if (s.time_per_sim_s)
      std::snprintf(per_sim, sizeof per_sim, "%.3g", s.time_per_sim_s->median * 1e3);
    std::snprintf(line, sizeof line, "%-8s %-*s %11s %20s %9s %20s %17s %15s %15s%s\n",
                  s.predictor.c_str(), w, s.model_key.c_str(), counts,
                  Tail(s.position, 1e3).c_str(), multiple, Tail(s.angle, 180 / M_PI).c_str(), mode,
                  time, per_sim, marks.c_str());
    out << line;
  }
  out << "\nworst trials (largest final position error; `arena plot --db FILE TRIAL`), "
         "divergences and failures:\n";
  for (const auto& s : r.settings) {
    if (s.worst.empty() && s.diverged_trials.empty() && s.failed_trials.empty()) continue;
    out << "  " << s.predictor << " " << s.model_key << ":";
    if (!s.worst.empty()) {
      out << " worst";
      for (const auto& w : s.worst) {
        std::snprintf(line, sizeof line, " %lld (%.3g mm)", static_cast<long long>(w.trial_id),
                      w.value * 1e3);
        out << line;
      }
    }
    if (!s.diverged_trials.empty())
      out << "; diverged/left grasp " << s.diverged_trials.size() << ": "
          << TrialIds(s.diverged_trials, 10) << " (" << s.diverged_trials.front().reason << ")";
    if (!s.failed_trials.empty())
      out << "; failed " << s.failed_trials.size() << ": " << TrialIds(s.failed_trials, 10) << " ("
          << s.failed_trials.front().reason << ")";
    out << "\n";
  }
  PrintSteered(out, r, w);
  out << "\nconvergence against each predictor's finest setting (pieces restarted from the true "
         "state) beside the error against the truth, final position mm med/p95:\n";
  for (const auto& s : r.settings) {
    std::snprintf(
        line, sizeof line, "  %-8s %-*s discretisation %-17s vs truth %s%s\n", s.predictor.c_str(),
        w, s.model_key.c_str(),
        s.convergence
            ? (Tail(std::optional<assessment::Distribution>(s.convergence->position), 1e3) + " (" +
               std::to_string(s.convergence->pieces) + " pieces)")
                  .c_str()
            : "-",
        Tail(s.position, 1e3).c_str(), s.finest ? "  (finest)" : "");
    out << line;
  }
  out << "\noutcome: NMSE of the push's outcome (dx, dy, dtheta: the object's final pose in its "
         "initial frame; each output's mean squared error over its variance across the trials "
         "scored, averaged over the three; 1 = predicting the mean outcome), final position and "
         "angle error, force error against the measured force (n: trials whose force was "
         "scored), wall time per trial:\n";
  out << OutcomeTable(r.settings);
  for (const auto& g : r.groups) {
    out << "\n" << r.group_by << " = " << g.value << " (" << g.trials << " trials):\n";
    out << OutcomeTable(g.settings);
  }
  out << "\nfront: " << r.front << "\n";
  out << "recommendation: " << r.recommendation << "\n";
  return out.str();
}

// One grid axis of named choices: each text through `parse`, or bad input
// naming the option and what it takes.
template <typename Parse>
auto ChoiceList(const std::vector<std::string>& texts, const char* option, const char* takes,
                Parse parse) {
  std::vector<typename decltype(parse(std::string_view()))::value_type> out;
  for (const auto& t : texts) {
    const auto value = parse(t);
    if (!value) {
      throw CommandError(kExitBadInput,
                         std::string(option) + ": must be " + takes + ", got '" + t + "'");
    }
    out.push_back(*value);
  }
  return out;
}

// --facets, --points, --dt, --reduce, --contacts, --pads, --cone, --inertia:
// the arena predictor's grid.
assessment::FidelityGrid ArenaGrid(const EvaluateOptions& o) {
  assessment::FidelityGrid grid;
  grid.facets = o.facets;
  grid.points = o.points;
  grid.dt = o.dt;
  grid.reduce.clear();
  for (const auto& r : o.reduce) {
    if (r == "auto")
      grid.reduce.push_back(mechanics::Reduce::kAuto);
    else if (r == "full")
      grid.reduce.push_back(mechanics::Reduce::kFull);
    else if (r == "planar")
      grid.reduce.push_back(mechanics::Reduce::kPlanar);
    else
      throw CommandError(kExitBadInput, "--reduce: must be auto, full or planar, got '" + r + "'");
  }
  grid.contacts.clear();
  for (const auto& m : o.contacts) {
    const auto mode = mechanics::ContactTrackingFromString(m);
    if (!mode) {
      throw CommandError(kExitBadInput, "--contacts: must be tracked or fixed, got '" + m + "'");
    }
    grid.contacts.push_back(*mode);
  }
  grid.pads = ChoiceList(o.pads, "--pads", "elastic or rigid", mechanics::PadModelFromString);
  grid.cone = ChoiceList(o.cone, "--cone", "polyhedral or aligned", mechanics::ConeModelFromString);
  grid.inertia = ChoiceList(o.inertia, "--inertia", "carried, quasi_static or auto",
                            mechanics::InertiaModelFromString);
  return grid;
}

// --predictors with their grids (arena's, MuJoCo's).
std::vector<assessment::PredictorRequest> PredictorRequests(const EvaluateOptions& o,
                                                            const assessment::FidelityGrid& grid) {
  std::vector<assessment::PredictorRequest> out;
  for (const auto& name : o.predictors) {
    assessment::PredictorRequest req;
    req.name = name;
    if (name == "arena" && o.grid_given) req.arena_grid = grid;
    if (name == "mujoco" && o.mujoco_grid_given) {
      req.mujoco_grid = assessment::MujocoGrid{o.mujoco_timestep, o.mujoco_cone, o.mujoco_noslip};
      if (!o.mujoco_solref.empty()) {
        req.mujoco_grid->solref.clear();
        for (const auto& v : o.mujoco_solref)
          req.mujoco_grid->solref.push_back(ParseColonList<2>("--mujoco-solref", v));
      }
      if (!o.mujoco_solimp.empty()) {
        req.mujoco_grid->solimp.clear();
        for (const auto& v : o.mujoco_solimp)
          req.mujoco_grid->solimp.push_back(ParseColonList<5>("--mujoco-solimp", v));
      }
    }
    out.push_back(req);
  }
  return out;
}

// The options that need no store: predictors, threads, start, budgets.
assessment::EvaluationOptions EvaluationOptionsOf(const EvaluateOptions& o) {
  assessment::EvaluationOptions eo;
  const assessment::FidelityGrid grid = ArenaGrid(o);
  eo.predictors = PredictorRequests(o, grid);
  if (o.threads < 0) throw CommandError(kExitBadInput, "--threads: must be >= 0 (0: one per core)");
  if (o.convergence_trials < 0)
    throw CommandError(kExitBadInput, "--convergence-trials: must be >= 0 (0: no table)");
  eo.threads = o.threads;
  eo.convergence_trials = o.convergence_trials;
  if (const auto from = assessment::StartFromString(o.from)) {
    eo.start_from = *from;
  } else {
    throw CommandError(kExitBadInput, "--from: must be measured or planned, got '" + o.from + "'");
  }
  try {
    for (const auto& b : o.budgets) eo.budgets.push_back(assessment::ParseBudget(b));
    if (o.grid_given) (void)assessment::ExpandGrid(grid);
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, std::string("evaluate: ") + e.what());
  }
  return eo;
}

// --calibration's fitted scales (a calibration of this campaign), then --scale's.
void ReadScales(const EvaluateOptions& o, const db::Store& store,
                assessment::EvaluationOptions* eo) {
  if (o.calibration > 0) {
    const db::Calibration cal = store.GetCalibration(o.calibration);
    if (cal.campaign_id != o.campaign)
      throw CommandError(kExitBadInput,
                         "--calibration: calibration " + std::to_string(o.calibration) +
                             " was fitted to campaign " + std::to_string(cal.campaign_id) +
                             ", not " + std::to_string(o.campaign));
    const auto fitted = nlohmann::json::parse(cal.params_json, nullptr, false);
    if (!fitted.is_object())
      throw CommandError(kExitBadInput, "--calibration: calibration " +
                                            std::to_string(o.calibration) +
                                            " has no fitted parameters");
    for (const auto& item : fitted.items())
      eo->scales[item.key()] = item.value().at("scale").get<double>();
  }
  for (const auto& text : o.scales) {
    const auto eq = text.find('=');
    double k = 0;
    std::size_t used = 0;
    const std::string name = text.substr(0, eq);
    try {
      if (eq != std::string::npos) k = std::stod(text.substr(eq + 1), &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (eq == std::string::npos || used == 0 || used != text.size() - eq - 1 || !std::isfinite(k) ||
        !(k > 0))
      throw CommandError(kExitBadInput, "--scale: '" + text +
                                            "' must be NAME=FACTOR with a factor > 0 (e.g. "
                                            "mu_pusher=1.2)");
    try {
      (void)assessment::ParseCalibrationParam(name);
    } catch (const assessment::CalibrationError& e) {
      throw CommandError(kExitBadInput, std::string("--scale: ") + e.what());
    }
    eo->scales[name] = k;
  }
}

// The report as JSON: the evaluation's, its start, and what the errors are
// measured against (self-consistent predictors, trials per truth and backend).
nlohmann::json EvaluationJson(const assessment::EvaluationRun& run,
                              const std::vector<db::Store::TruthCount>& truths,
                              const std::vector<std::string>& self_consistent) {
  nlohmann::json j = assessment::ToJson(run.report);
  j["start"] = assessment::ToJson(run.start);
  j["truth"]["self_consistency_predictors"] = self_consistent;
  j["evaluation_id"] = run.evaluation_id;
  // "truth" is the report's object (source, independent, statement); the
  // per-backend trial counts sit in it.
  j["truth"]["trials"] = nlohmann::json::array();
  for (const auto& t : truths) {
    j["truth"]["trials"].push_back(
        {{"truth", t.truth}, {"backend", t.backend}, {"trials", t.trials}});
  }
  return j;
}

// The report as text: the table, the start, and what each truth means.
void PrintEvaluation(const assessment::EvaluationRun& run,
                     const std::vector<db::Store::TruthCount>& truths,
                     const std::vector<std::string>& self_consistent) {
  const std::string text = FormatTable(run.report, run.evaluation_id) + FormatStart(run.start);
  std::fwrite(text.data(), 1, text.size(), stdout);
  for (const auto& t : truths) {
    std::printf("truth: %s (%s backend), %lld trials%s\n",
                t.truth.empty() ? "unreported" : t.truth.c_str(),
                t.backend.empty() ? "?" : t.backend.c_str(), static_cast<long long>(t.trials),
                t.truth == "self-consistency"
                    ? ": these errors are arena's model against itself, not accuracy"
                : t.truth == "measured"
                    ? ": measured, the observed streams are the truth (no separate true "
                      "stream); trials whose poses failed the import check are not served"
                : t.truth == db::kTruthMeasuredNoForces
                    ? ": measured poses; the forces were not measured or failed their import "
                      "check: poses scored, forces not scored on these trials"
                    : "");
  }
  for (const auto& p : self_consistent)
    std::printf(
        "predictor %s: the truth's own engine (%s backend): its errors are self-consistency, "
        "not accuracy\n",
        p.c_str(), EngineBackend(p).c_str());
}

int RunEvaluate(const EvaluateOptions& o) {
  assessment::EvaluationOptions eo = EvaluationOptionsOf(o);
  if (o.group_by.empty() && !o.trial_parameters.empty())
    throw CommandError(kExitBadInput, "--trial-parameters: only with --group-by");
  const TrialParameters parameters(o.trial_parameters, "--trial-parameters");
  if (!o.group_by.empty()) {
    eo.group_by = o.group_by;
    eo.group_of = [&parameters, &o](const db::Trial& t) {
      return parameters.Value(t, o.group_by, "--group-by");
    };
  }

  RefuseToOverwriteStore(o.out_path, "--out", o.db_path);
  const std::string rescue = o.out_path.empty() ? RescuePath("evaluation", o.campaign) : o.out_path;

  // Signals first, so the worker threads inherit the blocked mask.
  std::atomic<bool> cancel{false};
  SignalWatcher signals([&cancel](int) { cancel.store(true); });
  eo.cancel = &cancel;
  eo.on_store_busy = BusyStoreNotice("evaluate", rescue, [&cancel] { return cancel.load(); });

  assessment::EvaluationRun run;
  std::vector<db::Store::TruthCount> truths;  // what the errors are measured against
  try {
    db::StoreOptions so;
    so.create = false;
    so.scene_facts = orchestrator::SceneFactsOfJson;  // an older store's migration reads scenes
    auto store = db::Store::Open(o.db_path, so);
    ReadScales(o, *store, &eo);
    std::unique_ptr<ProgressLine> progress;
    eo.progress = [&progress](long done, long failed, long total) {
      if (!progress) progress = std::make_unique<ProgressLine>(total, "replays");
      progress->Update(done, failed);
    };
    run = assessment::EvaluateCampaign(*store, o.campaign, eo);
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
  // Predictors whose engine made the truth: self-consistency, not accuracy.
  std::vector<std::string> self_consistent;
  for (const auto& p : run.report.predictors)
    if (SelfConsistent(p, run.report.truth.source)) self_consistent.push_back(p);
  nlohmann::json j = EvaluationJson(run, truths, self_consistent);
  if (!run.not_stored.empty()) {
    // Finished, but the store would not take it: the work is kept in a file.
    j["evaluation_id"] = nullptr;
    j["campaign"] = o.campaign;
    j["settings"] = nlohmann::json::parse(run.settings_json);
    j["not_stored"] = run.not_stored;
    WriteResultFile(rescue, j.dump(2) + "\n");
    throw CommandError(
        run.not_stored_kind == db::StoreError::Kind::kBadInput ? kExitBadInput : kExitStore,
        "evaluate: finished, but the store did not take the result (" +
            UserMessage(run.not_stored) + "); the report is saved in " + rescue);
  }
  if (!o.out_path.empty()) WriteResultFile(o.out_path, j.dump(2) + "\n");
  if (o.json)
    std::printf("%s\n", j.dump(2).c_str());
  else
    PrintEvaluation(run, truths, self_consistent);
  return kExitOk;
}

// The arena predictor's grid options: each a comma-separated list; any of
// them given replaces the default grid.
void AddArenaGridOptions(CLI::App* cmd, const std::shared_ptr<EvaluateOptions>& o) {
  const auto axis = [cmd, o](const char* name, auto& values, const char* help) {
    cmd->add_option(name, values, help)->delimiter(',')->each([o](const std::string&) {
      o->grid_given = true;
    });
  };
  axis("--facets", o->facets,
       "arena: friction cone facets to try (comma separated; default grid: 4,8,16,32 x dt 8,4,2,1 "
       "ms, keeping only settings every trial's scene takes)");
  axis("--points", o->points, "arena: constituent points per line/patch to try");
  axis("--dt", o->dt, "arena: time steps to try (s)");
  axis("--reduce", o->reduce, "arena: model reductions to try (auto, full, planar)");
  axis("--contacts", o->contacts,
       "arena: contact geometries to try (tracked: follow the object; fixed: frozen frame)");
  axis("--pads", o->pads, "arena: pad models to try (elastic, rigid)");
  axis("--cone", o->cone,
       "arena: friction cones to try (polyhedral; aligned: edges turned onto the slip)");
  axis("--inertia", o->inertia, "arena: inertia models to try (carried, quasi_static, auto)");
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
  cmd->add_option("--predictors", o->predictors,
                  "Predictors to replay through, comma separated: arena, mujoco")
      ->delimiter(',')
      ->capture_default_str();
  AddArenaGridOptions(cmd, o);
  auto mujoco_given = [o](const std::string&) { o->mujoco_grid_given = true; };
  cmd->add_option("--mujoco-timestep", o->mujoco_timestep, "mujoco: timesteps to try (s)")
      ->delimiter(',')
      ->each(mujoco_given)
      ->capture_default_str();
  cmd->add_option("--mujoco-cone", o->mujoco_cone,
                  "mujoco: friction cones to try (elliptic, pyramidal)")
      ->delimiter(',')
      ->each(mujoco_given)
      ->capture_default_str();
  cmd->add_option("--mujoco-noslip", o->mujoco_noslip, "mujoco: noslip iterations to try")
      ->delimiter(',')
      ->each(mujoco_given)
      ->capture_default_str();
  cmd->add_option("--mujoco-solref", o->mujoco_solref,
                  "mujoco: contact solref values to try, each TIMECONST:DAMPRATIO (default "
                  "0.002:1)")
      ->delimiter(',')
      ->each(mujoco_given);
  cmd->add_option("--mujoco-solimp", o->mujoco_solimp,
                  "mujoco: contact solimp values to try, each DMIN:DMAX:WIDTH:MID:POWER (default "
                  "0.9:0.95:0.001:0.5:2)")
      ->delimiter(',')
      ->each(mujoco_given);
  cmd->add_option("--convergence-trials", o->convergence_trials,
                  "Trials whose pieces the convergence table restarts from the true state "
                  "(0: no table)")
      ->capture_default_str();
  cmd->add_option(
      "--budget", o->budgets,
      "Budget, repeatable (all must hold), judged on p95: '1mm' = p95 final position error "
      "<= 1 mm, '2ms' = p95 predictor time per trial <= 2 ms, '1.5floor' = p95 final position "
      "error <= 1.5 x the noise floor; or METRIC=VALUE[UNIT] with METRIC position_median|"
      "position_p95|angle_median|angle_p95|force_median|force_p95|mode_agreement_median "
      "(a minimum)|time_p95");
  cmd->add_option("--threads", o->threads, "Worker threads (0: one per core)")
      ->capture_default_str();
  cmd->add_option("--calibration", o->calibration,
                  "Apply this calibration's fitted scales (arena calibrate) to every trial's "
                  "scene before predicting it, for every predictor")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--scale", o->scales,
                  "NAME=FACTOR, repeatable: scale this parameter (arena calibrate's names: "
                  "mu_pusher, mu_support, pressure_rim, ...) on every scene, over "
                  "--calibration's");
  cmd->add_option("--group-by", o->group_by,
                  "Also report every setting per value of this trial parameter (e.g. shape, "
                  "push_angle_rad, speed_mm_s): the trial's stored parameters, else "
                  "--trial-parameters");
  cmd->add_option("--trial-parameters", o->trial_parameters,
                  "A CSV with a seed column whose rows give the trials of those seeds more "
                  "parameters (an imported dataset's trials.csv)");
  cmd->add_flag("--json", o->json, "Print the report as JSON");
  cmd->add_option("--from", o->from,
                  "Where predictions start: measured (the start pose each trial's cell "
                  "measured: errors are the model's) or planned (the scene's pose: errors "
                  "include the reset's placement); from measured, each setting also runs from "
                  "planned and the report says how much of the error the start pose explains")
      ->capture_default_str();
  cmd->add_option("--out", o->out_path,
                  "Also write the report (JSON) to this file; a run the store cannot take "
                  "(locked until Ctrl-C, full) is saved there too");
  cmd->footer(
      "Example:\n"
      "  arena evaluate --db lab.db --campaign 3 --predictors arena --budget 1.5floor\n"
      "  arena evaluate --db lab.db --campaign 3 --facets 4,8,16 --points 3,5 --budget 1mm\n"
      "Every done trial is replayed from its stored scene through each predictor at each setting\n"
      "of its grid (arena: facets x points x dt x reduce), scored against its stored ground\n"
      "truth, and the run is stored (tables evaluations, evaluation_results). Every error is\n"
      "median/p95/max over the trials predicted; divergences (left the grasp, blew up) and\n"
      "failures are counted and listed apart, never averaged in. The noise floor is the spread\n"
      "of the true final pose between replicates. The Pareto front is the first error budget's\n"
      "metric (default: p95 final position error) against median time; with a budget the\n"
      "cheapest setting meeting it on p95 is recommended (with only a time budget, the most\n"
      "accurate), without one the front is described. The report names its truth.\n"
      "Plot the trade with: arena plot --db FILE --campaign ID --tradeoff --out FILE.svg\n");
  cmd->callback([o, action] { *action = [o] { return RunEvaluate(*o); }; });
}

}  // namespace arena::cli
