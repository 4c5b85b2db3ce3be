// Which trial an idle cell claims; the contract is in claim_chooser.hpp.
#include "arena/orchestrator/claim_chooser.hpp"

namespace arena::orchestrator {
namespace {

// SplitMix64: a fixed, portable mix (std::hash is neither).
std::uint64_t Mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace

std::int64_t BlockOf(std::int64_t index, int window) { return window > 0 ? index / window : 0; }

std::uint64_t DrawSeed(std::uint64_t campaign_seed, const std::string& cell_id) {
  std::uint64_t h = 1469598103934665603ULL;  // FNV-1a of the cell id
  for (unsigned char c : cell_id) h = (h ^ c) * 1099511628211ULL;
  return Mix(campaign_seed ^ Mix(h));
}

std::optional<ClaimChoice> ChooseClaim(const SchedulingOptions& options,
                                       const std::vector<ClaimCandidate>& candidates,
                                       const ClaimerState& cell) {
  if (candidates.empty()) return std::nullopt;
  const int window = options.window > 0 ? options.window : 1;
  const std::int64_t block = BlockOf(candidates.front().index, window);
  auto cost = [&](const ClaimCandidate& c) {
    return cell.costs ? schemas::ChangeSeconds(
                            schemas::ChangesBetween(cell.mounted, c.fixtures, *cell.costs))
                      : 0.0;
  };
  if (!options.change_aware || window == 1 || !cell.costs) {
    return ClaimChoice{candidates.front().trial_id, block, cost(candidates.front()),
                       "claim.plan_order"};
  }
  std::size_t n = 0;  // the current block's candidates: a prefix (ascending index)
  while (n < candidates.size() && BlockOf(candidates[n].index, window) == block) ++n;
  if (cell.last_block != block) {
    const std::uint64_t draw = Mix(cell.draw_seed ^ Mix(static_cast<std::uint64_t>(block)));
    const ClaimCandidate& c = candidates[draw % n];
    return ClaimChoice{c.trial_id, block, cost(c), "claim.block_entry"};
  }
  std::size_t best = 0;
  double best_cost = cost(candidates[0]);
  for (std::size_t i = 1; i < n; ++i) {
    const double c = cost(candidates[i]);
    if (c < best_cost) {
      best = i;
      best_cost = c;
    }
  }
  return ClaimChoice{candidates[best].trial_id, block, best_cost, "claim.least_change"};
}

}  // namespace arena::orchestrator
