// Predicting a trial: the campaign's model settings applied to the trial's
// scene, the model run, and the result scored against the ground truth.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "arena/db/store.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::orchestrator {

// Overrides the scene's `model` with the settings present in `model`
// (facets, points, dt, reduce; any may be absent; null = none).
// @throws mechanics::SceneError naming "model.<field>" for a bad setting.
mechanics::Scene ApplyModelSettings(const mechanics::Scene& scene, const nlohmann::json& model);

// "g8_k3_dt0.004_auto": the fidelity label predictions are stored under.
std::string ModelKey(const mechanics::ModelOptions& model);

// Runs the model on `scene` and scores it against `truth`; never throws.
// A solver failure is a prediction with status "solver_failure" (experiment
// data, not an error), an invalid scene one with "invalid_scene".
db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth);

// Closed loop (issue 19): the pusher commands a closed-loop trial applied,
// indexed by the sample they answered (ClosedLoopCommand.commanded).
using RecordedCommands = std::vector<mechanics::PusherMotion>;
RecordedCommands CommandsOf(const db::ClosedLoopRun& run);
// A closed-loop scene (pusher.controller set) is predicted by replaying its
// recorded commands open-loop through the model: command k moves the pusher
// from the step after sample k, exactly as on the cell. Without commands a
// closed-loop scene's prediction is status "error".
db::Prediction PredictTrial(const mechanics::Scene& scene,
                            const std::vector<mechanics::TrajectorySample>& truth,
                            const RecordedCommands* commands);
// A prediction that could not be made (status, reason in detail_json).
db::Prediction PredictionFailure(const std::string& status, const std::string& reason);

}  // namespace arena::orchestrator
