// Reading a campaign file for `arena submit` and `arena run`: the campaign
// itself (orchestrator) and its defect profile (executors), both validated on
// the client so that nothing invalid reaches the store.
#pragma once

#include <string>

#include "arena/executors/defects.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "commands.hpp"

namespace arena::cli {

// @throws CommandError(kExitBadInput) naming the file and the field.
inline orchestrator::Campaign LoadValidCampaign(const std::string& path) {
  orchestrator::Campaign campaign;
  try {
    campaign = orchestrator::LoadCampaignFile(path);
  } catch (const orchestrator::CampaignError& e) {
    throw CommandError(kExitBadInput, path + ": " + e.what());
  }
  try {
    executors::ParseDefectProfile(campaign.defects_json);
  } catch (const executors::DefectError& e) {
    throw CommandError(kExitBadInput, path + ": defects." + e.what());
  }
  return campaign;
}

}  // namespace arena::cli
