// Which trial an idle cell claims (issue 29): a pure function, so that the
// rule is tested on its own (tests/orchestrator/claim_chooser_test.cpp) and
// the driver calls it at one place (trial_driver.cpp, NextTrialFor).
//
// Change-aware scheduling batches fixture changes (schemas/fixtures.hpp)
// without biasing the data:
//
//   block     the campaign's plan (trial index order) is cut into blocks of
//             K = `window` consecutive trials: block b holds indices
//             [bK, (b+1)K). A cell may only claim within the current block:
//             the block of the lowest-index trial it could claim now. So a
//             trial runs at most one block away from its plan position, and
//             every condition stays interleaved in time exactly as the
//             (randomised or low-discrepancy) plan interleaves it.
//   entry     a cell's first claim in a block is drawn at random among the
//             block's claimable trials (seeded by campaign seed, block and
//             cell): which cell starts on which fixture is re-randomised in
//             every block, so no condition stays with one cell.
//   batch     later claims in the same block take the trial whose change
//             from the cell's mounted fixtures costs least (ties: plan order).
//   off       (scheduling.change_aware false, K = 1, or a cell that declares
//             no change costs) plan order, as before issue 29.
//
// Determinism: the choice depends only on its inputs (no clock, no global
// random state); the plan itself is never reordered or redrawn, so an
// adaptive campaign's rounds and stored decisions do not depend on it.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "arena/schemas/fixtures.hpp"

namespace arena::orchestrator {

// A campaign's "scheduling" block (docs/campaigns.md).
struct SchedulingOptions {
  bool change_aware = true;  // "change_aware": false switches it off
  int window = 16;           // "window": K, trials per block, 1..kMaxSchedulingWindow
};
inline constexpr int kMaxSchedulingWindow = 256;

// One trial the cell may claim now (planned, due, its contact types offered).
struct ClaimCandidate {
  std::int64_t trial_id = 0;
  std::int64_t index = 0;  // its plan position in the campaign
  schemas::Fixtures fixtures;
};

// What the cell did before this claim.
struct ClaimerState {
  std::optional<schemas::Fixtures> mounted;   // nullopt: not known (a fresh cell)
  std::optional<schemas::ChangeCosts> costs;  // nullopt: the cell declared none
  std::optional<std::int64_t> last_block;     // the block of its last claim in this campaign
  std::uint64_t draw_seed = 0;                // campaign seed mixed with the cell id
};

struct ClaimChoice {
  std::int64_t trial_id = 0;
  std::int64_t block = 0;
  double change_s = 0;  // what reaching it costs from the mounted fixtures
  // The rule that chose it: "claim.plan_order", "claim.block_entry" or
  // "claim.least_change".
  std::string rule;
};

// The block of a plan index.
std::int64_t BlockOf(std::int64_t index, int window);

// Chooses among `candidates` (one campaign's claimable trials, ascending
// index, at least every claimable trial of the current block).
// @returns nullopt when there are none.
std::optional<ClaimChoice> ChooseClaim(const SchedulingOptions& options,
                                       const std::vector<ClaimCandidate>& candidates,
                                       const ClaimerState& cell);

// The seed of a cell's block-entry draws in a campaign.
std::uint64_t DrawSeed(std::uint64_t campaign_seed, const std::string& cell_id);

}  // namespace arena::orchestrator
