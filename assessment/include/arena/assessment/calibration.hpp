// Calibration: fit model parameters to a campaign's ground truth
// (`arena calibrate`; docs/adaptive.md).
//
// Parameters are multiplicative scales on the scene's values, so one fit
// serves a campaign whose scenes vary them:
//
//   mu_fingers   every finger's friction coefficient
//   mu_pusher    the pusher's friction coefficient
//   grip_force   the grip force the cell really applies
//   object_mass  the object's mass (and inertia)
//   mu_support   the support's friction coefficient (free pushing)
//   pressure_rim the support's pressure distribution, a one-parameter family:
//                each pressure point's weight (the scene's points, or the
//                uniform quadrature of its resting face) times k^rho, rho
//                its distance from the centre of mass over the farthest
//                point's, then tilted linearly so that the centre of
//                pressure stays under the centre of mass. k = 1 is the
//                scene's own (uniform) pressure, k > 1 loads the rim (k
//                times the centre's pressure there), k < 1 the centre.
//
// Loss of one trial (weights: LossScales, documented in the README):
//
//   L = (e_pos / s_pos)^2 + (e_ang / s_ang)^2 + (e_force / s_force)^2
//
// e_pos: final object position error (m), e_ang: final angle error (rad),
// e_force: RMS over samples and contacts of |f_pred - f_true| (N); with a
// force window, of the difference of each contact's mean force over
// consecutive windows of that length (MuJoCo's soft contacts hand the load
// between two coupled sliding fingers from one 4 ms sample to the next: ~2 N
// RMS of chatter that no parameter explains, measured on the calibration
// e2e campaign, while 40 ms means keep the friction's signal). The fit
// minimises the mean L over the training trials with a derivative-free
// optimiser (NLopt BOBYQA; COBYLA for one parameter) over log(scale) within
// bounds. Uncertainty: a bootstrap over the training trials (each resample
// refitted from the optimum). The held-out trials (a seeded split) measure
// the error before (all scales 1) and after; a fit that does not lower the
// held-out error is reported as not improved and must not be applied.
//
// The simulator is passed in (SimulateFn, or a simulators::Simulator whose
// PreparedScene builds each trial's model once: MuJoCo's), so the same fit
// runs against arena's model or any other predictor. Every (trial, scales)
// pair is simulated once (a memo), so the optimiser's start, the refits'
// starts and repeated bootstrap draws cost nothing.
//
// Uncertainty, two ways (BootstrapMethod):
//   refit  each bootstrap resample of the training trials refitted from the
//          optimum (max(10, max_evaluations/3) evaluations each): the honest
//          one, but it costs `bootstrap` more fits.
//   reuse  each resample's optimum is the point, among those the main fit
//          already evaluated, that minimises the resample's mean loss: no
//          simulation at all (for expensive predictors). Its resolution is
//          the spacing of the evaluated points near the optimum, so a spread
//          narrower than the optimiser's last steps shows as zero.
// Identifiability (profile): a bootstrap refitted from the optimum cannot
// see a direction in which the loss is flat (a pusher that sticks in every
// trial fits any friction above the one it needs, and the refits stay where
// they start), so each parameter is also profiled: the training loss along
// that parameter alone, the others at the fit, on `profile_points` scales
// spread over the bounds plus six near the fit (x 0.82 ... 1.22). A scale
// "fits worse" than the fit when the per-trial loss increases (paired over
// the training trials) have a mean above kProfileMinIncrease of the fit's
// mean loss (a plateau 0.1 % above the fit is no evidence) and a one-sided Wilcoxon
// signed-rank statistic more than kProfileStandardErrors standard
// deviations above zero: ranks, so that one trial the model gets badly
// wrong does not swamp the evidence of all the others (a mean's standard
// error would), and trials that a parameter does not affect at all (zero
// increase) count for nothing. The profile range is bracketed by the
// nearest profiled scales on either side of the fit that fit worse (what
// the data rule out lies beyond them); a side with none up to its bound is
// not bounded by the data, and the parameter is reported as not
// identified: its fitted value is then one of many that fit as well.
// Thread safety: Calibrate calls `simulate` from up to `threads` threads at
// once, never twice at once for the same trial.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/assessment/scoring.hpp"
#include "arena/db/store.hpp"
#include "arena/errors/error.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/simulators/simulator.hpp"

namespace arena::assessment {

using SimulateFn = std::function<mechanics::SimulationResult(const mechanics::Scene&)>;

// Bad calibration input (unknown parameter, too few trials, ...): the
// message names the option ("--params: ...").
class CalibrationError : public Error {
 public:
  explicit CalibrationError(const std::string& what) : Error(ErrorCategory::kBadInput, what) {}
};

enum class CalibrationParam {
  kMuFingers,
  kMuPusher,
  kGripForce,
  kObjectMass,
  kMuSupport,
  kPressureRim
};
const char* ToString(CalibrationParam p);  // "mu_fingers", ...
// @throws CalibrationError naming the unknown name.
CalibrationParam ParseCalibrationParam(const std::string& name);

// The scene with the given scales applied (name -> factor, names as ToString).
// @throws CalibrationError for an unknown name or a factor that is not > 0.
mechanics::Scene ApplyScales(const mechanics::Scene& scene,
                             const std::map<std::string, double>& scales);

struct LossScales {
  double position_m = 1e-3;   // 1 mm of final position error weighs 1
  double angle_rad = 0.01;    // 0.01 rad (0.57 deg) of final angle error weighs 1
  double force_n = 0.5;       // 0.5 N RMS contact-force error weighs 1
  double force_window_s = 0;  // forces compared as means over windows this long (0: per sample)
  // Outcome loss instead (set by Calibrate from `outcome_loss`): each
  // output's squared error over its variance across the training trials,
  // averaged over dx, dy, dtheta -- the mean loss is then the training
  // trials' NMSE (scoring.hpp). All three > 0 when in use.
  std::array<double, 3> outcome_variance{0, 0, 0};
};

// One trial to fit: the scene the predictor runs (the campaign's model
// settings applied) and its true trajectory.
struct CalibrationTrial {
  std::int64_t trial_id = 0;
  mechanics::Scene scene;
  std::vector<mechanics::TrajectorySample> truth;
};

enum class BootstrapMethod { kRefit, kReuse };
const char* ToString(BootstrapMethod m);  // "refit", "reuse"

struct CalibrationOptions {
  std::vector<CalibrationParam> params;  // at least one, no repeats
  double lower = 0.2, upper = 5.0;       // bounds of every scale
  double holdout = 0.3;                  // fraction of trials held out, [0, 0.9] (0: none)
  std::uint64_t seed = 1;                // the hold-out split and the bootstrap
  // Non-empty: exactly these trials are held out (a split by a trial
  // parameter, e.g. one shape), every other one fitted; `holdout` is unused.
  std::vector<std::int64_t> heldout_ids;
  int max_evaluations = 150;  // of the loss, for the main fit
  int bootstrap = 20;         // resamples for the uncertainty (0: none)
  int threads = 1;            // simulations in parallel
  LossScales scales;
  // true: fit the outcome's NMSE (LossScales::outcome_variance from the
  // training trials' true outcomes) instead of the pose and force loss.
  bool outcome_loss = false;
  int profile_points = 12;  // identifiability profile: scales over the bounds (0: no profile)
  BootstrapMethod bootstrap_method = BootstrapMethod::kRefit;
  std::function<void(const std::string&)> progress;  // optional, one line per stage
  // Optional, after every loss evaluation of the main fit: its number (from
  // 1), the budget (max_evaluations), its loss and the best so far.
  std::function<void(int evaluation, int budget, double loss, double best)> on_evaluation;
};

struct FittedParam {
  std::string name;
  double scale = 1;                // the fit
  double std = 0;                  // bootstrap standard deviation of the scale
  double ci_low = 1, ci_high = 1;  // bootstrap 2.5 and 97.5 percentiles
  std::optional<double> nominal;   // the scenes' common value (e.g. mu 0.5), when they share one
  // Identifiability profile (above); absent when profile_points is 0.
  bool profiled = false;
  double profile_low = 1, profile_high = 1;        // the scales that fit worse, or the bounds
  bool bounded_low = true, bounded_high = true;    // false: the range reaches that bound
  std::vector<std::pair<double, double>> profile;  // (scale, mean training loss), ascending
  bool identified() const { return !profiled || (bounded_low && bounded_high); }
  // The fit lies outside its own bootstrap interval: every resampled refit
  // moved the same way (they start at the fit with a third of its
  // evaluations), so the interval says where the refits went, not how
  // uncertain the fit is.
  bool fit_outside_bootstrap() const { return scale < ci_low || scale > ci_high; }
};

// The sentence `arena calibrate` prints for a parameter whose fit lies
// outside its bootstrap interval (FittedParam::fit_outside_bootstrap);
// empty when it does not.
std::string BootstrapWarning(const FittedParam& f);

// A profile scale fits worse than the fit when the signed-rank statistic of
// its per-trial loss increases is this many standard deviations above zero.
inline constexpr double kProfileStandardErrors = 2.0;
// ... and the mean increase is above this fraction of the fit's mean loss.
inline constexpr double kProfileMinIncrease = 0.01;

// Per-trial error of a prediction against truth (samples paired by index).
struct TrialError {
  double position = 0, angle = 0, force = 0;
  PlanarOutcome predicted_outcome, true_outcome;  // each from its first sample to the last paired
  bool ok = true;  // false: the simulation failed (the loss then counts kFailedTrialLoss)
};
inline constexpr double kFailedTrialLoss = 1e4;

// Figures of a set of trials at one set of scales, as `arena evaluate`
// gives them: the outcome's NMSE (scoring.hpp; absent with fewer than 2
// trials or an output that does not vary) and the final errors' median and
// p95 over the trials predicted.
struct SetFigures {
  int trials = 0, predicted = 0;
  std::optional<OutcomeNmse> nmse;
  double position_median = 0, position_p95 = 0;  // m
  double angle_median = 0, angle_p95 = 0;        // rad
};

struct CalibrationResult {
  std::vector<FittedParam> fitted;
  std::vector<std::int64_t> train_ids, heldout_ids;
  double train_before = 0, train_after = 0;      // mean loss, training trials
  double heldout_before = 0, heldout_after = 0;  // mean loss, held-out trials
  // Held-out mean errors before/after, for the report (m, rad, N).
  double heldout_position_before = 0, heldout_position_after = 0;
  double heldout_angle_before = 0, heldout_angle_after = 0;
  double heldout_force_before = 0, heldout_force_after = 0;
  // Each held-out trial's errors (in heldout_ids' order), before and after.
  std::vector<TrialError> heldout_errors_before, heldout_errors_after;
  SetFigures train_figures_before, train_figures_after;
  SetFigures heldout_figures_before, heldout_figures_after;
  bool improved = false;         // heldout_after < heldout_before (nothing held out: train_*)
  int evaluations = 0;           // loss evaluations of the main fit
  std::string optimizer;         // "LN_BOBYQA" / "LN_COBYLA"
  std::string stop;              // NLopt's result
  std::string bootstrap_method;  // "refit" / "reuse"
  long simulations = 0;          // predictor runs, all stages (the memo's misses)
  long models_reused = 0;        // of those, runs on a prepared model (Calibrate with a Simulator)
  std::map<std::string, double> Scales() const;
};

// window_s: the force window (LossScales::force_window_s; 0: per sample).
TrialError CompareTrajectories(const mechanics::Scene& scene,
                               const std::vector<mechanics::TrajectorySample>& predicted,
                               const std::vector<mechanics::TrajectorySample>& truth,
                               double window_s = 0);
double Loss(const TrialError& e, const LossScales& s);

// The figures of a set of trials' errors (failed simulations: not predicted).
SetFigures FiguresOf(const std::vector<TrialError>& errors);
// Those figures as the stored report and `arena calibrate --json` give them
// (SI: metres, radians).
nlohmann::json ToJson(const SetFigures& figures);

// @throws CalibrationError for bad options or fewer than 4 trials.
CalibrationResult Calibrate(const std::vector<CalibrationTrial>& trials, const SimulateFn& simulate,
                            const CalibrationOptions& options);
// One fit per held-out set (a split by a trial parameter: each set one
// value's trials, every other trial fitted), sharing one memo of the
// simulations, so a (trial, scales) pair that two splits evaluate runs
// once. result[k].simulations: the runs split k added.
// @throws CalibrationError as Calibrate, or for no set or an empty one.
std::vector<CalibrationResult> CalibrateSplits(
    const std::vector<CalibrationTrial>& trials, const SimulateFn& simulate,
    const CalibrationOptions& options, const std::vector<std::vector<std::int64_t>>& heldout_sets);
// The same with `simulator`, each trial's scene prepared once
// (Simulator::Prepare) and only its friction, grip force and mass changed.
CalibrationResult Calibrate(const std::vector<CalibrationTrial>& trials,
                            const simulators::Simulator& simulator,
                            const CalibrationOptions& options);

// The done trials of a campaign with their ground truth, each scene with
// `model_json`'s settings applied by `prepare` (the campaign's prediction).
// @throws db::StoreError.
std::vector<CalibrationTrial> LoadCalibrationTrials(
    const db::Store& store, std::int64_t campaign_id,
    const std::function<mechanics::Scene(const mechanics::Scene&)>& prepare);

// The result as stored (db::Calibration's params_json / report_json).
std::string ParamsJson(const CalibrationResult& r);
std::string ReportJson(const CalibrationResult& r);

}  // namespace arena::assessment
