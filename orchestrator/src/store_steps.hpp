// How the trial driver runs a step against the store (trial_driver.hpp, "the
// store policy"): a busy store (kBusy) queues the same step again with a
// doubling back-off, and the cell that waits on it holds its deadlines; a
// store that cannot go on (full, I/O, corrupt, read-only, too new) stops the
// service (the error is rethrown); any other error makes the step moot (the
// trial moved on: cancelled, failed, another attempt) and goes to on_moot.
#pragma once

#include <deque>
#include <functional>
#include <string>

#include "arena/db/store.hpp"
#include "arena/orchestrator/trial_driver.hpp"

namespace arena::orchestrator {

// What a store error means for the step that met it.
enum class StoreVerdict { kRetry, kStop, kMoot };
StoreVerdict Judge(const db::StoreError& e);

class StoreSteps {
 public:
  using Clock = DriverClock;
  using Run = std::function<void()>;
  using OnMoot = std::function<void(const db::StoreError&)>;
  static constexpr double kFirstBackoff_s = 0.05;
  static constexpr double kMaxBackoff_s = 2.0;

  // `on_wait(cell_id, +1 / -1)`: a cell's step starts / stops waiting on a busy store.
  StoreSteps(std::function<Clock::time_point()> now,
             std::function<void(const std::string& cell_id, int delta)> on_wait);

  // Runs one step now. @returns true when it ran to its end.
  bool Step(const std::string& what, const std::string& cell_id, const Run& run,
            const OnMoot& on_moot = {}, double backoff_s = kFirstBackoff_s);
  // A step whose busy retry is pointless (the next pass does it anyway).
  void Attempt(const std::string& what, const Run& run);
  // The queued steps that are due, each once (those busy again are queued again).
  void RunDue();
  std::size_t pending() const { return pending_.size(); }

 private:
  struct Pending {
    std::string what;
    std::string cell_id;  // "" when no cell waits on it
    Run run;
    OnMoot on_moot;
    Clock::time_point due;
    double backoff_s;
  };
  std::function<Clock::time_point()> now_;
  std::function<void(const std::string&, int)> on_wait_;
  std::deque<Pending> pending_;
};

}  // namespace arena::orchestrator
