// Sensitivity of a push's predicted outcome to its inputs, and whether the
// push is unstable (docs/sensitivity.md states the criterion; `arena
// sensitivity SCENE.json` prints it).
//
// Parameters are the inputs the prehensile-pushing seeds name -- contact
// positions and normals (kinematics), grip force, pusher velocity and angular
// velocity -- and friction coefficients and mass. Each has a unit, a nominal
// value, a reference scale (for normalising, default steps and tolerances)
// and a finite-difference step. Offsets (contact positions along the contact
// plane, normal tilts) have nominal 0.
//
// Derivatives: central differences at steps h and h/2 (forward ones at a
// bound such as mu = 0). They are reported when the two agree (relative
// `agreement`, compared on the normalised scale) and the discrete outcome
// (contact mode sequences, grasp kept) is the same at every probe; otherwise
// the parameter is "not differentiable here" and the note says why.
//
// Instability: every parameter with a tolerance delta (the cell's noise
// levels, or a relative --tolerance) is probed at +-delta, +-2 delta, ...;
// the push is unstable when within +-delta a contact's mode sequence or
// the grasp changes, a model run fails, or a quantity moves by more than
// `linear_multiple` times its linearised estimate |dY/dp| delta (plus 1 % of
// the quantity's reference scale, so that nothing near zero is flagged for
// rounding), or jumps (is discontinuous) within one finite-difference step
// smaller than the tolerance. Magnitudes (rotation, displacement) at zero are
// judged through their signed components (a norm has a kink there). Where the
// discrete outcome changes the boundary is located by
// bisection; the nearest boundary (in tolerances) is reported with its
// parameter, also when it lies beyond the tolerance (then not flagged).
//
// Thread safety: the functions are reentrant; model runs go to `threads`
// worker threads, so the SimulateFn must be callable concurrently.
#pragma once

#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "arena/assessment/noise.hpp"
#include "arena/assessment/outcome.hpp"
#include "arena/mechanics/scene.hpp"

namespace arena::assessment {

enum class ParameterKind {
  kGripForce,
  kMass,
  kMu,                     // one contact's friction coefficient
  kFingersMu,              // every finger's mu moved together (nominal: their mean)
  kMuScale,                // every mu scaled together (a cell's friction variability)
  kPushSpeed,              // |pusher velocity|, direction kept
  kPusherVelocity,         // one gripper-frame component (m/s)
  kPusherAngularVelocity,  // one component (rad/s)
  kContactPosition,        // offset along the contact plane's tangent t1 or t2 (m)
  kContactNormal,          // tilt of the pusher's normal towards t1 or t2 (rad)
  kFingerNormals,          // every finger normal tilted together (the grasp axis; rad):
                           // the model needs opposing fingers' normals to cancel
};

struct Parameter {
  std::string name;   // "grip_force", "left.mu", "fingers.mu", "pusher.velocity.z",
                      // "right.position.t1", "fingers.normal.t1", "pusher.normal.t2", ...
  std::string group;  // "grip_force", "mass", "friction", "velocity", "angular_velocity",
                      // "position", "normal"
  std::string unit;   // "N", "kg", "1", "m/s", "rad/s", "m", "rad"
  ParameterKind kind = ParameterKind::kGripForce;
  int contact = -1;  // fingers index; fingers.size() is the pusher
  int axis = 0;      // x, y, z for velocities; t1, t2 for positions and normals
  double nominal = 0;
  double scale = 1;  // > 0: |nominal| or a reference magnitude when that is ~0
  double step = 0;   // finite-difference step h (> 0)
  double lower = -std::numeric_limits<double>::infinity();  // smallest admissible value
};

// The unit human output shows a value in SI `si_unit` in: mm for m, deg for
// rad, and so per second; N, kg and "1" as they are. JSON stays SI.
struct HumanUnit {
  std::string unit;
  double factor = 1;  // human value = SI value * factor
};
HumanUnit HumanUnitOf(const std::string& si_unit);

// Every parameter the scene has (no pusher: no pusher parameters).
std::vector<Parameter> SceneParameters(const mechanics::Scene& scene);

// The parameters matching any filter: a name ("grip_force", "left.mu"), a
// group ("friction", "position", ...), "kinematics" (positions and normals)
// or a contact's name ("left": all of left.*). Empty filters: all.
// @throws std::invalid_argument naming a filter that matches nothing.
std::vector<Parameter> SelectParameters(const std::vector<Parameter>& all,
                                        const std::vector<std::string>& filters);

// The scene with `parameter` moved by `delta` (its unit) from its nominal.
// @throws mechanics::SceneError when the result is not a valid scene (e.g.
//   a contact pushed off its face).
mechanics::Scene PerturbScene(const mechanics::Scene& scene, const Parameter& parameter,
                              double delta);

// One quantity's derivative with respect to one parameter.
struct Derivative {
  double value = 0;       // dY/dp, unit of Y per unit of p
  double normalised = 0;  // % change of Y (of its reference scale) per 1 % of p's scale
  bool agrees = true;     // the two step sizes agreed
};

struct ParameterSensitivity {
  Parameter parameter;
  bool differentiable = true;
  std::string note;  // why not ("" when differentiable)
  std::array<Derivative, kQuantityCount> derivatives{};
  double score = 0;  // max |normalised| over quantities: the ranking key
  // A jump: the quantity changes about as much over +-h/2 as over +-h (a
  // smooth one changes half as much) by more than 1 % of its scale -- the
  // outcome is discontinuous at the nominal. Empty when none.
  std::string jump_quantity;
  double jump = 0;  // |Y(p+h) - Y(p-h)| of that quantity, its unit
};

struct ParameterStability {
  std::string parameter;
  double tolerance = 0;  // delta, in the parameter's unit
  std::string source;    // where delta came from ("--tolerance 2%", "friction_variability x2")
  bool flips = false;    // the discrete outcome changes within +-delta
  bool nonlinear = false;
  std::string nonlinear_quantity;  // the worst quantity when nonlinear
  double linear_ratio = 0;         // worst |dY| / (|dY/dp| delta + 1 % scale) within +-delta
  std::optional<double> boundary;  // signed offset from nominal of the nearest change found
  std::string change;              // what changes there
  bool failed = false;             // a model run failed within +-delta
};

struct Boundary {
  std::string parameter;
  double offset = 0;      // signed, parameter's unit
  double tolerances = 0;  // |offset| / delta
  std::string change;
};

struct Stability {
  bool checked = false;
  bool unstable = false;
  std::vector<std::string> reasons;  // one sentence per reason
  std::vector<ParameterStability> parameters;
  std::optional<Boundary> nearest;
};

struct StabilityOptions {
  // Relative tolerance for parameters no other source covers: delta =
  // relative_tolerance * parameter scale (0: such parameters are not probed).
  double relative_tolerance = 0.02;
  std::map<std::string, double> tolerances;  // absolute, by parameter name (wins)
  // Cell noise: mu_scale, push_speed and pusher.velocity.* get noise_sigmas * std.
  ActuationNoise noise;
  double noise_sigmas = 2;
  double linear_multiple = 3;  // > 1
  int search_levels = 3;       // probes at delta * 2^(0..levels-1)
  int bisections = 6;
};

struct SensitivityOptions {
  std::vector<std::string> params;  // filters (SelectParameters); empty: all
  double step_scale = 1;            // multiplies every parameter's default step
  double agreement = 0.1;           // relative agreement of the two step sizes
  bool check_stability = true;
  StabilityOptions stability;
  int threads = 0;      // 0: one per core
  SimulateFn simulate;  // empty: DefaultSimulate()
  // Called from worker threads (serialised): model runs done, planned so far.
  std::function<void(long, long)> progress;
};

struct SensitivityReport {
  Outcome nominal;
  std::array<double, kQuantityCount> scales{};   // each quantity's reference scale
  std::vector<ParameterSensitivity> parameters;  // ranked by score, highest first
  Stability stability;
  long model_runs = 0;
  double wall_s = 0;
  int threads = 1;
};

// @throws std::invalid_argument for bad options or filters.
// The nominal run failing is not an exception: report.nominal.ok is false
// and nothing else is filled in.
SensitivityReport AnalyseScene(const mechanics::Scene& scene, const SensitivityOptions& options);

nlohmann::json ToJson(const SensitivityReport& report, const mechanics::Scene& scene);

// The tolerance of each parameter under `options` (0: not probed), and why.
std::pair<double, std::string> ToleranceFor(const Parameter& p, const StabilityOptions& options);

// Runs fn(0..n-1) on up to `threads` threads (0: one per core).
void RunParallel(long n, int threads, const std::function<void(long)>& fn);
int ThreadCount(int requested);

}  // namespace arena::assessment
