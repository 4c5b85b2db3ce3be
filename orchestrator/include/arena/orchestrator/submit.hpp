// Putting a campaign into the store: its spec, and its planned trials
// expanded by the sampler (each trial's scene, parameters, seed).
#pragma once

#include <cstdint>

#include "arena/db/store.hpp"
#include "arena/orchestrator/campaign.hpp"

namespace arena::orchestrator {

inline constexpr std::int64_t kPlanChunk = 5000;  // trials planned and written per transaction

// Stores the campaign and plans all of its trials. The first chunk is written
// with the campaign in one transaction, the rest in further transactions, each
// storing the sampler's position ({"next_index": N}) with its trials so a
// partial plan can be seen and continued.
// @returns the campaign id. @throws db::StoreError.
std::int64_t SubmitCampaign(db::Store& store, const Campaign& campaign);

}  // namespace arena::orchestrator
