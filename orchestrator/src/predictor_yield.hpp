// When a trial's prediction may start: the predictor yields to the trials'
// path (issue 27, the service's overhead per trial).
//
// A prediction is off its trial's path (it starts after the trial's RESET
// went out), but the model runs on the same cores as the path of every
// cell's next trial: the publish's commit, the reset's round trip, the claim
// and the EXECUTE's hop. Measured on the 2-core build host
// (bench/README.md, "Overhead, part X"), a prediction started there took
// 0.4-0.5 ms off the median overhead and 3 ms off its p95. So a prediction
// starts when no cell is between its phases (from the status that ended its
// phase until its next phase was handed to it, plus the hop that carries
// it), which on a cell's cycle is its EXECUTE or its RESET running:
//
//   job taken --backlog half full-------------------------> start  (never hold claims)
//             --yielded kMaxYield already------------------> start  (never starve)
//             --no cell on the path, kHopGrace since the last hand-off--> start
//             --otherwise: wait until the path is quiet or kMaxYield--> ask again
//
// DecidePredictorStart is the rule (pure, tested row by row in
// tests/orchestrator/predictor_yield_test.cpp); PathWatch is the state the
// service's loop writes and the predictor threads wait on.
#pragma once

#include <chrono>
#include <condition_variable>
#include <map>
#include <mutex>
#include <string>

namespace arena::orchestrator {

struct PredictorYield {
  using Clock = std::chrono::steady_clock;
  // A command's hop to its cell and the cell's intake: the path goes on this
  // long after the service handed the phase (the EXECUTE's or RESET's hop
  // measured 0.04-0.5 ms, "Overhead, part IX").
  static constexpr Clock::duration kHopGrace = std::chrono::milliseconds(1);
  // At most this long a prediction waits for a quiet path: with many cells
  // the path is seldom quiet, and the prediction must still run.
  static constexpr Clock::duration kMaxYield = std::chrono::milliseconds(20);
  // A cell on the path longer than this is not on a fast path (a store
  // waiting, a cell lost between its phases): it does not hold predictions.
  static constexpr Clock::duration kStale = std::chrono::milliseconds(50);
};

struct PredictorStartInputs {
  PredictorYield::Clock::time_point now, waiting_since;
  int backlog = 0;        // predictions waiting or running, this one included
  int backlog_bound = 1;  // ServiceOptions::prediction_backlog
  int cells_on_path = 0;  // cells between their phases (stale ones not counted)
  PredictorYield::Clock::time_point quiet_from;  // the last hand-off + kHopGrace
};

struct PredictorStart {
  bool start = false;
  PredictorYield::Clock::time_point wait_until;  // when not started: ask again then
  const char* rule = "";
};

PredictorStart DecidePredictorStart(const PredictorStartInputs& in);

// Which cells are between their phases, as the service's loop sees them;
// thread-safe: the loop writes it, the predictor threads wait on it.
class PathWatch {
 public:
  using Clock = PredictorYield::Clock;

  // `cell` took the status that ended its phase: it waits for the service.
  void OnPath(const std::string& cell, Clock::time_point at);
  // `cell` was handed its next phase (or left idle, or lost) at `at`.
  void OffPath(const std::string& cell, Clock::time_point at);
  // Blocks until `backlog()` and the path let a prediction start, or Stop().
  // @returns the rule that let it start ("" after Stop()).
  template <class Backlog>
  const char* WaitToStart(int backlog_bound, Backlog backlog);
  // Wakes every waiter for good (the predictor pool is stopping).
  void Stop();

 private:
  PredictorStartInputs Inputs(Clock::time_point now, Clock::time_point since, int backlog,
                              int backlog_bound) const;

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::map<std::string, Clock::time_point> on_path_;  // cell -> since
  Clock::time_point last_hand_off_{};
  bool stop_ = false;
};

template <class Backlog>
const char* PathWatch::WaitToStart(int backlog_bound, Backlog backlog) {
  const Clock::time_point since = Clock::now();
  std::unique_lock lock(mu_);
  for (;;) {
    if (stop_) return "";
    const PredictorStart d =
        DecidePredictorStart(Inputs(Clock::now(), since, backlog(), backlog_bound));
    if (d.start) return d.rule;
    cv_.wait_until(lock, d.wait_until);
  }
}

}  // namespace arena::orchestrator
