// Calibration by derivative-free least squares (design: calibration.hpp).
#include "arena/assessment/calibration.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <numeric>
#include <thread>

#include <nlohmann/json.hpp>
#include <nlopt.hpp>

#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/support.hpp"

namespace arena::assessment {
namespace {

uint64_t Mix(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

std::vector<Eigen::Vector3d> Normals(const mechanics::Scene& scene) {
  std::vector<Eigen::Vector3d> n;
  for (const auto& f : scene.fingers) n.push_back(f.normal.normalized());
  if (scene.pusher) n.push_back(scene.pusher->normal.normalized());
  return n;
}

// Runs fn(i) for i in [0, n) on up to `threads` threads.
void ParallelFor(int n, int threads, const std::function<void(int)>& fn) {
  threads = std::clamp(threads, 1, std::max(1, n));
  if (threads == 1) {
    for (int i = 0; i < n; ++i) fn(i);
    return;
  }
  std::atomic<int> next{0};
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t)
    pool.emplace_back([&] {
      for (int i = next++; i < n; i = next++) fn(i);
    });
  for (auto& th : pool) th.join();
}

double PercentileOrNan(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<size_t>(std::floor(pos));
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

struct Errors {
  std::vector<TrialError> per_trial;
  double MeanLoss(const LossScales& s) const {
    double sum = 0;
    for (const auto& e : per_trial) sum += Loss(e, s);
    return per_trial.empty() ? 0 : sum / static_cast<double>(per_trial.size());
  }
};

using TrialSimulateFn =
    std::function<mechanics::SimulationResult(int trial, const mechanics::Scene& scene)>;

// One point the main fit evaluated: log scales and each training trial's loss.
struct Evaluated {
  std::vector<double> log_x;
  std::vector<double> losses;  // in the order of the training subset
};

// Every (trial, log scales) simulated so far: shared by the fits of one
// campaign's splits, which run one after another.
using Memo = std::map<std::pair<int, std::vector<double>>, TrialError>;

class Fitter {
 public:
  Fitter(const std::vector<CalibrationTrial>& trials, TrialSimulateFn simulate,
         const CalibrationOptions& o, Memo* memo)
      : trials_(trials), simulate_(std::move(simulate)), o_(o), memo_(*memo) {}

  std::map<std::string, double> ScalesOf(const std::vector<double>& log_x) const {
    std::map<std::string, double> s;
    for (size_t k = 0; k < o_.params.size(); ++k) s[ToString(o_.params[k])] = std::exp(log_x[k]);
    return s;
  }

  // Each trial of `subset` (repeats allowed) at log scales `log_x`; every
  // (trial, log_x) is simulated once, so one trial never runs on two threads.
  Errors Evaluate(const std::vector<int>& subset, const std::vector<double>& log_x) {
    std::vector<int> unsimulated;
    {
      std::lock_guard lock(mu_);
      for (int i : subset)
        if (!memo_.count({i, log_x}) &&
            std::find(unsimulated.begin(), unsimulated.end(), i) == unsimulated.end())
          unsimulated.push_back(i);
    }
    const auto scales = ScalesOf(log_x);
    std::vector<TrialError> fresh(unsimulated.size());
    ParallelFor(static_cast<int>(unsimulated.size()), o_.threads, [&](int k) {
      const int i = unsimulated[static_cast<size_t>(k)];
      const CalibrationTrial& t = trials_[static_cast<size_t>(i)];
      const mechanics::SimulationResult r = simulate_(i, ApplyScales(t.scene, scales));
      if (r.status != mechanics::SimulationStatus::kOk || r.samples.empty()) {
        fresh[static_cast<size_t>(k)].ok = false;
        return;
      }
      fresh[static_cast<size_t>(k)] =
          CompareTrajectories(t.scene, r.samples, t.truth, o_.scales.force_window_s);
    });
    Errors out;
    std::lock_guard lock(mu_);
    for (size_t k = 0; k < unsimulated.size(); ++k) memo_[{unsimulated[k], log_x}] = fresh[k];
    simulations_ += static_cast<long>(unsimulated.size());
    for (int i : subset) out.per_trial.push_back(memo_.at({i, log_x}));
    return out;
  }

  // Minimises the mean loss over `subset` from `start` (log scales). `record`:
  // the main fit (its points kept for the reuse bootstrap, reported per
  // evaluation).
  std::vector<double> Fit(const std::vector<int>& subset, std::vector<double> start, int max_eval,
                          double step, bool record, int* evaluations, std::string* stop) {
    const auto n = static_cast<unsigned>(o_.params.size());
    const nlopt::algorithm algorithm = n >= 2 ? nlopt::LN_BOBYQA : nlopt::LN_COBYLA;
    nlopt::opt opt(algorithm, n);
    opt.set_lower_bounds(std::vector<double>(n, std::log(o_.lower)));
    opt.set_upper_bounds(std::vector<double>(n, std::log(o_.upper)));
    opt.set_initial_step(step);
    opt.set_xtol_abs(1e-4);  // 0.01 % of a scale
    opt.set_maxeval(max_eval);
    struct Data {
      Fitter* self;
      const std::vector<int>* subset;
      bool record;
      int budget;
      int count;
      double best;
      std::vector<double> best_x;
    } data{this, &subset, record, max_eval, 0, INFINITY, start};
    opt.set_min_objective(
        [](const std::vector<double>& x, std::vector<double>&, void* p) {
          auto* d = static_cast<Data*>(p);
          ++d->count;
          const Errors e = d->self->Evaluate(*d->subset, x);
          const double loss = e.MeanLoss(d->self->o_.scales);
          if (loss < d->best) d->best = loss, d->best_x = x;
          if (d->record) {
            Evaluated point{x, {}};
            for (const auto& t : e.per_trial) point.losses.push_back(Loss(t, d->self->o_.scales));
            d->self->evaluated_.push_back(std::move(point));
            if (d->self->o_.on_evaluation)
              d->self->o_.on_evaluation(d->count, d->budget, loss, d->best);
          }
          return loss;
        },
        &data);
    double best = 0;
    nlopt::result result = nlopt::FAILURE;
    try {
      result = opt.optimize(start, best);
    } catch (const nlopt::roundoff_limited&) {
      result = nlopt::ROUNDOFF_LIMITED;  // start holds the best point found
    }
    if (evaluations) *evaluations = data.count;
    // The best point evaluated, not the optimiser's last iterate: on a loss
    // that is rough at small scales (MuJoCo's chattering contacts) the two
    // can differ, and the fit must never end worse than where it started.
    if (std::isfinite(data.best)) start = data.best_x;
    if (stop) {
      switch (result) {
        case nlopt::XTOL_REACHED:
          *stop = "xtol_reached";
          break;
        case nlopt::FTOL_REACHED:
          *stop = "ftol_reached";
          break;
        case nlopt::MAXEVAL_REACHED:
          *stop = "maxeval_reached";
          break;
        case nlopt::ROUNDOFF_LIMITED:
          *stop = "roundoff_limited";
          break;
        default:
          *stop = "result " + std::to_string(static_cast<int>(result));
      }
    }
    return start;
  }

  // Reuse bootstrap: the evaluated point minimising the weighted mean loss
  // (weights: how often each training trial was drawn).
  std::vector<double> BestEvaluated(const std::vector<double>& weights) const {
    const Evaluated* best = nullptr;
    double best_loss = INFINITY;
    for (const auto& p : evaluated_) {
      double sum = 0;
      for (size_t i = 0; i < weights.size(); ++i) sum += weights[i] * p.losses[i];
      if (sum < best_loss) best_loss = sum, best = &p;
    }
    return best ? best->log_x : std::vector<double>(o_.params.size(), 0.0);
  }

  long simulations() const { return simulations_; }

 private:
  const std::vector<CalibrationTrial>& trials_;
  TrialSimulateFn simulate_;
  const CalibrationOptions& o_;
  std::mutex mu_;
  Memo& memo_;
  long simulations_ = 0;
  std::vector<Evaluated> evaluated_;
};

void Mean(const Errors& e, double* pos, double* ang, double* force) {
  *pos = *ang = *force = 0;
  int n = 0;
  for (const auto& t : e.per_trial) {
    if (!t.ok) continue;
    *pos += t.position;
    *ang += t.angle;
    *force += t.force;
    ++n;
  }
  if (n > 0) {
    *pos /= n;
    *ang /= n;
    *force /= n;
  }
}

}  // namespace

SetFigures FiguresOf(const std::vector<TrialError>& errors) {
  SetFigures f;
  f.trials = static_cast<int>(errors.size());
  std::vector<PlanarOutcome> predicted, truth;
  std::vector<double> position, angle;
  for (const auto& t : errors) {
    if (!t.ok) continue;
    predicted.push_back(t.predicted_outcome);
    truth.push_back(t.true_outcome);
    position.push_back(t.position);
    angle.push_back(t.angle);
  }
  f.predicted = static_cast<int>(position.size());
  f.nmse = ComputeNmse(predicted, truth);
  if (!position.empty()) {
    f.position_median = PercentileOrNan(position, 0.5);
    f.position_p95 = PercentileOrNan(position, 0.95);
    f.angle_median = PercentileOrNan(angle, 0.5);
    f.angle_p95 = PercentileOrNan(angle, 0.95);
  }
  return f;
}

namespace {

std::optional<double> CommonValue(const std::vector<CalibrationTrial>& trials, CalibrationParam p) {
  std::optional<double> value;
  for (const auto& t : trials) {
    std::vector<double> vs;
    switch (p) {
      case CalibrationParam::kMuFingers:
        for (const auto& f : t.scene.fingers) vs.push_back(f.mu);
        break;
      case CalibrationParam::kMuPusher:
        if (t.scene.pusher) vs.push_back(t.scene.pusher->mu);
        break;
      case CalibrationParam::kGripForce:
        vs.push_back(t.scene.grip_force);
        break;
      case CalibrationParam::kObjectMass:
        vs.push_back(t.scene.object.mass);
        break;
      case CalibrationParam::kMuSupport:
        if (t.scene.support) vs.push_back(t.scene.support->mu);
        break;
      case CalibrationParam::kPressureRim:
        // Uniform pressure is the family's k = 1; given points have no common value.
        if (t.scene.support) vs.push_back(t.scene.support->pressure_points.empty() ? 1.0 : NAN);
        break;
    }
    for (double v : vs)
      if (std::isnan(v)) return std::nullopt;
    for (double v : vs) {
      if (!value) value = v;
      if (std::abs(*value - v) > 1e-12 * std::max(1.0, std::abs(v))) return std::nullopt;
    }
  }
  return value;
}

}  // namespace

const char* ToString(CalibrationParam p) {
  switch (p) {
    case CalibrationParam::kMuFingers:
      return "mu_fingers";
    case CalibrationParam::kMuPusher:
      return "mu_pusher";
    case CalibrationParam::kGripForce:
      return "grip_force";
    case CalibrationParam::kObjectMass:
      return "object_mass";
    case CalibrationParam::kMuSupport:
      return "mu_support";
    case CalibrationParam::kPressureRim:
      return "pressure_rim";
  }
  return "?";
}

namespace {

// The pressure_rim family (calibration.hpp) at k: the scene's pressure
// points weighted by k^rho, then tilted (w (1 + a . d)) so that their
// centre stays under the centre of mass.
void ScalePressure(mechanics::Scene* s, double k) {
  if (!s->support || k == 1) return;
  const mechanics::SupportPressure base = mechanics::SupportPressureOf(*s);
  // The scene's centre of pressure (under the centre of mass: the scene is valid).
  Eigen::Vector2d com = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < base.points_O.size(); ++i)
    com += base.weights[i] * base.points_O[i].head<2>();
  std::vector<Eigen::Vector2d> d;
  double far = 0;
  for (const auto& p : base.points_O) {
    d.push_back(p.head<2>() - com);
    far = std::max(far, d.back().norm());
  }
  if (!(far > 0)) return;
  std::vector<double> w(d.size());
  Eigen::Vector2d m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d mm = Eigen::Matrix2d::Zero();
  for (std::size_t i = 0; i < d.size(); ++i) {
    w[i] = base.weights[i] * std::pow(k, d[i].norm() / far);
    m += w[i] * d[i];
    mm += w[i] * d[i] * d[i].transpose();
  }
  // Σ w (1 + a.d) d = 0: the centre of pressure back under the centre of mass.
  Eigen::Vector2d a = Eigen::Vector2d::Zero();
  if (m.norm() > 1e-12 * far && std::abs(mm.determinant()) > 0) a = -mm.ldlt().solve(m);
  s->support->pressure_points.clear();
  for (std::size_t i = 0; i < d.size(); ++i) {
    const double wi = w[i] * (1 + a.dot(d[i]));
    if (!(wi >= 0))
      throw CalibrationError(
          "pressure_rim: scale " + std::to_string(k) +
          " needs a negative weight to keep the centre of pressure under the centre of mass "
          "(a face far from symmetric about it); narrow the bounds");
    const Eigen::Vector3d& p = base.points_O[i];
    s->support->pressure_points.emplace_back(p.x(), p.y(), wi);
  }
}

}  // namespace

CalibrationParam ParseCalibrationParam(const std::string& name) {
  for (auto p : {CalibrationParam::kMuFingers, CalibrationParam::kMuPusher,
                 CalibrationParam::kGripForce, CalibrationParam::kObjectMass,
                 CalibrationParam::kMuSupport, CalibrationParam::kPressureRim}) {
    if (name == ToString(p)) return p;
  }
  throw CalibrationError("--params: unknown parameter '" + name +
                         "' (expected mu_fingers, mu_pusher, grip_force, object_mass, "
                         "mu_support or pressure_rim)");
}

mechanics::Scene ApplyScales(const mechanics::Scene& scene,
                             const std::map<std::string, double>& scales) {
  mechanics::Scene s = scene;
  for (const auto& [name, k] : scales) {
    if (!(k > 0) || !std::isfinite(k))
      throw CalibrationError("calibration: scale of " + name + " must be finite and > 0");
    switch (ParseCalibrationParam(name)) {
      case CalibrationParam::kMuFingers:
        for (auto& f : s.fingers) f.mu *= k;
        break;
      case CalibrationParam::kMuPusher:
        if (s.pusher) s.pusher->mu *= k;
        break;
      case CalibrationParam::kGripForce:
        s.grip_force *= k;
        break;
      case CalibrationParam::kObjectMass:
        s.object.mass *= k;
        if (s.object.inertia) *s.object.inertia *= k;
        break;
      case CalibrationParam::kMuSupport:
        if (s.support) s.support->mu *= k;
        break;
      case CalibrationParam::kPressureRim:
        ScalePressure(&s, k);
        break;
    }
  }
  return s;
}

TrialError CompareTrajectories(const mechanics::Scene& scene,
                               const std::vector<mechanics::TrajectorySample>& predicted,
                               const std::vector<mechanics::TrajectorySample>& truth,
                               double window_s) {
  TrialError e;
  const size_t n = std::min(predicted.size(), truth.size());
  if (n == 0) {
    e.ok = false;
    return e;
  }
  const auto normals = Normals(scene);
  // Samples per window (250 Hz); 1 compares sample by sample.
  const auto w =
      static_cast<size_t>(std::max(1L, std::lround(window_s * mechanics::kSampleRateHz)));
  double sum = 0;
  long pairs = 0;
  for (size_t begin = 0; begin < n; begin += w) {
    const size_t end = std::min(n, begin + w);
    size_t m = normals.size();
    for (size_t i = begin; i < end; ++i)
      m = std::min({m, predicted[i].contacts.size(), truth[i].contacts.size()});
    for (size_t c = 0; c < m; ++c) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();  // mean over the window of f_pred - f_true
      for (size_t i = begin; i < end; ++i) {
        const auto& p = predicted[i].contacts[c];
        const auto& t = truth[i].contacts[c];
        d += (p.normal_force - t.normal_force) * normals[c] +
             (p.tangential_force - t.tangential_force);
      }
      d /= static_cast<double>(end - begin);
      sum += d.squaredNorm();
      ++pairs;
    }
  }
  e.position = (predicted[n - 1].position - truth[n - 1].position).norm();
  e.angle = predicted[n - 1].orientation.normalized().angularDistance(
      truth[n - 1].orientation.normalized());
  e.force = pairs ? std::sqrt(sum / static_cast<double>(pairs)) : 0;
  e.predicted_outcome = PlanarOutcomeOf(predicted[0].position, predicted[0].orientation,
                                        predicted[n - 1].position, predicted[n - 1].orientation);
  e.true_outcome = PlanarOutcomeOf(truth[0].position, truth[0].orientation, truth[n - 1].position,
                                   truth[n - 1].orientation);
  return e;
}

double Loss(const TrialError& e, const LossScales& s) {
  if (!e.ok) return kFailedTrialLoss;
  if (s.outcome_variance[0] > 0) {
    const PlanarOutcome& p = e.predicted_outcome;
    const PlanarOutcome& t = e.true_outcome;
    return ((p.dx - t.dx) * (p.dx - t.dx) / s.outcome_variance[0] +
            (p.dy - t.dy) * (p.dy - t.dy) / s.outcome_variance[1] +
            (p.dtheta - t.dtheta) * (p.dtheta - t.dtheta) / s.outcome_variance[2]) /
           3;
  }
  const double a = e.position / s.position_m, b = e.angle / s.angle_rad, c = e.force / s.force_n;
  return a * a + b * b + c * c;
}

std::map<std::string, double> CalibrationResult::Scales() const {
  std::map<std::string, double> s;
  for (const auto& f : fitted) s[f.name] = f.scale;
  return s;
}

namespace {

// Whether the per-trial loss increases over the fit's (paired) show a
// scale fitting worse: their mean is above kProfileMinIncrease of the fit's
// mean loss (`loss_at_fit`) and a one-sided Wilcoxon
// signed-rank test (normal approximation, zeros dropped) puts them above
// zero by more than kProfileStandardErrors standard deviations. Ranks, not
// a mean's standard error: one trial the model gets badly wrong would
// otherwise swamp the evidence of all the others.
bool FitsWorse(const std::vector<double>& increase, double loss_at_fit) {
  double mean = 0;
  std::vector<double> nonzero;
  for (double d : increase) {
    mean += d / static_cast<double>(increase.size());
    if (d != 0) nonzero.push_back(d);
  }
  if (!(mean > kProfileMinIncrease * loss_at_fit) || nonzero.empty()) return false;
  std::vector<size_t> order(nonzero.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return std::abs(nonzero[a]) < std::abs(nonzero[b]); });
  double w_plus = 0;  // sum of the ranks (ties: mean rank) of the positive increases
  for (size_t i = 0; i < order.size();) {
    size_t k = i;
    while (k + 1 < order.size() && std::abs(nonzero[order[k + 1]]) == std::abs(nonzero[order[i]]))
      ++k;
    const double rank = 0.5 * static_cast<double>(i + k) + 1;
    for (size_t m = i; m <= k; ++m)
      if (nonzero[order[m]] > 0) w_plus += rank;
    i = k + 1;
  }
  const auto n = static_cast<double>(nonzero.size());
  const double sd = std::sqrt(n * (n + 1) * (2 * n + 1) / 24);
  return (w_plus - n * (n + 1) / 4) > kProfileStandardErrors * sd;
}

// The scales profiled for parameter k (log): `points` spread over the
// bounds, six near the fit, and the fit itself; ascending, no repeats.
std::vector<double> ProfileGrid(double fit, const CalibrationOptions& o) {
  const double lo = std::log(o.lower), hi = std::log(o.upper);
  std::vector<double> xs = {fit};
  for (int i = 0; i < o.profile_points; ++i)
    xs.push_back(lo + (hi - lo) * i / std::max(1, o.profile_points - 1));
  for (double d : {0.05, 0.1, 0.2}) {
    if (fit - d >= lo) xs.push_back(fit - d);
    if (fit + d <= hi) xs.push_back(fit + d);
  }
  std::sort(xs.begin(), xs.end());
  xs.erase(std::unique(xs.begin(), xs.end(), [](double a, double b) { return b - a < 1e-9; }),
           xs.end());
  return xs;
}

// Identifiability profile of parameter k (calibration.hpp): the training
// loss along it alone, and the run of scales around the fit that do not fit
// worse (FitsWorse).
void Profile(Fitter& fitter, const std::vector<int>& train, const std::vector<double>& best,
             size_t k, const CalibrationOptions& o, FittedParam* f) {
  std::vector<double> at_fit;
  for (const auto& e : fitter.Evaluate(train, best).per_trial) at_fit.push_back(Loss(e, o.scales));
  const double mean_at_fit =
      std::accumulate(at_fit.begin(), at_fit.end(), 0.0) / static_cast<double>(at_fit.size());
  const std::vector<double> xs = ProfileGrid(best[k], o);
  std::vector<bool> as_good(xs.size());
  size_t fit_index = 0;
  for (size_t j = 0; j < xs.size(); ++j) {
    if (xs[j] == best[k]) fit_index = j;
    std::vector<double> x = best;
    x[k] = xs[j];
    const Errors e = fitter.Evaluate(train, x);
    std::vector<double> increase;
    for (size_t i = 0; i < at_fit.size(); ++i)
      increase.push_back(Loss(e.per_trial[i], o.scales) - at_fit[i]);
    as_good[j] = !FitsWorse(increase, mean_at_fit);
    f->profile.emplace_back(std::exp(xs[j]), e.MeanLoss(o.scales));
  }
  size_t low = fit_index, high = fit_index;
  while (low > 0 && as_good[low - 1]) --low;
  while (high + 1 < xs.size() && as_good[high + 1]) ++high;
  // The range reported is bracketed by the nearest scales that fit worse:
  // the data rule out what lies beyond them, not what lies between.
  f->profiled = true;
  f->bounded_low = low > 0;
  f->bounded_high = high + 1 < xs.size();
  f->profile_low = std::exp(f->bounded_low ? xs[low - 1] : xs[low]);
  f->profile_high = std::exp(f->bounded_high ? xs[high + 1] : xs[high]);
}

// The options a fit cannot start with, each named by its flag.
void CheckFitOptions(const std::vector<CalibrationTrial>& trials, const CalibrationOptions& o) {
  if (o.params.empty()) throw CalibrationError("--params: name at least one parameter");
  for (size_t i = 0; i < o.params.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      if (o.params[i] == o.params[j])
        throw CalibrationError(std::string("--params: ") + ToString(o.params[i]) + " is repeated");
  if (!(o.holdout >= 0 && o.holdout <= 0.9))
    throw CalibrationError("--holdout: must be in [0, 0.9] (0: fit every trial, none held out)");
  if (!(o.lower > 0 && o.lower < 1 && o.upper > 1 && std::isfinite(o.upper)))
    throw CalibrationError("bounds: need 0 < lower < 1 < upper");
  if (trials.size() < 4)
    throw CalibrationError("--campaign: " + std::to_string(trials.size()) +
                           " done trials with ground truth; calibration needs at least 4");
  if (o.max_evaluations < 5) throw CalibrationError("--max-evaluations: must be >= 5");
  if (o.bootstrap < 0) throw CalibrationError("--bootstrap: must be >= 0");
  if (o.profile_points != 0 && o.profile_points < 3)
    throw CalibrationError("--profile-points: must be 0 (no profile) or >= 3");
}

// Which trials are fitted and which held out (indices into the trials, ascending).
struct TrialSplit {
  std::vector<int> train, hold;
};

TrialSplit SplitTrials(const std::vector<CalibrationTrial>& trials, const CalibrationOptions& o) {
  // Seeded split: order trials by a hash of (seed, id), hold out the first part.
  std::vector<int> order(trials.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const auto ha =
        Mix(o.seed ^ Mix(static_cast<uint64_t>(trials[static_cast<size_t>(a)].trial_id)));
    const auto hb =
        Mix(o.seed ^ Mix(static_cast<uint64_t>(trials[static_cast<size_t>(b)].trial_id)));
    return ha != hb ? ha < hb : a < b;
  });
  TrialSplit split;
  std::vector<int>& hold = split.hold;
  std::vector<int>& train = split.train;
  if (!o.heldout_ids.empty()) {
    // A given split (by a trial parameter): these held out, the rest fitted.
    for (std::int64_t id : o.heldout_ids)
      if (std::none_of(trials.begin(), trials.end(),
                       [id](const CalibrationTrial& t) { return t.trial_id == id; }))
        throw CalibrationError("held-out trial " + std::to_string(id) +
                               " is not among the campaign's done trials");
    for (int i = 0; i < static_cast<int>(trials.size()); ++i) {
      const bool held = std::find(o.heldout_ids.begin(), o.heldout_ids.end(),
                                  trials[static_cast<size_t>(i)].trial_id) != o.heldout_ids.end();
      (held ? hold : train).push_back(i);
    }
    if (train.size() < 2)
      throw CalibrationError("the split leaves " + std::to_string(train.size()) +
                             " trial(s) to fit; it needs at least 2");
  } else if (o.holdout == 0) {
    // Every trial fitted and scored (the in-sample protocol): nothing held out.
    for (int i = 0; i < static_cast<int>(trials.size()); ++i) train.push_back(i);
  } else {
    const int n_hold =
        std::clamp(static_cast<int>(std::lround(o.holdout * static_cast<double>(trials.size()))), 1,
                   static_cast<int>(trials.size()) - 2);
    hold.assign(order.begin(), order.begin() + n_hold);
    train.assign(order.begin() + n_hold, order.end());
  }
  std::sort(hold.begin(), hold.end());
  std::sort(train.begin(), train.end());
  return split;
}

// The outcome loss's variances (dx, dy, dtheta) over the training trials'
// true outcomes (their first to last sample); zero without that loss.
std::array<double, 3> OutcomeVariances(const std::vector<CalibrationTrial>& trials,
                                       const std::vector<int>& train, const CalibrationOptions& o) {
  std::array<double, 3> variance = {0, 0, 0};
  if (!o.outcome_loss) return variance;
  std::vector<PlanarOutcome> outcomes;
  for (int i : train) {
    const auto& truth = trials[static_cast<size_t>(i)].truth;
    if (truth.empty()) continue;
    outcomes.push_back(PlanarOutcomeOf(truth.front().position, truth.front().orientation,
                                       truth.back().position, truth.back().orientation));
  }
  std::string why;
  if (!ComputeNmse(outcomes, outcomes, &why))
    throw CalibrationError("--loss nmse: the fitted trials' outcomes cannot normalise it: " + why);
  for (int k = 0; k < 3; ++k) {
    double mean = 0, var = 0;
    auto get = [k](const PlanarOutcome& p) { return k == 0 ? p.dx : k == 1 ? p.dy : p.dtheta; };
    for (const auto& p : outcomes) mean += get(p) / static_cast<double>(outcomes.size());
    for (const auto& p : outcomes)
      var += (get(p) - mean) * (get(p) - mean) / static_cast<double>(outcomes.size());
    variance[static_cast<size_t>(k)] = var;
  }
  return variance;
}

void Say(const CalibrationOptions& o, const std::string& line) {
  if (o.progress) o.progress(line);
}

// The main fit from the nominal scales (log 0) and its figures before and
// after, on the fitted and the held-out trials; returns the fit (log scales).
std::vector<double> FitAndScore(Fitter& fitter, const TrialSplit& split,
                                const CalibrationOptions& o, CalibrationResult* r) {
  const std::vector<int>& train = split.train;
  const std::vector<int>& hold = split.hold;
  const std::vector<double> zero(o.params.size(), 0.0);
  Say(o, "fitting " + std::to_string(o.params.size()) + " parameter(s) on " +
             std::to_string(train.size()) + " trials (" + std::to_string(hold.size()) +
             " held out)");
  r->train_before = fitter.Evaluate(train, zero).MeanLoss(o.scales);
  std::vector<double> best =
      fitter.Fit(train, zero, o.max_evaluations, 0.3, true, &r->evaluations, &r->stop);
  r->train_after = fitter.Evaluate(train, best).MeanLoss(o.scales);

  Say(o, "held-out trials before and after");
  const Errors before = fitter.Evaluate(hold, zero);
  const Errors after = fitter.Evaluate(hold, best);
  r->heldout_before = before.MeanLoss(o.scales);
  r->heldout_after = after.MeanLoss(o.scales);
  Mean(before, &r->heldout_position_before, &r->heldout_angle_before, &r->heldout_force_before);
  Mean(after, &r->heldout_position_after, &r->heldout_angle_after, &r->heldout_force_after);
  // Nothing held out: the fit is judged on the trials it fitted.
  r->improved =
      hold.empty() ? r->train_after < r->train_before : r->heldout_after < r->heldout_before;
  r->heldout_errors_before = before.per_trial;
  r->heldout_errors_after = after.per_trial;
  r->heldout_figures_before = FiguresOf(before.per_trial);
  r->heldout_figures_after = FiguresOf(after.per_trial);
  r->train_figures_before = FiguresOf(fitter.Evaluate(train, zero).per_trial);
  r->train_figures_after = FiguresOf(fitter.Evaluate(train, best).per_trial);
  return best;
}

// Bootstrap: resample the training trials; refit from the optimum, or
// take the best point the main fit evaluated (calibration.hpp). The
// scales (not logs) each replicate found, per parameter.
std::vector<std::vector<double>> BootstrapScales(Fitter& fitter, const std::vector<int>& train,
                                                 const std::vector<double>& best,
                                                 const CalibrationOptions& o) {
  std::vector<std::vector<double>> boot(o.params.size());
  for (int b = 0; b < o.bootstrap; ++b) {
    if (o.bootstrap_method == BootstrapMethod::kRefit)
      Say(o, "bootstrap " + std::to_string(b + 1) + "/" + std::to_string(o.bootstrap));
    std::vector<int> resample;
    std::vector<double> weights(train.size(), 0.0);
    for (size_t i = 0; i < train.size(); ++i) {
      const uint64_t h = Mix(Mix(o.seed ^ 0xb007ULL) + static_cast<uint64_t>(b) * 7919 + i);
      resample.push_back(train[static_cast<size_t>(h % train.size())]);
      weights[static_cast<size_t>(h % train.size())] += 1;
    }
    const auto x = o.bootstrap_method == BootstrapMethod::kRefit
                       ? fitter.Fit(resample, best, std::max(10, o.max_evaluations / 3), 0.1, false,
                                    nullptr, nullptr)
                       : fitter.BestEvaluated(weights);
    for (size_t k = 0; k < o.params.size(); ++k) boot[k].push_back(std::exp(x[k]));
  }
  return boot;
}

// Each parameter's fitted scale, its bootstrap spread and profile, and
// its nominal value.
FittedParam FittedParamOf(const std::vector<CalibrationTrial>& trials, const CalibrationOptions& o,
                          size_t k, double best, const std::vector<double>& boot,
                          FittedParam profile) {
  FittedParam f = std::move(profile);
  f.name = ToString(o.params[k]);
  f.scale = std::exp(best);
  f.ci_low = f.ci_high = f.scale;
  if (boot.size() >= 2) {
    const double mean =
        std::accumulate(boot.begin(), boot.end(), 0.0) / static_cast<double>(boot.size());
    double ss = 0;
    for (double v : boot) ss += (v - mean) * (v - mean);
    f.std = std::sqrt(ss / static_cast<double>(boot.size() - 1));
    f.ci_low = PercentileOrNan(boot, 0.025);
    f.ci_high = PercentileOrNan(boot, 0.975);
  }
  f.nominal = CommonValue(trials, o.params[k]);
  return f;
}

CalibrationResult Fitted(const std::vector<CalibrationTrial>& trials, TrialSimulateFn simulate,
                         const CalibrationOptions& given, Memo* memo) {
  CheckFitOptions(trials, given);
  const TrialSplit split = SplitTrials(trials, given);
  CalibrationOptions o = given;  // the outcome loss's variances filled in
  o.scales.outcome_variance = OutcomeVariances(trials, split.train, o);
  CalibrationResult r;
  for (int i : split.train) r.train_ids.push_back(trials[static_cast<size_t>(i)].trial_id);
  for (int i : split.hold) r.heldout_ids.push_back(trials[static_cast<size_t>(i)].trial_id);
  Fitter fitter(trials, std::move(simulate), o, memo);
  const auto dims = o.params.size();
  r.optimizer = dims >= 2 ? "LN_BOBYQA" : "LN_COBYLA";
  r.bootstrap_method = ToString(o.bootstrap_method);
  const std::vector<double> best = FitAndScore(fitter, split, o, &r);
  const std::vector<std::vector<double>> boot = BootstrapScales(fitter, split.train, best, o);
  std::vector<FittedParam> profiles(dims);
  if (o.profile_points > 0) {
    for (size_t k = 0; k < dims; ++k) {
      Say(o, std::string("profile of ") + ToString(o.params[k]));
      Profile(fitter, split.train, best, k, o, &profiles[k]);
    }
  }
  r.simulations = fitter.simulations();
  for (size_t k = 0; k < dims; ++k)
    r.fitted.push_back(FittedParamOf(trials, o, k, best[k], boot[k], profiles[k]));
  return r;
}

}  // namespace

const char* ToString(BootstrapMethod m) { return m == BootstrapMethod::kReuse ? "reuse" : "refit"; }

CalibrationResult Calibrate(const std::vector<CalibrationTrial>& trials, const SimulateFn& simulate,
                            const CalibrationOptions& o) {
  Memo memo;
  return Fitted(
      trials, [&simulate](int, const mechanics::Scene& scene) { return simulate(scene); }, o,
      &memo);
}

std::vector<CalibrationResult> CalibrateSplits(
    const std::vector<CalibrationTrial>& trials, const SimulateFn& simulate,
    const CalibrationOptions& o, const std::vector<std::vector<std::int64_t>>& heldout_sets) {
  if (heldout_sets.empty()) throw CalibrationError("splits: give at least one held-out set");
  Memo memo;
  std::vector<CalibrationResult> out;
  long simulated = 0;
  for (const auto& held : heldout_sets) {
    if (held.empty()) throw CalibrationError("splits: a held-out set is empty");
    CalibrationOptions so = o;
    so.heldout_ids = held;
    out.push_back(Fitted(
        trials, [&simulate](int, const mechanics::Scene& scene) { return simulate(scene); }, so,
        &memo));
    // Fitted counts what its fitter ran; the memo's earlier entries were free.
    out.back().simulations = static_cast<long>(memo.size()) - simulated;
    simulated = static_cast<long>(memo.size());
  }
  return out;
}

CalibrationResult Calibrate(const std::vector<CalibrationTrial>& trials,
                            const simulators::Simulator& simulator, const CalibrationOptions& o) {
  // Each trial's model built on its first run (Fitter never runs one trial
  // on two threads at once).
  std::vector<std::unique_ptr<simulators::PreparedScene>> prepared(trials.size());
  std::vector<std::once_flag> once(trials.size());
  Memo memo;
  CalibrationResult r = Fitted(
      trials,
      [&](int i, const mechanics::Scene& scene) {
        const auto k = static_cast<size_t>(i);
        std::call_once(once[k], [&] { prepared[k] = simulator.Prepare(trials[k].scene); });
        return prepared[k]->Simulate(scene);
      },
      o, &memo);
  for (const auto& p : prepared)
    if (p) r.models_reused += p->reused();
  return r;
}

std::vector<CalibrationTrial> LoadCalibrationTrials(
    const db::Store& store, std::int64_t campaign_id,
    const std::function<mechanics::Scene(const mechanics::Scene&)>& prepare) {
  std::vector<CalibrationTrial> out;
  for (const auto& t : store.ListTrials(campaign_id)) {
    if (t.state != db::TrialState::kDone || !t.gt_stream_id) continue;
    CalibrationTrial c;
    c.trial_id = t.id;
    const mechanics::Scene scene = mechanics::ParseScene(t.scene_json);
    c.scene = prepare(scene);
    const auto normals = Normals(scene);
    for (const auto& s : store.ReadGroundTruth(t.id).samples) {
      mechanics::TrajectorySample ts;
      ts.t = s.t;
      ts.position = {s.object_pose[0], s.object_pose[1], s.object_pose[2]};
      ts.orientation = Eigen::Quaterniond(s.object_pose[3], s.object_pose[4], s.object_pose[5],
                                          s.object_pose[6]);
      for (size_t i = 0; i < s.contacts.size() && i < normals.size(); ++i) {
        const Eigen::Vector3d f(s.contacts[i].force[0], s.contacts[i].force[1],
                                s.contacts[i].force[2]);
        mechanics::ContactState cs;
        cs.normal_force = f.dot(normals[i]);
        cs.tangential_force = f - cs.normal_force * normals[i];
        ts.contacts.push_back(cs);
      }
      c.truth.push_back(std::move(ts));
    }
    out.push_back(std::move(c));
  }
  return out;
}

std::string BootstrapWarning(const FittedParam& f) {
  if (!f.fit_outside_bootstrap()) return "";
  char buf[640];
  std::snprintf(buf, sizeof buf,
                "%s: the fit %.4f lies outside its own bootstrap interval [%.4f, %.4f]: every "
                "resampled refit moved %s, so the interval says where the refits went, not how "
                "uncertain the fit is (the fit may have stopped short of its optimum, or a few "
                "trials pull it). Read the profile column.",
                f.name.c_str(), f.scale, f.ci_low, f.ci_high,
                f.scale > f.ci_high ? "below it" : "above it");
  return buf;
}

std::string ParamsJson(const CalibrationResult& r) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& f : r.fitted) {
    nlohmann::json p = {{"scale", f.scale},
                        {"std", f.std},
                        {"ci95", {f.ci_low, f.ci_high}},
                        {"fit_outside_ci95", f.fit_outside_bootstrap()}};
    if (f.profiled) {
      nlohmann::json loss = nlohmann::json::array();
      for (const auto& [scale, l] : f.profile) loss.push_back({scale, l});
      p["profile"] = {{"range", {f.profile_low, f.profile_high}},
                      {"bounded", {f.bounded_low, f.bounded_high}},
                      {"identified", f.identified()},
                      {"loss", loss}};
    }
    if (f.nominal) {
      p["nominal"] = *f.nominal;
      p["value"] = *f.nominal * f.scale;
    }
    j[f.name] = p;
  }
  return j.dump();
}

nlohmann::json ToJson(const SetFigures& f) {
  nlohmann::json nmse = nullptr;
  if (f.nmse)
    nmse = {{"value", f.nmse->mean},
            {"dx", f.nmse->dx},
            {"dy", f.nmse->dy},
            {"dtheta", f.nmse->dtheta}};
  return {{"trials", f.trials},
          {"predicted", f.predicted},
          {"outcome_nmse", nmse},
          {"position_error_m", {{"median", f.position_median}, {"p95", f.position_p95}}},
          {"angle_error_rad", {{"median", f.angle_median}, {"p95", f.angle_p95}}}};
}

std::string ReportJson(const CalibrationResult& r) {
  return nlohmann::json{
      {"train_ids", r.train_ids},
      {"heldout_ids", r.heldout_ids},
      {"train_loss", {{"before", r.train_before}, {"after", r.train_after}}},
      {"heldout_loss", {{"before", r.heldout_before}, {"after", r.heldout_after}}},
      {"heldout_position_m",
       {{"before", r.heldout_position_before}, {"after", r.heldout_position_after}}},
      {"heldout_angle_rad", {{"before", r.heldout_angle_before}, {"after", r.heldout_angle_after}}},
      {"heldout_force_n", {{"before", r.heldout_force_before}, {"after", r.heldout_force_after}}},
      {"train_figures",
       {{"before", ToJson(r.train_figures_before)}, {"after", ToJson(r.train_figures_after)}}},
      {"heldout_figures",
       {{"before", ToJson(r.heldout_figures_before)}, {"after", ToJson(r.heldout_figures_after)}}},
      {"improved", r.improved},
      {"evaluations", r.evaluations},
      {"optimizer", r.optimizer},
      {"stop", r.stop},
      {"bootstrap_method", r.bootstrap_method},
      {"simulations", r.simulations},
      {"models_reused", r.models_reused}}
      .dump();
}

}  // namespace arena::assessment
