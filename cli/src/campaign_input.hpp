// Reading a campaign file for `arena submit` and `arena run`: the campaign
// itself (orchestrator) and its defect profile (executors), both validated on
// the client so that nothing invalid reaches the store.
#pragma once

#include <string>

#include "arena/executors/defects.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "command_error.hpp"

namespace arena::cli {

// @throws CommandError(kExitBadInput) naming the file and the field.
inline orchestrator::Campaign LoadValidCampaign(const std::string& path) {
  orchestrator::Campaign campaign;
  try {
    campaign = orchestrator::LoadCampaignFile(path);
  } catch (const orchestrator::CampaignError& e) {
    throw CommandError(kExitBadInput, path + ": " + e.what());
  }
  executors::DefectProfile profile;
  try {
    profile = executors::ParseDefectProfile(campaign.defects_json);
  } catch (const executors::DefectError& e) {
    throw CommandError(kExitBadInput, path + ": defects." + e.what());
  }
  // A campaign no cell can run (a push out of the workspace or above the
  // pusher's speed limit that its own defect profile sets) is refused now,
  // not run to 100 % failure (issue 26). Adaptive campaigns choose their
  // points later; their corners are checked as scenes by ParseCampaign.
  if (!campaign.adaptive) {
    for (std::int64_t condition = 0; condition < campaign.conditions; ++condition) {
      const auto trial = orchestrator::PlanTrial(campaign, condition * campaign.replicates);
      if (const std::string why = executors::CheckCapabilities(profile, trial.scene);
          !why.empty()) {
        throw CommandError(kExitBadInput,
                           path + ": condition " + std::to_string(condition) + " " +
                               trial.parameters_json +
                               " cannot run within the campaign's defect profile: " + why);
      }
    }
  }
  return campaign;
}

}  // namespace arena::cli
