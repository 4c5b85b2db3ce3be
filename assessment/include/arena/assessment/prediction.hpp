// Predicting a trial: the campaign's model settings applied to the trial's
// scene, the model run, and the result scored against the ground truth.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "arena/db/sample.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

// What became of one prediction is a db::PredictionStatus (ok, diverged:
// ran but left the grasp or blew up, solver_failure: the solver gave up,
// invalid_scene: the setting does not fit the scene, error: the trial could
// not be loaded or scored). The status a simulation's status makes:
db::PredictionStatus StatusOf(mechanics::SimulationStatus status);

// Overrides the scene's `model` with the settings present in `model`
// (facets, points, dt, reduce; any may be absent; null = none).
// @throws mechanics::SceneError naming "model.<field>" for a bad setting.
mechanics::Scene ApplyModelSettings(const mechanics::Scene& scene, const nlohmann::json& model);

// "g8_k3_dt0.004_auto": the fidelity label predictions are stored under.
std::string ModelKey(const mechanics::ModelOptions& model);
// {"facets", "points", "dt", "reduce", "contacts", "inertia"} as JSON text: what an
// arena prediction is stored with (db::Prediction::model_json).
std::string ModelSettingsJson(const mechanics::ModelOptions& model);

// Why a predicted trajectory cannot be a prediction of a held object, or
// nothing. It diverged when a sample is not finite, or the object moved
// farther from its start than the pusher travelled plus the object's
// largest extent, or turned more than 90° beyond what the pusher's own
// rotation explains; it left the grasp when every finger separated over the last quarter
// of the trajectory while the truth still held the object (truth may be empty: then only
// the first checks apply).
std::optional<std::string> DivergenceReason(
    const mechanics::Scene& scene, const std::vector<mechanics::TrajectorySample>& predicted,
    const std::vector<mechanics::TrajectorySample>& truth);

// Scores a simulation of `scene` against `truth` into a stored prediction
// (status, errors, residuals and solver statistics in detail_json); never
// throws. model_key, model_json and wall_s are the caller's to set.
db::Prediction ScoreSimulation(const mechanics::Scene& scene,
                               const mechanics::SimulationResult& result,
                               const std::vector<mechanics::TrajectorySample>& truth);

// Runs the model on `scene` and scores it against `truth`; never throws.
// A solver failure is a prediction with status "solver_failure" (experiment
// data, not an error), an invalid scene one with "invalid_scene", a run
// that left the grasp or diverged one with "diverged" (errors still filled).
db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth);

// The same with the campaign's `prediction` object: "predictor": "mujoco"
// runs MuJoCo (simulators/) with the object's knobs (timestep, cone,
// noslip_iterations); anything else is arena's model on `scene` (whose
// model the caller already set with ApplyModelSettings). Never throws.
db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth,
                            const nlohmann::json& prediction);

// Closed loop (issue 19): the pusher commands a closed-loop trial applied,
// indexed by the sample they answered (db::ClosedLoopCommand.commanded).
using RecordedCommands = std::vector<mechanics::PusherMotion>;
RecordedCommands CommandsOf(const db::ClosedLoopRun& run);
// A command source that replays `commands` open-loop: command k moves the
// pusher from the step after sample k, exactly as on the cell; the run stops
// where the recording ends. `commands` must outlive the source.
mechanics::PusherCommandSource ReplayCommands(const RecordedCommands& commands);

// The scene a replay is scored against: a closed loop's pusher starts at
// rest (its scene motion is zero), so the divergence check bounds its
// travel by the fastest recorded command instead.
mechanics::Scene ReplayScoringScene(const mechanics::Scene& scene,
                                    const RecordedCommands& commands);

// The same, for any trial: a closed-loop scene (pusher.controller set) is
// predicted by replaying `commands` through the predictor (open-loop replay
// of the same inputs) and scored as any trial; without commands its
// prediction is status "error", on a predictor that cannot replay commands
// "invalid_scene" with the reason. `commands` is ignored for an open-loop
// scene and may be null. Never throws.
db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth,
                            const nlohmann::json& prediction, const RecordedCommands* commands);

// Where a prediction starts (issue 26). A lab predicts from the state it
// measured: from the start pose the cell reported, the error measures the
// model and not the reset's placement; from the planned pose (the scene's)
// it measures both, so the two together give the reset's share.
enum class StartFrom { kMeasured, kPlanned };
const char* ToString(StartFrom from);  // "measured", "planned"
std::optional<StartFrom> StartFromString(std::string_view text);
// The campaign's `prediction.start` (kMeasured when absent or `prediction` is null).
// @throws mechanics::SceneError naming "prediction.start" for another value.
StartFrom StartFromOf(const nlohmann::json& prediction);

struct PredictionStart {
  StartFrom from = StartFrom::kPlanned;
  // "planned"; measured: "observed" (the cell's sensors at the first sample
  // of its stream) or "first_sample" (that sample's pose: the sensors dropped
  // it, or the backend's truth is its measurement).
  std::string source = "planned";
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // m, gripper frame
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  double offset_m = 0;    // from the planned position
  double offset_rad = 0;  // from the planned orientation
};
// The start a prediction of `scene` takes: kPlanned (or no sample) the
// scene's object pose; kMeasured the first sample of the trial's stream.
PredictionStart StartOf(const mechanics::Scene& scene, const db::Sample* first, StartFrom from);
// The scene with its object at `start` and the fingers closed on it there,
// as a cell places it (the pusher where the scene has it); unchanged when the
// start is the planned pose. @throws mechanics::SceneError when a finger
// misses the object there.
mechanics::Scene StartedAt(const mechanics::Scene& scene, const PredictionStart& start);
// Records the start in p->detail_json as "start": {"from", "source",
// "position_m", "orientation_wxyz", "offset_m", "offset_rad"}: every stored
// prediction says which start it used.
void NoteStart(db::Prediction* p, const PredictionStart& start);

// A trial's predicted trajectory, made as the service makes it: `prediction`
// (the campaign's object, or null) applied to the trial's scene and run on
// the predictor it names. Plots and exports re-run it this way (the store
// keeps a prediction's scores, not its samples), so a MuJoCo-predicted
// campaign is drawn and exported with MuJoCo's trajectory.
struct PredictedRun {
  mechanics::Scene scene;  // what the predictor ran (the model settings applied)
  mechanics::SimulationResult result;
  std::string predictor;      // "arena" or "mujoco"
  std::string key;            // the label the service stores the prediction under
  std::string settings_json;  // the settings it ran with (stored as model_json)
  PredictionStart start;      // where it started (issue 26)
};
// A closed-loop scene (issue 19) replays `commands` (RecordedCommands, above);
// without them, or on a predictor that cannot replay commands, result.status
// is kInvalidScene with the reason.
// @throws mechanics::SceneError for bad model settings; std::exception when
//   the predictor cannot be made. A solver failure or a scene the predictor
//   refuses is in result.status, not thrown.
// `first` is the first sample of the trial's stream: the run starts where
// the service's prediction started (prediction.start: measured by default,
// from `first`; planned, or no `first`: the scene's pose).
PredictedRun SimulatePrediction(const mechanics::Scene& trial_scene,
                                const nlohmann::json& prediction,
                                const RecordedCommands* commands = nullptr,
                                const db::Sample* first = nullptr);

// A prediction that could not be made (status, reason in detail_json).
db::Prediction PredictionFailure(db::PredictionStatus status, const std::string& reason);

}  // namespace arena::assessment
