#include "predictor_yield.hpp"

#include <algorithm>

namespace arena::orchestrator {

PredictorStart DecidePredictorStart(const PredictorStartInputs& in) {
  using Y = PredictorYield;
  // Yielding must never be what holds the cells' claims back (the backlog's
  // bound does, TrialDriver): past half of it the predictor runs at once.
  if (2 * in.backlog >= in.backlog_bound) return {true, in.now, "predictor.backlog_half_full"};
  const auto give_up = in.waiting_since + Y::kMaxYield;
  if (in.now >= give_up) return {true, in.now, "predictor.yielded_enough"};
  if (in.cells_on_path == 0 && in.now >= in.quiet_from)
    return {true, in.now, "predictor.path_quiet"};
  // On the path: a hand-off wakes the waiter; quiet soon: ask again then.
  const auto again = in.cells_on_path == 0 ? std::min(in.quiet_from, give_up) : give_up;
  return {false, again, "predictor.yields_to_path"};
}

void PathWatch::OnPath(const std::string& cell, Clock::time_point at) {
  std::lock_guard lock(mu_);
  // The first mark counts (the path began then), unless it is stale: a mark
  // never taken off (a cell lost between its phases) must not hide a new one.
  auto [it, fresh] = on_path_.emplace(cell, at);
  if (!fresh && at - it->second >= PredictorYield::kStale) it->second = at;
}

void PathWatch::OffPath(const std::string& cell, Clock::time_point at) {
  {
    std::lock_guard lock(mu_);
    on_path_.erase(cell);
    last_hand_off_ = std::max(last_hand_off_, at);
  }
  cv_.notify_all();
}

void PathWatch::Stop() {
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
}

PredictorStartInputs PathWatch::Inputs(Clock::time_point now, Clock::time_point since, int backlog,
                                       int backlog_bound) const {
  PredictorStartInputs in;
  in.now = now;
  in.waiting_since = since;
  in.backlog = backlog;
  in.backlog_bound = backlog_bound;
  for (const auto& [cell, from] : on_path_) in.cells_on_path += now - from < PredictorYield::kStale;
  in.quiet_from = last_hand_off_ + PredictorYield::kHopGrace;
  return in;
}

}  // namespace arena::orchestrator
