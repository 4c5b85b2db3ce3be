// Simulate(): steps the contact model over the scene's duration and samples
// it at 250 Hz. Each sample at t in (t_n, t_{n+1}] reports the pose at t
// (exact: the pose moves linearly in position and along a constant rotation
// within a step), the twist and contact forces of that step; the sample at
// t = 0 reports the initial pose and rest twist with the first step's forces.
#include "arena/mechanics/simulate.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <nlohmann/json.hpp>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/pusher_motion.hpp"

namespace arena::mechanics {

const char* ToString(ContactMode mode) {
  switch (mode) {
    case ContactMode::kStick:
      return "stick";
    case ContactMode::kSlide:
      return "slide";
    case ContactMode::kSeparate:
      return "separate";
  }
  return "unknown";
}

const char* ToString(SimulationStatus status) {
  switch (status) {
    case SimulationStatus::kOk:
      return "ok";
    case SimulationStatus::kSolverFailure:
      return "solver_failure";
    case SimulationStatus::kInvalidScene:
      return "invalid_scene";
  }
  return "unknown";
}

const char* ToString(GraspStatus status) {
  switch (status) {
    case GraspStatus::kHeld:
      return "held";
    case GraspStatus::kLost:
      return "lost";
    case GraspStatus::kLeftGeometry:
      return "left_geometry";
  }
  return "unknown";
}

std::string SolverStatisticsJson(const SolverStatistics& solver) {
  return nlohmann::json({{"steps", solver.steps},
                         {"max_pivots", solver.max_pivots},
                         {"failures", solver.failures},
                         {"quasi_static_solves", solver.quasi_static_solves},
                         {"quasi_static_carried", solver.quasi_static_carried}})
      .dump();
}

std::string OscillationJson(const Oscillation& oscillation) {
  return nlohmann::json({{"detected", oscillation.detected},
                         {"amplitude_m", oscillation.amplitude_m},
                         {"amplitude_rad", oscillation.amplitude_rad},
                         {"frequency_hz", oscillation.frequency_hz},
                         {"window_s", oscillation.window_s},
                         {"periods", oscillation.periods}})
      .dump();
}

std::string ImpactJson(const Impact& impact) {
  nlohmann::json dt_limit = nullptr;  // infinite: nothing holds the object
  if (std::isfinite(impact.resolving_dt)) dt_limit = impact.resolving_dt;
  return nlohmann::json({{"detected", impact.detected},
                         {"t", impact.t},
                         {"approach_speed", impact.approach_speed},
                         {"momentum", impact.momentum},
                         {"holding_force", impact.holding_force},
                         {"resolving_dt", dt_limit},
                         {"resolved", impact.resolved}})
      .dump();
}

std::string SteeredSlipJson(const SteeredSlip& steered) {
  return nlohmann::json({{"detected", steered.detected},
                         {"share", steered.share},
                         {"max_rad", steered.max_rad},
                         {"steered_s", steered.steered_s}})
      .dump();
}

std::string RunFlagsJson(const SimulationResult& result) {
  nlohmann::json flags = nlohmann::json::object();
  if (result.oscillation.detected)
    flags["oscillation"] = nlohmann::json::parse(OscillationJson(result.oscillation));
  if (result.impact.detected && !result.impact.resolved)
    flags["impact"] = nlohmann::json::parse(ImpactJson(result.impact));
  if (result.steered_slip.detected)
    flags["steered_slip"] = nlohmann::json::parse(SteeredSlipJson(result.steered_slip));
  return flags.dump();
}

bool HasRunFlag(const std::string& detail_json, const char* flag) {
  const auto d = nlohmann::json::parse(detail_json, nullptr, false);
  return !d.is_discarded() && d.is_object() && d.contains(flag);
}

SimulationResult Simulate(const Scene& scene) { return Simulate(scene, nullptr); }

namespace {

// The command a closed loop may apply: translation within the model's plane
// (when the model is planar), the scene's own turning.
std::string CheckCommand(const Scene& scene, const ModelInfo& info, const PusherMotion& command) {
  if (!command.velocity.allFinite() || !command.angular_velocity.allFinite())
    return "pusher command: not finite";
  if (command.angular_velocity != scene.pusher->motion.angular_velocity)
    return "pusher command: angular velocity differs from the scene's (the model turns the pusher "
           "at a constant rate only)";
  if (info.dof == 3) {
    Scene with = scene;
    with.pusher->motion = command;
    const PlaneCheck plane = FindPlane(with);
    const PlaneCheck base = FindPlane(scene);
    if (!plane.planar || plane.normal.cross(base.normal).norm() > 1e-6)
      return "pusher command: leaves the plane of the planar model";
  }
  return "";
}

// The least-squares quadratic in τ ∈ [-1, 1] through (τ_i, y_i), subtracted.
std::vector<double> Detrended(const std::vector<double>& tau, const std::vector<double>& y) {
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < y.size(); ++i) {
    const Eigen::Vector3d phi(1, tau[i], tau[i] * tau[i]);
    A += phi * phi.transpose();
    b += phi * y[i];
  }
  const Eigen::Vector3d coef = A.ldlt().solve(b);
  std::vector<double> r(y.size());
  for (size_t i = 0; i < y.size(); ++i)
    r[i] = y[i] - (coef[0] + coef[1] * tau[i] + coef[2] * tau[i] * tau[i]);
  return r;
}

// Rotation vectors of q relative to its middle pose (small for a run that
// does not turn far, so each coordinate is an angle about a fixed axis).
std::vector<Eigen::Vector3d> RotationsFromMiddle(const std::vector<Eigen::Quaterniond>& q,
                                                 size_t n) {
  const Eigen::Quaterniond ref = q[n / 2].normalized();
  std::vector<Eigen::Vector3d> rot(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::AngleAxisd aa(q[i].normalized() * ref.conjugate());
    rot[i] = aa.angle() * aa.axis();
  }
  return rot;
}

// One coordinate of a run's poses for the oscillation detectors: the centre
// of mass along x, y, z (k = 0..2, m) or the rotation from the middle pose
// about x, y, z (k = 3..5, rad), its threshold (the gap tolerance, as an
// angle over the length scale), and what is left of it after its
// least-squares quadratic in τ with that residual's sum of squares.
struct PoseCoordinate {
  bool angle = false;
  double threshold = 0;
  std::vector<double> y, residual;
  double sum2 = 0;
};

PoseCoordinate CoordinateOf(int k, const std::vector<Eigen::Vector3d>& c,
                            const std::vector<Eigen::Vector3d>& rot, const std::vector<double>& tau,
                            double gap_tolerance, double length_scale) {
  PoseCoordinate out;
  const size_t n = tau.size();
  out.angle = k >= 3;
  out.threshold = out.angle ? gap_tolerance / length_scale : gap_tolerance;
  out.y.resize(n);
  for (size_t i = 0; i < n; ++i) out.y[i] = out.angle ? rot[i][k - 3] : c[i][k];
  out.residual = Detrended(tau, out.y);
  for (double x : out.residual) out.sum2 += x * x;
  return out;
}

// A coordinate found swinging: its amplitude joins the translation's or
// the rotation's, and the coordinate farthest above its threshold (`worst`,
// amplitude over threshold so far) names the frequency and periods.
void NoteMode(const PoseCoordinate& pc, double amplitude, double frequency_hz, double periods,
              double& worst, Oscillation& out) {
  out.detected = true;
  if (pc.angle) {
    out.amplitude_rad = std::max(out.amplitude_rad, amplitude);
  } else {
    out.amplitude_m = std::max(out.amplitude_m, amplitude);
  }
  if (amplitude / pc.threshold > worst) {
    worst = amplitude / pc.threshold;
    out.frequency_hz = frequency_hz;
    out.periods = periods;
  }
}

}  // namespace

Oscillation DetectSlowOscillation(const std::vector<double>& t,
                                  const std::vector<Eigen::Vector3d>& c,
                                  const std::vector<Eigen::Quaterniond>& q, double gap_tolerance,
                                  double length_scale) {
  Oscillation out;
  const size_t n = std::min({t.size(), c.size(), q.size()});
  if (n < 16 || !(t[n - 1] > t[0])) return out;
  const double window = t[n - 1] - t[0];
  const double mid = 0.5 * (t[0] + t[n - 1]), half = 0.5 * window;
  std::vector<double> tau(n);
  for (size_t i = 0; i < n; ++i) tau[i] = (t[i] - mid) / half;
  const std::vector<Eigen::Vector3d> rot = RotationsFromMiddle(q, n);
  double worst = 0;
  for (int k = 0; k < 6; ++k) {
    const PoseCoordinate pc = CoordinateOf(k, c, rot, tau, gap_tolerance, length_scale);
    const double threshold = pc.threshold, sum2 = pc.sum2;
    const std::vector<double>& y = pc.y;
    if (!(std::sqrt(2.0 * sum2 / static_cast<double>(n)) > threshold)) continue;
    // The acceleration at the interior steps against [1, τ, τ², y]: y
    // scaled by its residual's RMS so that the columns are comparable.
    const double scale = std::sqrt(sum2 / static_cast<double>(n));
    const long m = static_cast<long>(n) - 2;
    Eigen::MatrixXd X(m, 4);
    Eigen::VectorXd acc(m);
    double mean_step = 0;
    for (long j = 0; j < m; ++j) {
      const size_t i = static_cast<size_t>(j) + 1;
      const double h0 = t[i] - t[i - 1], h1 = t[i + 1] - t[i];
      acc[j] = 2.0 * ((y[i + 1] - y[i]) / h1 - (y[i] - y[i - 1]) / h0) / (h0 + h1);
      X.row(j) << 1.0, tau[i], tau[i] * tau[i], y[i] / scale;
      mean_step += 0.5 * (h0 + h1);
    }
    mean_step /= static_cast<double>(m);
    const Eigen::Vector4d coef = X.colPivHouseholderQr().solve(acc);
    const double omega2 = -coef[3] / scale;  // the restoring force per unit of y
    if (!(omega2 > 0)) continue;
    const double total = (acc.array() - acc.mean()).square().sum();
    const double unexplained = (acc - X * coef).squaredNorm();
    if (!(total > 0) || !(1.0 - unexplained / total >= kSlowModeFit)) continue;
    // ω from the discrete second difference, -(2 - 2 cos ω h) / h² = -ω²_d.
    const double half_angle = std::sqrt(omega2) * mean_step / 2;
    if (!(half_angle < 1.0)) continue;  // beyond the steps' resolution
    const double omega = 2.0 * std::asin(half_angle) / mean_step;
    const double periods = omega * window / (2 * M_PI);
    if (periods < kSlowModeMinPeriods) continue;
    // The path the mode swings about: y'' = q'' - ω² (y - q) for the
    // quadratic q(τ) = q0 + q1 τ + q2 τ² (q'' = 2 q2 / half² in time).
    const double q2 = coef[2] / omega2, q1 = coef[1] / omega2;
    const double q0 = (coef[0] - 2.0 * q2 / (half * half)) / omega2;
    double swing2 = 0;
    for (size_t i = 0; i < n; ++i) {
      const double s = y[i] - (q0 + q1 * tau[i] + q2 * tau[i] * tau[i]);
      swing2 += s * s;
    }
    const double amplitude = std::sqrt(2.0 * swing2 / static_cast<double>(n));
    if (!(amplitude > threshold)) continue;
    NoteMode(pc, amplitude, omega / (2 * M_PI), periods, worst, out);
  }
  if (out.detected) out.window_s = window;
  return out;
}

Oscillation DetectOscillation(const std::vector<double>& t, const std::vector<Eigen::Vector3d>& c,
                              const std::vector<Eigen::Quaterniond>& q, double gap_tolerance,
                              double length_scale) {
  Oscillation out;
  const size_t n = std::min({t.size(), c.size(), q.size()});
  if (n < 16 || !(t[n - 1] > t[0])) return out;
  out.window_s = t[n - 1] - t[0];
  const double mid = 0.5 * (t[0] + t[n - 1]), half = 0.5 * out.window_s;
  std::vector<double> tau(n);
  for (size_t i = 0; i < n; ++i) tau[i] = (t[i] - mid) / half;
  const std::vector<Eigen::Vector3d> rot = RotationsFromMiddle(q, n);
  double worst = 0;  // amplitude over threshold of the strongest oscillating coordinate
  for (int k = 0; k < 6; ++k) {
    const PoseCoordinate pc = CoordinateOf(k, c, rot, tau, gap_tolerance, length_scale);
    const double threshold = pc.threshold, sum2 = pc.sum2;
    const std::vector<double>& r = pc.residual;
    const double amplitude = std::sqrt(2.0 * sum2 / static_cast<double>(n));
    if (!(amplitude > threshold)) continue;
    // Swings from beyond +h to beyond -h and back (h = threshold / 2):
    // rounding or a single kink the quadratic missed does not count.
    const double h = 0.5 * threshold;
    int side = 0, crossings = 0;
    for (double x : r) {
      const int now = x > h ? 1 : (x < -h ? -1 : 0);
      if (now != 0 && side != 0 && now != side) ++crossings;
      if (now != 0) side = now;
    }
    if (crossings < kOscillationCrossings) continue;
    NoteMode(pc, amplitude, crossings / (2.0 * out.window_s), crossings / 2.0, worst, out);
  }
  return out;
}

namespace {

// The object's pose at every step after the run's first tenth, in a ring of
// at most kOscillationWindowSteps: DetectSlowOscillation reads all of it,
// DetectOscillation the run's last quarter (at most as many steps).
class PoseRing {
 public:
  void Size(long n_steps) {
    capacity_ =
        static_cast<size_t>(std::clamp(n_steps - n_steps / 10, 1L, long{kOscillationWindowSteps}));
    quarter_ = static_cast<size_t>(std::clamp(n_steps / 4, 1L, long{kOscillationWindowSteps}));
    t_.reserve(capacity_);
    c_.reserve(capacity_);
    q_.reserve(capacity_);
  }

  void Push(double t, const Eigen::Vector3d& c, const Eigen::Quaterniond& q) {
    if (t_.size() < capacity_) {
      t_.push_back(t);
      c_.push_back(c);
      q_.push_back(q);
      return;
    }
    t_[next_] = t;
    c_[next_] = c;
    q_[next_] = q;
    next_ = (next_ + 1) % capacity_;
  }

  // The run's oscillation, if any (none from fewer than 16 poses): the
  // fast detector on the last quarter first, the slow one on the whole ring
  // when that finds nothing. Leaves the ring oldest first.
  Oscillation Detect(double gap_tolerance, double length_scale) {
    if (t_.size() < 16) return {};
    std::rotate(t_.begin(), t_.begin() + static_cast<long>(next_), t_.end());
    std::rotate(c_.begin(), c_.begin() + static_cast<long>(next_), c_.end());
    std::rotate(q_.begin(), q_.begin() + static_cast<long>(next_), q_.end());
    next_ = 0;
    const long from = static_cast<long>(t_.size() - std::min(quarter_, t_.size()));
    const std::vector<double> tail_t(t_.begin() + from, t_.end());
    const std::vector<Eigen::Vector3d> tail_c(c_.begin() + from, c_.end());
    const std::vector<Eigen::Quaterniond> tail_q(q_.begin() + from, q_.end());
    const Oscillation fast = DetectOscillation(tail_t, tail_c, tail_q, gap_tolerance, length_scale);
    if (fast.detected) return fast;
    const Oscillation slow = DetectSlowOscillation(t_, c_, q_, gap_tolerance, length_scale);
    return slow.detected ? slow : fast;
  }

 private:
  std::vector<double> t_;
  std::vector<Eigen::Vector3d> c_;
  std::vector<Eigen::Quaterniond> q_;
  size_t capacity_ = 0, quarter_ = 0, next_ = 0;
};

// Watches each step for the pusher's first press after not pressing (or
// at the first step) and measures the impact there (see Impact).
class ImpactWatch {
 public:
  explicit ImpactWatch(const Scene& scene)
      : scene_(scene), peak_(scene.pusher ? PusherPeakRates(*scene.pusher).velocity.norm() : 0) {}

  // Before a step: the object's state and the pusher's velocity at its start.
  void Before(const ContactModel& model, const Eigen::Vector3d& pusher_v) {
    t0_ = model.time();
    c0_ = model.position();
    v0_ = model.velocity();
    w0_ = model.angular_velocity();
    p0_ = model.pusher_position();
    pusher_v_ = pusher_v;
  }

  void After(const ContactModel& model, Impact& worst) {
    if (!scene_.pusher || model.contacts().empty()) return;
    const ContactState& pusher = model.contacts().back();
    const double floor = 1e-9 * model.force_scale();
    const bool onset = pusher.normal_force > floor && !was_pressing_;
    was_pressing_ = pusher.normal_force > floor;
    if (!onset) return;
    // The contact normal (into the object): the pusher's force less its friction.
    const Eigen::Vector3d n =
        (model.pusher_force() - pusher.tangential_force) / pusher.normal_force;
    const double u = n.dot(pusher_v_ - (v0_ + w0_.cross(p0_ - c0_)));
    // Slower than kImpactSpeed of the pusher's top speed: a recorded
    // acceleration's first interval, not an impact that decides a branch.
    if (!(u > kImpactSpeed * std::max(peak_, pusher_v_.norm()))) return;
    const double momentum = scene_.object.mass * u;
    if (momentum <= worst.momentum) return;
    double holding = 0;
    for (size_t i = 0; i < scene_.fingers.size() && i < model.contacts().size(); ++i)
      holding += scene_.fingers[i].mu * model.contacts()[i].normal_force;
    if (scene_.support) holding += scene_.support->mu * scene_.object.mass * scene_.gravity.norm();
    worst.detected = true;
    worst.t = t0_;
    worst.approach_speed = u;
    worst.momentum = momentum;
    worst.holding_force = holding;
    worst.resolving_dt = holding > 0 ? momentum / holding : std::numeric_limits<double>::infinity();
    worst.resolved = model.time() - t0_ <= worst.resolving_dt;
  }

 private:
  const Scene& scene_;
  double peak_ = 0;
  double t0_ = 0;
  Eigen::Vector3d c0_, v0_, w0_, p0_, pusher_v_;
  bool was_pressing_ = false;
};

// Sums each step's SlipSteering over the run (SteeredSlip).
class SteeringWatch {
 public:
  void After(const SlipSteering& step, double dt) {
    friction_ += step.sliding_friction * dt;
    across_ += step.across * dt;
    max_rad_ = std::max(max_rad_, step.max_rad);
    if (step.max_rad > kSteerAngle) steered_s_ += dt;
  }
  SteeredSlip Result() const {
    SteeredSlip out;
    out.share = friction_ > 0 ? across_ / friction_ : 0.0;
    out.max_rad = max_rad_;
    out.steered_s = steered_s_;
    out.detected = out.share > kSteerShare;
    return out;
  }

 private:
  double friction_ = 0, across_ = 0, max_rad_ = 0, steered_s_ = 0;
};

}  // namespace

namespace {

// stop_if_carried: end the run at the step its "auto" inertia turns carried
// (Simulate then runs the scene again carried; the rest would be discarded).
SimulationResult SimulateRun(const Scene& scene, const PusherCommandSource& commands,
                             bool stop_if_carried) {
  const auto start = std::chrono::steady_clock::now();
  SimulationResult result;
  ContactModel model(scene);
  result.model = model.info();
  // Every return goes through finish(): it moves the result out (returned
  // by value from a lambda that captures it, it was copied, every sample
  // and its contact states, once per trial).
  PoseRing poses;
  SteeringWatch steering;
  auto finish = [&] {
    // "auto" inertia may turn carried during the run (model.cpp, CarryOnPush).
    result.model.inertia = model.info().inertia;
    if (result.status == SimulationStatus::kOk) {
      result.oscillation = poses.Detect(model.gap_tolerance(), model.length_scale());
    }
    result.steered_slip = steering.Result();
    result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return std::move(result);
  };
  if (model.status() != SimulationStatus::kOk) {
    result.status = model.status();
    result.error = model.error();
    return finish();
  }
  const double dt = scene.model.dt;
  const double period = 1.0 / kSampleRateHz;
  const long n_samples = static_cast<long>(std::floor(scene.duration * kSampleRateHz + 1e-9)) + 1;
  const long n_steps = std::max(1L, static_cast<long>(std::ceil(scene.duration / dt - 1e-9)));
  result.samples.reserve(static_cast<size_t>(n_samples));
  const Eigen::Vector3d pusher0 = scene.pusher ? scene.pusher->position : Eigen::Vector3d::Zero();
  const Eigen::Vector3d pusher_v =
      scene.pusher ? scene.pusher->motion.velocity : Eigen::Vector3d::Zero();
  const bool closed_loop = commands && scene.pusher;
  Eigen::Vector3d command_v = pusher_v;  // closed loop: the motion in force

  poses.Size(n_steps);
  ImpactWatch impacts(scene);
  long next = 0;  // next sample index
  for (long step = 0; step < n_steps; ++step) {
    const double t0 = model.time();
    const Eigen::Vector3d c0 = model.position();
    const Eigen::Quaterniond q0 = model.orientation();
    // The pusher's velocity at the step's start (a path's first interval,
    // not the step's mean: an acceleration within the step is no impact).
    impacts.Before(model, closed_loop || !scene.pusher
                              ? command_v
                              : PusherTwistOver(*scene.pusher, t0, kImpactProbeDt).velocity);
    const StepReport rep = model.Step();
    ++result.solver.steps;
    result.solver.max_pivots = std::max(result.solver.max_pivots, rep.pivots);
    result.solver.total_pivots += rep.pivots;
    result.solver.quasi_static_solves += rep.quasi_static_solves;
    result.solver.quasi_static_carried += rep.quasi_static_carried;
    if (!rep.ok) {
      result.solver.failures++;
      result.status = SimulationStatus::kSolverFailure;
      result.failed_step = static_cast<int>(step);
      char when[64];
      std::snprintf(when, sizeof when, "step %ld (t = %.6g s): ", step, t0);
      result.error = when + rep.error;
      return finish();
    }
    if (stop_if_carried && model.info().inertia == InertiaModel::kCarried) return finish();
    result.residuals.force_balance =
        std::max(result.residuals.force_balance, rep.residuals.force_balance);
    result.residuals.complementarity =
        std::max(result.residuals.complementarity, rep.residuals.complementarity);
    result.residuals.cone = std::max(result.residuals.cone, rep.residuals.cone);
    poses.Push(model.time(), model.position(), model.orientation());
    impacts.After(model, result.impact);
    steering.After(rep.steering, dt);
    if (result.grasp == GraspStatus::kHeld) {
      result.grasp = model.Grasp(&result.grasp_note);
      if (result.grasp != GraspStatus::kHeld) result.grasp_changed_t = model.time();
    }
    const double t1 = model.time();
    while (next < n_samples) {
      const double ts = static_cast<double>(next) * period;
      if (ts > t1 + 1e-9 * dt && step + 1 < n_steps) break;
      const double s = std::clamp((ts - t0) / dt, 0.0, 1.0);
      TrajectorySample sample;
      sample.t = ts;
      sample.position = c0 + (ts - t0) * model.velocity();
      sample.orientation = q0.slerp(s, model.orientation());
      if (next > 0) {
        sample.velocity = model.velocity();
        sample.angular_velocity = model.angular_velocity();
      }
      sample.pusher_position =
          closed_loop
              ? Eigen::Vector3d(model.pusher_position() - command_v * (t1 - ts))
              : (scene.pusher && scene.pusher->path ? PusherPoseAt(*scene.pusher, ts).position
                                                    : Eigen::Vector3d(pusher0 + pusher_v * ts));
      sample.pusher_force = model.pusher_force();
      sample.contacts = model.contacts();
      result.samples.push_back(std::move(sample));
      ++next;
      if (!closed_loop) continue;
      std::string why;
      const std::optional<PusherMotion> command = commands(result.samples, &why);
      if (!command) {
        result.stopped = why.empty() ? "stopped by the command source" : why;
        return finish();
      }
      if (std::string bad = CheckCommand(scene, result.model, *command); !bad.empty()) {
        result.status = SimulationStatus::kInvalidScene;
        result.error = bad;
        return finish();
      }
      model.SetPusherMotion(*command);
      command_v = command->velocity;
    }
  }
  return finish();
}

}  // namespace

// "auto" inertia that turned carried during a run (model.cpp, CarryOnPush:
// a push that needs the object's momentum) gives the carried model's answer
// from the start, not balanced steps followed by carried ones: those mixed
// the two (the centred edge push started at full speed, dt 0.1 ms: 9
// balanced steps through the impact, then carried, a roll 2.7 % past the
// carried run's and the closed form's). The balanced attempt stops at the
// step it turns; the solver statistics keep its solves and carried step. A closed-loop run is not
// run twice (its commands came from outside): it goes on carried from the step it turned.
SimulationResult Simulate(const Scene& scene, const PusherCommandSource& commands) {
  const bool closed_loop = commands && scene.pusher;
  const bool may_turn = !closed_loop && scene.model.inertia == InertiaModel::kAuto &&
                        InertiaOf(scene) == InertiaModel::kQuasiStatic;
  SimulationResult first = SimulateRun(scene, commands, may_turn);
  if (!may_turn || first.model.inertia != InertiaModel::kCarried) return first;
  Scene carried = scene;
  carried.model.inertia = InertiaModel::kCarried;
  SimulationResult again = SimulateRun(carried, commands, false);
  again.solver.quasi_static_solves += first.solver.quasi_static_solves;
  again.solver.quasi_static_carried += first.solver.quasi_static_carried;
  again.wall_s += first.wall_s;
  return again;
}

}  // namespace arena::mechanics
