// Putting a campaign into the store: its spec, and its planned trials
// expanded by the sampler (each trial's scene, parameters, seed).
#pragma once

#include <cstdint>
#include <functional>
#include <stdexcept>

#include "arena/db/store.hpp"
#include "arena/errors/error.hpp"
#include "arena/orchestrator/campaign.hpp"

namespace arena::orchestrator {

inline constexpr std::int64_t kPlanChunk = 5000;  // trials planned (in memory) at a time

// `interrupted` returned true: the submit was abandoned and nothing stored.
class SubmitInterrupted : public Error {
 public:
  SubmitInterrupted()
      : Error(ErrorCategory::kInterrupted, "submit interrupted; nothing was stored") {}
};

// Stores the campaign and plans all of its trials in ONE transaction (planned
// kPlanChunk at a time): a crash, a full disk or an interrupt mid-way leaves
// nothing of the campaign. `interrupted` is asked between chunks.
// @returns the campaign id. @throws db::StoreError, SubmitInterrupted.
std::int64_t SubmitCampaign(db::Store& store, const Campaign& campaign,
                            const std::function<bool()>& interrupted = {});

}  // namespace arena::orchestrator
