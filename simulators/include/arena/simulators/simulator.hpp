// Simulators: one interface for anything that turns a scene into a
// trajectory. Cell backends use a simulator as their physics (the truth of a
// simulated cell); predictors use one to predict a trial. Both get the same
// output type, mechanics::SimulationResult (250 Hz TrajectorySamples), so a
// prediction and a ground truth compare sample by sample.
//
//   name      what it is                                   truth it gives
//   arena     arena's own contact model (mechanics::Simulate)
//             at the settings below                        self-consistency only
//   mujoco    MuJoCo 2.2 (soft contact, elliptic cones)    independent engine
//
// Settings are plain structs with a default for every field; MakeSimulator()
// also reads them from JSON ({"timestep": 0.0005, ...}) so a command-line
// flag or a campaign can carry them. Simulate() is const and thread-safe:
// every call builds its own model and data.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "arena/errors/error.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::simulators {

// A name or setting a simulator does not know, or a value out of range.
// what() is "<field>: <reason>", e.g. "mujoco.timestep: must be in (0, 0.01]".
class SimulatorError : public Error {
 public:
  SimulatorError(std::string field, const std::string& reason)
      : Error(ErrorCategory::kBadInput, field + ": " + reason), field_(std::move(field)) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

// What kind of truth a simulator's trajectory is when a cell serves it.
enum class TruthKind {
  kSelfConsistency,  // arena's own model: an "error" against it is self-consistency
  kIndependent,      // another engine: an error against it says how usable the model is
};
const char* ToString(TruthKind kind);

// A scene built once and run again with other physical parameters: every
// finger's and the pusher's friction coefficient, the grip force, the
// object's mass (with its inertia scaled alike). Calibration evaluates the
// same trial scenes many times with only these changed; an engine whose
// model takes long to build (MuJoCo's XML compiler) patches its built model
// instead. Any other difference in `variant` (geometry, pose, motion,
// duration, an inertia not proportional to the mass) is run from scratch,
// so the answer is always the variant's own. Not thread-safe: one caller at
// a time per PreparedScene (each trial has its own).
class PreparedScene {
 public:
  virtual ~PreparedScene() = default;
  virtual mechanics::SimulationResult Simulate(const mechanics::Scene& variant) = 0;
  // Runs that reused the built model / that had to build a new one.
  virtual long reused() const = 0;
  virtual long rebuilt() const = 0;
};

class Simulator {
 public:
  virtual ~Simulator() = default;
  // "arena", "mujoco", ...
  virtual std::string name() const = 0;
  virtual TruthKind truth() const = 0;
  // The settings in force, as canonical JSON (stored with every trial).
  virtual std::string settings_json() const = 0;
  // Never throws for a scene that passed mechanics::ValidateScene(); a scene
  // the simulator cannot build or step ends with status kInvalidScene or
  // kSolverFailure and a reason. Never returns NaN samples.
  virtual mechanics::SimulationResult Simulate(const mechanics::Scene& scene) const = 0;
  // Why this simulator cannot run the scene at all ("" = it can), e.g. a
  // shape it does not model. Cheap; a cell refuses such a scene up front.
  virtual std::string CheckScene(const mechanics::Scene& scene) const = 0;
  // `scene` prepared for repeated runs with other friction, grip force and
  // mass (PreparedScene). The default simulates every variant afresh.
  virtual std::unique_ptr<PreparedScene> Prepare(const mechanics::Scene& scene) const;
  // Closed loop (issue 19): the scene with its pusher motion commanded after
  // every sample (mechanics::Simulate(scene, commands)). Only a simulator
  // that steps with commanded pusher velocities can (closed_loop() true:
  // `arena`); the others end at once with kInvalidScene and say so.
  virtual bool closed_loop() const { return false; }
  virtual mechanics::SimulationResult SimulateClosedLoop(
      const mechanics::Scene& scene, const mechanics::PusherCommandSource& commands) const {
    (void)scene;
    (void)commands;
    mechanics::SimulationResult r;
    r.status = mechanics::SimulationStatus::kInvalidScene;
    r.error = "the " + name() + " simulator cannot run closed-loop scenes";
    return r;
  }
};

// ---- arena: the contact model (mechanics) -------------------------------------------------

struct ArenaSettings {
  int facets = 0;  // friction-cone edges (>= 3); 0 = the scene's own model.facets
  int points = 0;  // constituent points per line/patch (>= 1); 0 = the scene's own
  double dt = 0;   // time step (s, > 0); 0 = the scene's own
  // true: a scene asking for finer settings keeps its own (a cell's truth is
  // never coarser than the scene asked for); false: these settings exactly
  // (a predictor's).
  bool at_least = false;
};
std::unique_ptr<Simulator> MakeArenaSimulator(const ArenaSettings& settings);

// ---- mujoco: MuJoCo 2.2 ------------------------------------------------------------------

// How line and patch pads are shaped (a point is always one sphere).
enum class PadShapes {
  kSpheres,  // a line: 5 spheres along it; a patch: 6 on the 2R/3 ring (default)
  kShapes,   // a line: one capsule; a patch: one thin box (MuJoCo's own colliders)
};

// Defaults are the converged ones (simulators/README.md: convergence study).
struct MujocoSettings {
  double timestep = 0.0005;         // s, (0, 0.01]
  bool elliptic = true;             // elliptic friction cones (pyramidal: false)
  double solref_timeconst = 0.002;  // s, contact stiffness time constant (clamped to 2·timestep)
  double solref_damping = 1.0;      // damping ratio
  double solimp[5] = {0.9, 0.95, 0.001, 0.5, 2};  // impedance (dmin, dmax, width m, mid, power)
  double impratio = 30;                           // frictional-to-normal impedance ratio, >= 1
  // Post-solve no-slip iterations, >= 0 (0 = off). Off by default: with
  // fingers sliding it made the truth depend on the timestep (0.26 mm
  // between 0.5 and 0.125 ms); impratio 30 keeps a held object's creep
  // to ~0.04 mm/s instead (simulators/README.md, "Default settings").
  int noslip_iterations = 0;
  double tolerance = 1e-10;      // Newton solver tolerance
  int iterations = 100;          // solver iterations
  double object_damping = 0.01;  // free-joint damping (N s/m, N m s/rad): a quasi-static truth
  // kg, each finger pad body. 0.02: at 0.05 the free fingers' soft contacts
  // chattered and the canonical grasp drifted 0.26 mm along its grip axis in
  // 0.2 s (bench/README.md, the extremes per simulator).
  double finger_mass = 0.02;
  // Slip speed (m/s) above which a touching contact counts as sliding.
  double slip_speed = 1e-4;
  // Spheres by default: capsules and boxes converged worse or equal on the
  // pivot study (simulators/README.md, "The MuJoCo scene").
  PadShapes pads = PadShapes::kSpheres;
  // Contact forces, torques and modes of a 250 Hz sample: true = over the
  // sample's interval (the impulse of its steps / 4 ms, as a force sensor
  // filtered for 250 Hz reports them and as arena's model steps them);
  // false = at the sample's instant. A sliding soft contact makes a finger
  // chatter on and off the face between steps, so an instant says little.
  bool interval_forces = true;
  // Pad sphere radius and contact margin (m): contacts are found within the
  // margin and act from touch (gap = margin). Scaled to the scene with
  // scale_to_scene.
  double pad_radius = 0.001;
  double contact_margin = 0.001;
  // true: the pads, margin and solimp width shrink with a small object, the
  // finger mass with a light one, and the contact impedance rises with the
  // load (simulators/README.md, "Scaled to the scene"), so the soft contact
  // stays small against the scene; a scene like the canonical one (0.2 kg,
  // 3 cm and more, 10 N) keeps these settings exactly. false: as set.
  bool scale_to_scene = true;
};
std::unique_ptr<Simulator> MakeMujocoSimulator(const MujocoSettings& settings);

// Compiled MuJoCo models kept for reuse. Building one (parsing, compiling,
// mj_makeData) costs a few ms; an evaluation runs every
// setting of the mujoco predictor on one scene in a row, and settings that
// differ only in <option> (timestep, cone, impratio, noslip_iterations,
// tolerance, iterations) share one compiled model and its data: the options
// are written into the model and the data reset before each run, which gives
// the same trajectory as a fresh build (tests/simulators). At most `models`
// idle models are kept (each holds its stack), the least recently used go.
class MujocoModelCache;
std::shared_ptr<MujocoModelCache> MakeMujocoModelCache(std::size_t models);
// A mujoco simulator drawing its models from `cache` (shared by simulators
// and threads; null: a fresh build per run, as MakeMujocoSimulator).
std::unique_ptr<Simulator> MakeMujocoSimulator(const MujocoSettings& settings,
                                               std::shared_ptr<MujocoModelCache> cache);

// The MJCF text the mujoco simulator builds for a scene (for inspection,
// `arena simulate --engine mujoco --mjcf`, and tests).
// @throws SimulatorError when the scene cannot be expressed (e.g. an unknown shape).
std::string MujocoModelXml(const mechanics::Scene& scene, const MujocoSettings& settings);

// ---- by name ------------------------------------------------------------------------------

// "arena" and "mujoco".
std::vector<std::string> SimulatorNames();

// settings_json: an object of the simulator's settings ("" or "{}" = defaults),
// e.g. {"timestep": 0.001, "noslip_iterations": 0} for mujoco,
// {"facets": 16, "points": 5, "dt": 0.002, "at_least": true} for arena.
// @throws SimulatorError naming the unknown simulator or the bad setting.
std::unique_ptr<Simulator> MakeSimulator(std::string_view name,
                                         std::string_view settings_json = "");
// The same; a mujoco simulator draws its models from `cache` (see above).
std::unique_ptr<Simulator> MakeSimulator(std::string_view name, std::string_view settings_json,
                                         std::shared_ptr<MujocoModelCache> cache);

}  // namespace arena::simulators
