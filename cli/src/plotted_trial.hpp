// What both per-trial plots (`arena plot TRIAL` and `--paths`) read from the
// store and re-run: the trial with its campaign, ground truth and scene, and
// its prediction made exactly as the service made it.
#pragma once

#include <cstdint>
#include <string>

#include "arena/db/store.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "plot_trial.hpp"

namespace arena::cli {

struct PlottedTrial {
  db::Trial trial;
  db::Campaign campaign;
  db::GroundTruth gt;  // at least one sample
  mechanics::Scene scene;
};

// @throws CommandError: kExitBadInput for an unknown trial or one without
//   ground truth (yet, or ever: the message says which and what to do),
//   kExitFailure for a ground truth without samples, kExitStore for a store
//   failure or an unreadable stored scene.
PlottedTrial LoadPlottedTrial(const db::Store& store, std::int64_t trial_id);

// The prediction as the service made it: the campaign's "prediction"
// settings applied to the trial's scene, on its predictor, from the start
// the service took (the cell's measured start unless prediction.start says
// planned); a closed-loop trial replays its applied commands. Fills
// info->model_key and info->prediction_status; a prediction that could not
// be made or did not finish leaves its reason in *reason (empty otherwise)
// and, if it could not be made, no samples.
mechanics::SimulationResult PredictPlottedTrial(const db::Store& store, const PlottedTrial& p,
                                                TrialPlotInfo* info, std::string* reason);

}  // namespace arena::cli
