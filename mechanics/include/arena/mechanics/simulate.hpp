// Simulate a scene: the object's motion and every contact force over time,
// sampled at 250 Hz. Model: model.hpp; scene format: docs/scene.md.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arena/mechanics/scene.hpp"

namespace arena::mechanics {

inline constexpr double kSampleRateHz = 250.0;

enum class ContactMode { kStick, kSlide, kSeparate };
const char* ToString(ContactMode mode);

// One finger or the pusher, summed over its constituent points.
struct ContactState {
  double normal_force = 0;                                     // N, on the object
  Eigen::Vector3d tangential_force = Eigen::Vector3d::Zero();  // N, on the object, gripper frame
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();            // N m about the contact position
  ContactMode mode = ContactMode::kSeparate;
  // Whether it touches the object (a constituent point within the gap
  // tolerance of the surface, or pressing), how many of its constituent
  // points do, and where: the force-weighted centre of those points in the
  // object frame (m; where the primitive is when it touches nothing).
  bool touching = false;
  int touching_points = 0;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
};

struct TrajectorySample {
  double t = 0;                                        // s
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // object, gripper frame (m)
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();          // m/s
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s
  Eigen::Vector3d pusher_position = Eigen::Vector3d::Zero();   // pusher contact point (m)
  Eigen::Vector3d pusher_force = Eigen::Vector3d::Zero();      // on the object (N)
  std::vector<ContactState> contacts;  // fingers in scene order, then pusher
};

// Worst over all steps, relative to the scene's force scale.
struct Residuals {
  double force_balance = 0;
  double complementarity = 0;
  double cone = 0;
};

struct SolverStatistics {
  int steps = 0;
  int max_pivots = 0;
  long total_pivots = 0;
  int failures = 0;
  // Quasi-static (model.inertia): the solves repeated to balance the forces,
  // summed over the run, and the steps that found no balance and carried the
  // momentum instead (those steps are quasi-dynamic, not quasi-static).
  long quasi_static_solves = 0;
  int quasi_static_carried = 0;
};

// The statistics as one JSON object (steps, max_pivots, failures,
// quasi_static_solves, quasi_static_carried): the one rendering every
// output, stored detail and export uses, so none of them drops a field.
std::string SolverStatisticsJson(const SolverStatistics& solver);

struct ModelInfo {
  int dof = 6;  // 3 when the planar reduction is in use
  int facets = 0;
  int points = 0;
  double dt = 0;
  int unknowns = 0;  // LCP size of one step
  // The inertia model the steps used (model.inertia, "auto" decided).
  InertiaModel inertia = InertiaModel::kCarried;
};

enum class SimulationStatus {
  kOk,
  kSolverFailure,  // the complementarity solver found no solution (reason says why)
  kInvalidScene,   // e.g. reduce=planar on a scene that is not planar
};
const char* ToString(SimulationStatus status);

// Whether the predicted motion stayed within the grasp it started from.
// kHeld: every finger touches the object throughout. kLost (tracked
// contacts): a finger lost contact, e.g. its pad passed the object's edge,
// a physical prediction of a drop. kLeftGeometry (fixed contacts): a
// finger's frozen contact point is no longer on the object's surface, so
// the model ran outside its validity; not a normal prediction.
enum class GraspStatus { kHeld, kLost, kLeftGeometry };
const char* ToString(GraspStatus status);

// Whether a run ends in an undamped oscillation, so that its final pose is
// one phase of it rather than a settled answer (e.g. an object rocking about
// the grip axis with its momentum carried). Detected from the object's pose
// at every step over the last quarter of the run (at most
// kOscillationWindowSteps steps): each coordinate of the centre of mass and
// of the rotation (vector, from the window's middle pose) less its
// least-squares quadratic over the window (the slow path) leaves a
// residual; a coordinate oscillates when that residual's amplitude (√2 ×
// its RMS, a sinusoid's amplitude) exceeds the model's contact resolution
// (its gap tolerance, 1e-4 of the object's extent, for a position; that
// over the extent, 1e-4 rad, for an angle) and it swings across ± half of
// that at least kOscillationCrossings times (3 periods). Frequency: the
// crossings per second over 2.
inline constexpr int kOscillationWindowSteps = 4096;
inline constexpr int kOscillationCrossings = 6;
struct Oscillation {
  bool detected = false;
  double amplitude_m = 0;    // largest over the centre of mass's x, y, z (m)
  double amplitude_rad = 0;  // largest over the rotation vector's x, y, z (rad)
  double frequency_hz = 0;   // of the coordinate farthest above its threshold
  double window_s = 0;       // the end of the run analysed (s)
  // The periods of that coordinate's swing the window held (0 when none
  // detected): below 3 only for a slow mode (DetectSlowOscillation).
  double periods = 0;
};
// The oscillation as one JSON object (detected, amplitude_m, amplitude_rad,
// frequency_hz, window_s, periods): the one rendering every output, stored
// detail and export uses.
std::string OscillationJson(const Oscillation& oscillation);
// The analysis above on one run's step poses (t ascending; at least 16);
// gap_tolerance (m) and length_scale (m) as ContactModel gives them.
Oscillation DetectOscillation(const std::vector<double>& t, const std::vector<Eigen::Vector3d>& c,
                              const std::vector<Eigen::Quaterniond>& q, double gap_tolerance,
                              double length_scale);

// A mode too slow for the crossings above (fewer than 3 periods in the last
// quarter, e.g. a pitch at 4 Hz in a 0.2 s push), judged over the run after
// its first tenth (at most kOscillationWindowSteps steps): a coordinate
// whose least-squares quadratic leaves a residual above its threshold (as
// above) is a mode when its acceleration (second differences of the step
// poses) is, to a fraction kSlowModeFit of its variance, a restoring force
// about a slow path: y'' = a0 + a1 τ + a2 τ² − ω² y with ω² > 0, the
// equation of an undamped oscillation about a quadratic path. A smooth path
// (a polynomial, or one that bends where a contact starts to slip) leaves
// an acceleration no such force explains; a path that is itself a slow arc
// (a centre of mass turning about a pad) does, so at least
// kSlowModeMinPeriods of the fitted period must fit in the window. The
// amplitude is √2 × the RMS of y less that path; the frequency ω / 2π
// (from the discrete second difference).
inline constexpr double kSlowModeFit = 0.9;
inline constexpr double kSlowModeMinPeriods = 0.5;
Oscillation DetectSlowOscillation(const std::vector<double>& t,
                                  const std::vector<Eigen::Vector3d>& c,
                                  const std::vector<Eigen::Quaterniond>& q, double gap_tolerance,
                                  double length_scale);

// Whether the pusher meets the object at speed (an impact: a pusher that
// starts at full speed on it, or reaches it moving) in a step too long to
// resolve it. The object takes up a momentum p = m u (u: the pusher's
// approach speed along its force, at the step it first presses) while what
// holds it (the fingers' friction Σ μ N, a support's μ m g) takes up only
// its force times dt per step: below dt = p / that force (resolving_dt)
// the impact is resolved (the answer of the limit dt → 0); above it the
// first step shares the impact with what holds the object, and a run near a
// stick/slide threshold can take another branch (docs/scene.md, `dt`).
// u is the approach along the contact normal of the pusher's velocity at
// the step's start (over kImpactProbeDt: a recorded path's first interval)
// against the object's. Detected at approach speeds above kImpactSpeed of
// the pusher's top speed (slower: a recorded acceleration's first interval,
// which decides no branch); the largest impact of the run (by momentum) is
// kept.
inline constexpr double kImpactSpeed = 0.5;
inline constexpr double kImpactProbeDt = 1e-6;
struct Impact {
  bool detected = false;
  double t = 0;               // s: the start of the step it happened in
  double approach_speed = 0;  // m/s
  double momentum = 0;        // N s: object mass × approach speed
  double holding_force = 0;   // N: Σ μ N of the fingers, + μ m g of a support
  double resolving_dt = 0;    // s: momentum / holding_force (infinite: nothing holds)
  bool resolved = true;       // dt <= resolving_dt
};
// The impact as one JSON object (detected, t, approach_speed, momentum,
// holding_force, resolving_dt (null when infinite), resolved).
std::string ImpactJson(const Impact& impact);

// Whether the friction cones steered the run's slip (issue 31). A
// polyhedral cone's friction opposes a slip only along one of its edges; a
// slip that falls between two edges meets a friction partly across it,
// which turns the slip towards an edge, so where a contact slides in a free
// direction the answer depends on `facets` (at first order: the tilted push
// through the grip axis turns 56 % too far at 8 facets, 3 % at 64) while the
// circular cone's friction has no part across the slip. Over the run's
// steps (the accepted answer of each, see SlipSteering): the share of the
// sliding points' friction impulse that acts across their slip, the largest
// angle between a friction and its slip's opposite, and how long some point
// slid with its friction more than kSteerAngle off that opposite. Detected
// when the share exceeds kSteerShare: `"cone": "aligned"` (the friction of a
// sliding point opposing its slip) is then the model that scene needs.
inline constexpr double kSteerAngle = 1e-2;
inline constexpr double kSteerShare = 1e-2;
struct SteeredSlip {
  bool detected = false;
  double share = 0;      // ∫ Σ |f_t × û| dt / ∫ Σ |f_t| dt (0 when nothing slid)
  double max_rad = 0;    // rad
  double steered_s = 0;  // s
};
// The steered slip as one JSON object (detected, share, max_rad, steered_s).
std::string SteeredSlipJson(const SteeredSlip& steered);

struct SimulationResult {
  SimulationStatus status = SimulationStatus::kOk;
  std::string error;  // empty when ok; names the step and reason otherwise
  int failed_step = -1;
  ModelInfo model;
  std::vector<TrajectorySample> samples;  // 250 Hz from t = 0 (up to the failure, if any)
  Residuals residuals;
  SolverStatistics solver;
  double wall_s = 0;
  // Closed loop: why the command source stopped the run early (status stays
  // kOk, samples end there); empty when it ran to the scene's duration.
  std::string stopped;
  GraspStatus grasp = GraspStatus::kHeld;
  double grasp_changed_t = -1;  // s: when it first stopped being kHeld (-1: never)
  std::string grasp_note;       // which finger, and why
  // Whether the run ended in an undamped oscillation (its amplitude and
  // frequency): the final pose is then a phase of it (see Oscillation).
  Oscillation oscillation;
  // The run's largest pusher impact and whether dt resolved it (see Impact).
  Impact impact;
  // Whether the friction cones steered the slip (see SteeredSlip).
  SteeredSlip steered_slip;
};

// The flags a stored result carries beside its numbers, as one JSON object:
// "oscillation" when one was detected, "impact" when one was detected that
// dt did not resolve, "steered_slip" when the cones steered it; {} when
// none. The one rendering every stored
// detail (truths, predictions, closed-loop trials) uses.
std::string RunFlagsJson(const SimulationResult& result);
// Whether a stored detail (a JSON object RunFlagsJson's flags were merged
// into) carries the flag `flag` ("oscillation", "impact", "steered_slip");
// false for text that is not a JSON object.
bool HasRunFlag(const std::string& detail_json, const char* flag);

// Never throws for a scene that passed ValidateScene(); a step the solver
// cannot solve ends the run with status kSolverFailure. Never returns NaN.
// A closed-loop scene (pusher.controller set) runs with its pusher at rest:
// use the overload below to give it commands.
SimulationResult Simulate(const Scene& scene);

// Closed loop: the pusher's motion commanded sample by sample. Called once
// per sample, in order, with every sample so far (the newest last); the
// motion it returns moves the pusher from the next step on. It returns
// nullopt to stop the run (why in *stop_reason, copied to
// SimulationResult::stopped). A command that leaves the plane of a planar
// model, or turns the pusher differently from the scene, ends the run with
// kInvalidScene. The same commands in the same order give the same result,
// bit for bit: the replay of a closed-loop trial is this with the recorded
// commands.
using PusherCommandSource = std::function<std::optional<PusherMotion>(
    const std::vector<TrajectorySample>& samples, std::string* stop_reason)>;
SimulationResult Simulate(const Scene& scene, const PusherCommandSource& commands);

}  // namespace arena::mechanics
