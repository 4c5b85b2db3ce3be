// A predictor: a named model of contact dynamics with its fidelity knobs.
// `arena evaluate --predictors arena,mujoco` replays the same done trials
// through every predictor's grid of settings; the campaign's `prediction`
// may name one. A predictor turns a scene into a mechanics::SimulationResult
// (the model's trajectory at 250 Hz, status, residuals) so that one scorer
// judges them all.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

// One point of a predictor's grid.
struct PredictorSetting {
  std::string key;         // unique within the predictor: "g8_k3_dt0.004_auto"
  std::string knobs_json;  // the knobs as a JSON object (stored as model_json)
  double step = 0;         // the step size (s): the knob the curves vary
  int refinement = 0;      // larger = finer (the finest setting is the reference)
};

class Predictor {
 public:
  virtual ~Predictor() = default;
  virtual const std::string& name() const = 0;  // "arena", "mujoco"
  virtual const std::vector<PredictorSetting>& settings() const = 0;
  // Runs `scene` (its own `model` ignored) at settings()[setting]. Never
  // throws: a setting the scene cannot take is kInvalidScene, a solver that
  // gives up kSolverFailure.
  virtual mechanics::SimulationResult Run(const mechanics::Scene& scene,
                                          std::size_t setting) const = 0;
  // Closed loop (issue 19): the same with the pusher's motion taken from
  // `commands` after every sample (the replay of a closed-loop trial's
  // recorded commands). A predictor that cannot step with commanded pusher
  // velocities returns kInvalidScene with the reason.
  virtual mechanics::SimulationResult RunClosedLoop(
      const mechanics::Scene& scene, std::size_t setting,
      const mechanics::PusherCommandSource& commands) const = 0;
  // Settings that build the same model for `scene` share this key (arena:
  // constituent points do not matter to a scene of point contacts), so an
  // evaluation runs the model once and gives both the result and its time.
  virtual std::string EffectiveKey(const mechanics::Scene& scene, std::size_t setting) const {
    (void)scene;
    return settings().at(setting).key;
  }
};

// arena's own model (mechanics) at each of `grid`'s settings.
// @throws std::invalid_argument for an empty grid or a repeated setting.
std::unique_ptr<Predictor> MakeArenaPredictor(std::vector<mechanics::ModelOptions> grid);

// MuJoCo's knobs: the cross product of the lists (timestep outermost); the
// rest of simulators::MujocoSettings stays at its converged defaults.
struct MujocoGrid {
  std::vector<double> timestep{0.004, 0.002, 0.001, 0.0005};  // s, (0, 0.01]
  std::vector<std::string> cone{"elliptic"};                  // elliptic | pyramidal
  std::vector<int> noslip{0};  // noslip iterations, >= 0 (the simulator's default: off)
  // Contact softness (the simulator's defaults: [0.002, 1] and
  // [0.9, 0.95, 0.001, 0.5, 2]). Physics, not refinement: a setting's key
  // names them only when they differ from the defaults.
  std::vector<std::array<double, 2>> solref{{0.002, 1.0}};  // [timeconst s, damping ratio]
  std::vector<std::array<double, 5>> solimp{
      {0.9, 0.95, 0.001, 0.5, 2.0}};  // [dmin, dmax, width, mid, power]
};

// A MuJoCo setting's model key: "mujoco_ts0.001_elliptic_ns0", with
// "_sr0.005:1" / "_si..." appended only where solref / solimp differ from
// the simulator's defaults (so the keys of the default settings never
// change). `knobs` as MakeSimulator("mujoco", ...) reads them; absent knobs
// are the defaults.
std::string MujocoSettingKey(const nlohmann::json& knobs);

// MuJoCo 2.2 (simulators/, the same engine and scene builder as the
// `mujoco` cell backend) at each of `grid`'s settings.
// @throws std::invalid_argument naming the list for an empty or repeated
//   list or a value the simulator refuses.
std::unique_ptr<Predictor> MakeMujocoPredictor(const MujocoGrid& grid);

// The index of the finest setting: the largest `refinement`, ties to the first.
std::size_t FinestSetting(const Predictor& predictor);

}  // namespace arena::assessment
