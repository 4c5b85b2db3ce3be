// Measuring the speed/accuracy trade on a campaign's own data (`arena
// evaluate`): every done trial's scene is replayed through each predictor
// (predictor.hpp: `arena`, `mujoco`) at each setting of its grid, scored
// against the stored ground truth, and summarised per (predictor, setting).
//
// Conventions (also in the CLI help and assessment/README.md):
// * Percentiles interpolate linearly between closest ranks (R-7, numpy's
//   default): p of sorted x[0..n-1] is at rank (n-1)·p.
// * Every metric is given as median, p95 and max over the trials the
//   setting predicted ("ok"). For contact-mode agreement the tail is the low
//   side: "p95" is the 5th percentile and "max" the minimum.
// * A prediction that diverged or left the grasp, and one that failed
//   (solver failure, invalid scene, error), is its own outcome: counted and
//   listed with its trial id, never in the error distributions.
// * Budgets and the Pareto front judge a setting over all the trials it was
//   given: a diverged or failed trial counts as an infinite error there, so a
//   setting that fails on more than 5 % of trials meets no p95 budget, and
//   one that fails at all is never on the front.
// * Model time is the predictor's wall time per trial (s) and per simulated
//   second (wall s / ground-truth duration s); trials run in parallel, so
//   timings share the cores (use one thread for uncontended figures).
// * The noise floor (noise_floor.hpp) is the replicate spread of the true
//   final pose; errors are also given as multiples of its median.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "arena/assessment/noise_floor.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/assessment/predictor.hpp"
#include "arena/assessment/scoring.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene.hpp"

namespace arena::assessment {

// arena's settings: the cross product of the lists (facets outermost).
struct FidelityGrid {
  std::vector<int> facets{4, 8, 16, 32};
  std::vector<int> points{3};
  std::vector<double> dt{0.008, 0.004, 0.002, 0.001};
  std::vector<mechanics::Reduce> reduce{mechanics::Reduce::kAuto};
  std::vector<mechanics::ContactTracking> contacts{mechanics::ContactTracking::kTracked};
  // The model's opt-in choices (issue 31), the model's defaults unless given:
  // so an evaluation can weigh the aligned cone or quasi-static steps against
  // their cost on a campaign's own trials.
  std::vector<mechanics::PadModel> pads{mechanics::ModelOptions{}.pads};
  std::vector<mechanics::ConeModel> cone{mechanics::ModelOptions{}.cone};
  std::vector<mechanics::InertiaModel> inertia{mechanics::ModelOptions{}.inertia};
};

// @throws std::invalid_argument naming the list for an empty list, a
//   duplicate, facets < 3, points < 2, or dt not finite and > 0.
//   (Settings a scene then refuses, e.g. the aligned cone with quasi-static
//   steps in 6 DOF, fail per trial as predictions do, with the reason.)
std::vector<mechanics::ModelOptions> ExpandGrid(const FidelityGrid& grid);

// The default grid for these scenes: FidelityGrid{}'s settings (16: facets
// 4..32 × dt 8..1 ms, 3 constituent points, or more when a scene's own model
// asks for more), keeping only settings that are valid for every scene (no
// `points 2` on a patch trial, no dt longer than the shortest trial).
// @throws std::invalid_argument when no setting fits every scene.
std::vector<mechanics::ModelOptions> DefaultArenaGrid(const std::vector<mechanics::Scene>& scenes);

// Linear-interpolation percentile, p in [0, 1].
// @throws std::invalid_argument for no values or p outside [0, 1].
double Percentile(std::vector<double> values, double p);

// What a budget can bound (SI units: m, rad, N, fraction, s).
enum class ErrorMetric {
  kPositionMedian,
  kPositionP95,  // final object position error (m)
  kAngleMedian,
  kAngleP95,  // final orientation error (rad)
  kForceMedian,
  kForceP95,             // RMS contact force error (N)
  kModeAgreementMedian,  // contact-mode agreement (fraction; a budget is a minimum)
  kTimeP95,              // predictor wall time per trial (s)
};
const char* ToString(ErrorMetric metric);  // "position_median", ...
// true: smaller is better (all but mode agreement).
bool LowerIsBetter(ErrorMetric metric);

// A budget: `metric` must be <= limit (>= for mode agreement). With
// floor_multiple > 0 the limit is that multiple of the noise floor's median
// (position or angle), resolved when the floor is known.
struct Budget {
  ErrorMetric metric = ErrorMetric::kPositionP95;
  double limit = 0;  // in the metric's SI unit
  double floor_multiple = 0;
};

// "1mm" (p95 final position error <= 1 mm), "2ms" (p95 time per trial <=
// 2 ms), "1.5floor" (p95 final position error <= 1.5 × the noise floor),
// or METRIC=VALUE[UNIT] with METRIC one of ToString(ErrorMetric) and UNIT
// among m, mm, um (position), rad, mrad, deg (angle), N, mN (force), %
// (mode agreement), s, ms, us (time), floor (position, angle); a bare number
// is in SI units. E.g. "position_median=5mm", "angle_p95=0.5deg".
// @throws std::invalid_argument saying what is wrong.
Budget ParseBudget(const std::string& text);
std::string FormatBudget(const Budget& budget);

struct Distribution {
  double median = 0;
  double p95 = 0;  // mode agreement: the 5th percentile (the bad tail)
  double max = 0;  // mode agreement: the minimum
};

// One trial named in a listing (worst errors, divergences, failures).
struct TrialNote {
  std::int64_t trial_id = 0;
  double value = 0;    // the error (m) for the worst list; else 0
  std::string reason;  // for divergences and failures
};

// Self-consistency of a setting against its predictor's finest setting
// (convergence.hpp): short pieces restarted from the true state.
struct Convergence {
  int pieces = 0;
  Distribution position;  // m
  Distribution angle;     // rad
};

// What a setting is, apart from how it did.
struct SettingInfo {
  std::string predictor = "arena";
  PredictorSetting setting;
  std::optional<mechanics::ModelOptions> model;  // arena's settings (for the JSON's knob keys)
};

// One (predictor, setting)'s figures over the evaluated trials.
struct SettingSummary {
  std::string predictor = "arena";
  std::string model_key;  // the setting's key
  std::string knobs_json = "{}";
  std::optional<mechanics::ModelOptions> model;
  double step = 0;
  bool finest = false;                         // the predictor's reference for convergence
  int trials = 0;                              // replayed
  int ok = 0;                                  // predicted and scored
  int diverged = 0;                            // left the grasp or blew up
  int failures = 0;                            // solver failure, invalid scene, error
  std::optional<Distribution> position;        // m   (absent when ok == 0)
  std::optional<Distribution> angle;           // rad
  std::optional<Distribution> force;           // N (over force_trials of the ok trials)
  int force_trials = 0;                        // ok trials whose measured force was scored
  std::optional<Distribution> mode_agreement;  // fraction
  Distribution time;                           // s per trial, over all replayed trials
  std::optional<Distribution> time_per_sim_s;  // wall s per simulated s
  std::vector<TrialNote> worst;                // largest position errors, worst first (<= 5)
  std::vector<TrialNote> diverged_trials;      // every one (ids)
  std::vector<TrialNote> failed_trials;        // every one (ids)
  // Of the ok trials, those whose prediction the friction cones steered
  // (`steered_slip` in its detail: its answer moves with the facets; see
  // mechanics::SteeredSlip).
  int steered = 0;
  // ... and those whose prediction ended in a swing nothing damps
  // (`oscillation` in its detail: its final pose is a phase of the swing).
  int oscillating = 0;
  std::optional<Convergence> convergence;
  // NMSE of the push's outcome (scoring.hpp) over the ok trials; absent, with
  // the reason in nmse_note, when it cannot be computed (< 2 trials, an
  // output that does not vary).
  std::optional<OutcomeNmse> nmse;
  std::string nmse_note;
  // p95 of position and angle error over all trials, failures as +inf.
  double position_p95_all = 0, angle_p95_all = 0;
  bool pareto = false;
  bool within_budget = false;
  // The value of `metric` over the ok trials (absent when none).
  std::optional<double> Metric(ErrorMetric metric) const;
  // The value a budget and the front judge: over all trials, failures counted
  // as infinitely bad (may be +inf).
  double Judged(ErrorMetric metric) const;
  bool eligible() const { return trials > 0 && failures == 0 && diverged == 0; }
};

// Where the ground truth came from.
struct TruthInfo {
  std::string source = "model";  // the cells' backend(s), e.g. "model", "mujoco", "model,mujoco"
  bool independent = false;      // false: the truth is arena's own model
  std::string statement;         // one sentence for every report
};

// Error against ground-truth duration, per predictor at one setting.
struct DurationPoint {
  double duration_s = 0;  // the bin's median duration
  int trials = 0;
  double position_median = 0, position_p95 = 0;  // m
};
struct DurationCurve {
  std::string predictor;
  std::string model_key;
  std::vector<DurationPoint> points;  // by duration
};

// The figures of the trials whose trial parameter `group_by` has one value
// (`arena evaluate --group-by shape`): every setting summarised over them
// alone (the NMSE's variance is the group's own).
struct GroupReport {
  std::string value;
  int trials = 0;
  std::vector<SettingSummary> settings;  // as EvaluationReport::settings
};

struct EvaluationReport {
  std::int64_t campaign_id = 0;
  int trials = 0;  // done trials replayed
  TruthInfo truth;
  std::optional<NoiseFloor> floor;
  ErrorMetric primary = ErrorMetric::kPositionP95;
  std::vector<Budget> budgets;
  std::vector<std::string> predictors;
  std::vector<SettingSummary> settings;  // predictor by predictor, grid order
  std::vector<DurationCurve> duration_curves;
  std::optional<std::size_t> recommended;  // index into settings (only with a budget)
  std::string recommendation;              // what and why (or why none)
  std::string front;                       // what the Pareto front looks like
  std::map<std::string, double> scales;    // calibrated scales applied to every scene
  std::string group_by;                    // the trial parameter grouped by ("" : none)
  std::vector<GroupReport> groups;         // by value, sorted
};

// One trial's result at one setting (what the workers produce).
struct TrialEvaluation {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::size_t setting = 0;  // index into the settings given to Summarise
  double truth_duration_s = 0;
  db::Prediction prediction;
};

// Summarises the results per setting, the tails, the failures, the floor
// multiples, the Pareto front and the recommendation (pure: the unit-tested
// core of EvaluateCampaign).
EvaluationReport Summarise(const std::vector<SettingInfo>& settings,
                           const std::vector<TrialEvaluation>& results,
                           const std::vector<Budget>& budgets,
                           const std::optional<NoiseFloor>& floor = std::nullopt);
// The per-group reports of `results` (a trial's group: group_of_trial).
std::vector<GroupReport> SummariseGroups(const std::vector<SettingInfo>& settings,
                                         const std::vector<TrialEvaluation>& results,
                                         const std::map<std::int64_t, std::string>& group_of_trial);

// arena-only settings (as the grid of one arena predictor).
std::vector<SettingInfo> ArenaSettings(const std::vector<mechanics::ModelOptions>& models);

// Marks `pareto` on `settings` (eligible ones only) for `primary` vs median time.
void MarkParetoFront(std::vector<SettingSummary>& settings, ErrorMetric primary);

nlohmann::json ToJson(const EvaluationReport& report);

// A predictor asked for by name, with its grid (absent: the default grid
// for the campaign's scenes).
struct PredictorRequest {
  std::string name = "arena";  // arena | mujoco
  std::optional<FidelityGrid> arena_grid;
  std::optional<MujocoGrid> mujoco_grid;
};

// How much of the error the start pose explains (issue 26): per setting,
// the median final error predicted from the planned start and from the
// measured one, over the trials both predicted ("ok"); planned minus
// measured is the reset's share.
struct StartShare {
  std::string predictor;
  std::string model_key;
  int trials = 0;                                      // paired: ok from both starts
  double position_measured = 0, position_planned = 0;  // m, medians
  double angle_measured = 0, angle_planned = 0;        // rad, medians
};
struct StartReport {
  StartFrom from = StartFrom::kMeasured;  // where the stored predictions start
  int measured_trials = 0;                // trials whose stream gave a measured start
  // How far the starts used lie from the planned pose (m, rad; 0 from planned).
  std::optional<Distribution> offset_position, offset_angle;
  std::vector<StartShare> settings;  // one per setting; empty when from planned
};
// Pure: `planned` holds the same (trial, setting) predictions from the
// planned start (empty: not run), `starts` each trial's start (by trial).
StartReport StartShareOf(const std::vector<SettingInfo>& settings,
                         const std::vector<TrialEvaluation>& results,
                         const std::vector<std::optional<db::Prediction>>& planned,
                         const std::vector<std::optional<PredictionStart>>& starts, StartFrom from);
// {"from", "measured_trials", "offset_m", "offset_rad", "explained": [{"predictor",
// "setting", "trials", "position_median_m": {"measured", "planned", "explained"},
// "angle_median_rad": {...}}]} (SI units).
nlohmann::json ToJson(const StartReport& report);

struct EvaluationOptions {
  std::vector<PredictorRequest> predictors{PredictorRequest{}};
  // Where predictions start (issue 26): the start pose each trial's cell
  // measured (the first sample of its stream), or the planned one.
  StartFrom start_from = StartFrom::kMeasured;
  std::vector<Budget> budgets;
  int threads = 0;             // 0: one per core
  int convergence_trials = 8;  // trials the convergence table restarts pieces of (0: none)
  // Called from the calling thread about 10 times a second and at the end:
  // (jobs done, jobs failed, jobs total); a job is one (trial, setting).
  std::function<void(long, long, long)> progress;
  const std::atomic<bool>* cancel = nullptr;  // set: stop early, store nothing
  // The finished run's write found the store locked by another process: it
  // waits and retries (db::RetryWhileBusy) until the lock is free, `cancel`
  // is set, or this returns false; (seconds waited, SQLite's message).
  std::function<bool(double, const std::string&)> on_store_busy;
  // Per-group figures (GroupReport): `group_by` names the trial parameter,
  // `group_of` gives a trial's value of it (it throws, naming the trial,
  // when the trial has none: the exception propagates before any work,
  // nothing is evaluated or stored).
  std::string group_by;
  std::function<std::string(const db::Trial&)> group_of;
  // Calibrated scales (calibration.hpp's names, e.g. mu_pusher) applied to
  // every trial's scene before any predictor runs it (`arena evaluate
  // --calibration ID`); empty: the scenes as stored.
  std::map<std::string, double> scales;
};

struct EvaluationRun {
  std::int64_t evaluation_id = 0;  // 0 when cancelled (nothing stored)
  bool cancelled = false;
  EvaluationReport report;
  StartReport start;  // where predictions started and the start's share of the error
  // Set when the run finished but the store refused its write (locked past
  // the caller's patience, full, read-only, ...): the report is still here
  // for the caller to keep (`arena evaluate` writes it to a file).
  std::string not_stored;
  db::StoreError::Kind not_stored_kind = db::StoreError::Kind::kIo;
  std::string settings_json;  // the grid as it would be stored
};

// The truth of a campaign's trials, from the backend and kind of truth each
// trial's cell reported (Store::CampaignTruths; a trial that reported none
// ran the model). Any self-consistency truth makes the report say so.
TruthInfo TruthOf(const db::Store& store, std::int64_t campaign_id);

// Replays every done trial of the campaign through every requested
// predictor's grid on `threads` worker threads (each with its own read-only
// connection to store.path()), stores the run (Store::RecordEvaluation) and
// returns it.
// @throws std::invalid_argument for a bad grid, an unknown predictor or a
//   campaign without done trials (nothing to evaluate: nothing is stored);
//   db::StoreError for an unknown campaign or a store failure.
EvaluationRun EvaluateCampaign(db::Store& store, std::int64_t campaign_id,
                               const EvaluationOptions& options);

}  // namespace arena::assessment
