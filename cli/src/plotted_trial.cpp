#include "plotted_trial.hpp"

#include <exception>

#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "command_error.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

// A trial that has no ground truth: why, and what the reader can do.
[[noreturn]] void ThrowNoGroundTruth(const db::Store& store, const db::Trial& trial) {
  const std::string id = std::to_string(trial.id);
  if (db::IsTerminal(trial.state)) {
    // Failed or cancelled before any ground truth was kept: there is
    // nothing to plot now or later, and nothing to watch.
    std::string why;
    try {
      const auto history = store.ListTransitions(trial.id);
      if (!history.empty()) why = history.back().reason;
    } catch (const db::StoreError&) {
    }
    throw CommandError(kExitBadInput,
                       "trial " + id + " " + db::ToString(trial.state) + " without ground truth" +
                           (why.empty() ? "" : " (" + why + ")") +
                           "; there is nothing to plot (`arena query --db " + store.path() +
                           " \"select * from trial_transitions where trial_id = " + id +
                           "\"` shows its history)");
  }
  throw CommandError(
      kExitBadInput,
      "trial " + id + " has no ground truth yet (state " + db::ToString(trial.state) +
          "); plot it once it has executed (`arena status` shows progress), or watch it live "
          "with `arena watch " +
          id + "`");
}

}  // namespace

PlottedTrial LoadPlottedTrial(const db::Store& store, std::int64_t trial_id) {
  PlottedTrial p;
  try {
    p.trial = store.GetTrial(trial_id);
    p.campaign = store.GetCampaign(p.trial.campaign_id);
  } catch (const db::StoreError& e) {
    if (e.kind() == db::StoreError::Kind::kNotFound)
      throw CommandError(kExitBadInput, "no trial " + std::to_string(trial_id) + " in " +
                                            store.path() +
                                            " (find trial ids with `arena query --db " +
                                            store.path() + " --campaign ID`)");
    throw StoreCommandError(e);
  }
  if (!p.trial.gt_stream_id) ThrowNoGroundTruth(store, p.trial);
  try {
    p.gt = store.ReadGroundTruth(trial_id);
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  }
  if (p.gt.samples.empty())
    throw CommandError(kExitFailure,
                       "trial " + std::to_string(trial_id) + ": its ground truth has no samples");
  try {
    p.scene = mechanics::ParseScene(p.trial.scene_json);
  } catch (const std::exception& e) {
    throw CommandError(
        kExitStore, "trial " + std::to_string(trial_id) + ": stored scene unreadable: " + e.what());
  }
  return p;
}

mechanics::SimulationResult PredictPlottedTrial(const db::Store& store, const PlottedTrial& p,
                                                TrialPlotInfo* info, std::string* reason) {
  reason->clear();
  try {
    nlohmann::json model;
    const auto spec = nlohmann::json::parse(p.campaign.spec_json);
    if (spec.is_object() && spec.contains("prediction")) model = spec["prediction"];
    // A closed-loop trial (issue 19) is predicted by replaying its applied commands.
    assessment::RecordedCommands commands;
    if (p.scene.pusher && p.scene.pusher->controller) {
      if (auto applied = store.GetClosedLoop(p.trial.id))
        commands = assessment::CommandsOf(*applied);
    }
    assessment::PredictedRun run =
        assessment::SimulatePrediction(p.scene, model, &commands, &p.gt.samples.front());
    info->model_key = run.key;
    info->prediction_status = assessment::StatusOf(run.result.status);
    if (run.result.status != mechanics::SimulationStatus::kOk) *reason = run.result.error;
    return std::move(run.result);
  } catch (const std::exception& e) {
    info->prediction_status = db::PredictionStatus::kError;
    *reason = e.what();
    return {};
  }
}

}  // namespace arena::cli
