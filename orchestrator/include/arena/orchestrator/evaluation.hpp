// Measuring the speed/accuracy trade of the model on a campaign's own data
// (`arena evaluate`): every done trial's scene is replayed through the model
// at each fidelity setting of a grid, scored against the stored ground truth
// (ScorePrediction), and summarised per setting. The Pareto front of error
// against model time is marked, and the cheapest setting within the user's
// error budget is recommended.
//
// Conventions (also in the CLI help):
// * Percentiles interpolate linearly between closest ranks (R-7, numpy's
//   default): p of sorted x[0..n-1] is at rank (n-1)·p.
// * Error distributions are over the trials the setting predicted ("ok");
//   a setting that failed on any trial (solver failure, invalid scene) is
//   reported but is neither on the Pareto front nor recommended, because its
//   error figures leave out the trials it could not predict.
// * Model time is the predictor's wall time per trial (s), median over all
//   trials replayed; trials run in parallel, so timings share the cores
//   (use one thread for uncontended figures).
// * The Pareto front minimises (primary error, median time): the primary
//   error is the first budget's metric, or the median final position error
//   when no budget is given. A setting is on the front when no other
//   eligible setting is at least as good in both and better in one.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "arena/db/store.hpp"
#include "arena/mechanics/scene.hpp"

namespace arena::orchestrator {

// The settings evaluated: the cross product of the lists (facets outermost).
struct FidelityGrid {
  std::vector<int> facets{4, 8, 16, 32};
  std::vector<int> points{2, 3, 5, 9};
  std::vector<double> dt{0.004};  // s
  std::vector<mechanics::Reduce> reduce{mechanics::Reduce::kAuto};
  std::vector<mechanics::ContactTracking> contacts{mechanics::ContactTracking::kTracked};
};

// @throws std::invalid_argument naming the list for an empty list, a
//   duplicate, facets < 3, points < 2, or dt not finite and > 0.
std::vector<mechanics::ModelOptions> ExpandGrid(const FidelityGrid& grid);

// Linear-interpolation percentile, p in [0, 1].
// @throws std::invalid_argument for no values or p outside [0, 1].
double Percentile(std::vector<double> values, double p);

// The error measures a budget can bound (SI units: m, rad, N, fraction).
enum class ErrorMetric {
  kPositionMedian,
  kPositionP95,  // final object position error (m)
  kAngleMedian,
  kAngleP95,  // final orientation error (rad)
  kForceMedian,
  kForceP95,             // RMS contact force error (N)
  kModeAgreementMedian,  // contact-mode agreement (fraction; a budget is a minimum)
};
const char* ToString(ErrorMetric metric);  // "position_median", ...
// true: smaller is better (all but mode agreement).
bool LowerIsBetter(ErrorMetric metric);

// An error budget: `metric` must be <= limit (>= for mode agreement).
struct Budget {
  ErrorMetric metric = ErrorMetric::kPositionMedian;
  double limit = 0;  // in the metric's SI unit
};

// "1mm" (median final position error <= 1 mm), or METRIC=VALUE[UNIT] with
// METRIC one of ToString(ErrorMetric) and UNIT among m, mm, um (position),
// rad, mrad, deg (angle), N, mN (force), % (mode agreement); a bare number
// is in SI units. E.g. "position_p95=5mm", "angle_median=0.5deg",
// "mode_agreement_median=95%".
// @throws std::invalid_argument saying what is wrong.
Budget ParseBudget(const std::string& text);
std::string FormatBudget(const Budget& budget);

struct Distribution {
  double median = 0;
  double p95 = 0;
};

// One setting's figures over the evaluated trials.
struct SettingSummary {
  std::string model_key;  // ModelKey(model)
  mechanics::ModelOptions model;
  int trials = 0;                              // replayed
  int ok = 0;                                  // predicted and scored
  int failures = 0;                            // trials - ok (solver failure, invalid scene, error)
  std::optional<Distribution> position;        // m   (absent when ok == 0)
  std::optional<Distribution> angle;           // rad
  std::optional<Distribution> force;           // N
  std::optional<Distribution> mode_agreement;  // fraction
  Distribution time;                           // s per trial, over all replayed trials
  bool pareto = false;
  bool within_budget = false;  // eligible and meets every budget
  // The value of `metric` (absent when the setting has no ok trial).
  std::optional<double> Metric(ErrorMetric metric) const;
  bool eligible() const { return trials > 0 && failures == 0; }
};

struct EvaluationReport {
  std::int64_t campaign_id = 0;
  int trials = 0;  // done trials replayed
  ErrorMetric primary = ErrorMetric::kPositionMedian;
  std::vector<Budget> budgets;
  std::vector<SettingSummary> settings;    // grid order
  std::optional<std::size_t> recommended;  // index into settings
  std::string recommendation;              // one sentence: what and why (or why none)
};

// One trial's result at one setting (what the workers produce).
struct TrialEvaluation {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::size_t setting = 0;  // index into the grid
  db::Prediction prediction;
};

// Summarises the results per setting, marks the Pareto front and the
// recommendation (pure: the unit-tested core of EvaluateCampaign).
EvaluationReport Summarise(const std::vector<mechanics::ModelOptions>& settings,
                           const std::vector<TrialEvaluation>& results,
                           const std::vector<Budget>& budgets);

// Marks `pareto` on `settings` (eligible ones only) for `primary` vs median time.
void MarkParetoFront(std::vector<SettingSummary>& settings, ErrorMetric primary);

nlohmann::json ToJson(const EvaluationReport& report);

struct EvaluationOptions {
  FidelityGrid grid;
  std::vector<Budget> budgets;
  int threads = 0;  // 0: one per core
  // Called from the calling thread about 10 times a second and at the end:
  // (jobs done, jobs failed, jobs total); a job is one (trial, setting).
  std::function<void(long, long, long)> progress;
  const std::atomic<bool>* cancel = nullptr;  // set: stop early, store nothing
};

struct EvaluationRun {
  std::int64_t evaluation_id = 0;  // 0 when cancelled (nothing stored)
  bool cancelled = false;
  EvaluationReport report;
};

// Replays every done trial of the campaign at every setting of the grid, on
// `threads` worker threads (each with its own read-only connection to
// store.path()), stores the run (Store::RecordEvaluation) and returns it.
// @throws std::invalid_argument for a bad grid; db::StoreError for an unknown
//   campaign or a store failure.
EvaluationRun EvaluateCampaign(db::Store& store, std::int64_t campaign_id,
                               const EvaluationOptions& options);

}  // namespace arena::orchestrator
