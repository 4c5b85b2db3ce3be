// Which service a cell serves, and the commands waiting for its worker.
//
// A cell serves one service session at a time (README.md, "One service per store, one service per
// cell"):
//
//   free --claim / first phase command--> serving S --lease runs out--> free
//     serving S --release (lease 0)--> free          (S retired)
//     serving S --claim by S' of the same store--> serving S'  (S retired:
//                                       one service per store, so S is dead)
//
// A retired session is never served again, so a dead service's late commands
// cannot run after its successor claimed the cell. Commands of the served
// session queue for the worker; every other session's are dropped.
//
// No DDS and no locking here: the cell calls it under its own mutex from the
// intake thread (Take, Expire) and the worker (Pop, Serves), which keeps the
// rules testable without processes (tests/executors/command_intake_test.cpp).
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <optional>
#include <set>
#include <string>

#include "arena/schemas/arena.h"

namespace arena::executors {

class CommandIntake {
 public:
  using Clock = std::chrono::steady_clock;

  struct Serving {
    std::uint64_t session = 0;  // 0: free
    std::string host, store;
    std::uint32_t pid = 0;
    double lease_s = 0;
    Clock::time_point until{};
  };

  // A command without a claim (a test driver) holds the cell this long.
  static constexpr double kImplicitLease_s = 10.0;
  static constexpr double kMaxLease_s = 3600.0;
  static constexpr std::size_t kRetiredKept = 256;

  // What taking one command did.
  struct Taken {
    bool queued = false;    // it waits for the worker (Pop)
    bool announce = false;  // `serving` changed: the cell announces it
  };

  // One command as it arrives (claims act at once). `cell_id` is the cell's.
  Taken Take(const msg::TrialCommand& c, Clock::time_point now, const std::string& cell_id);

  // Frees the cell when the served session's lease ran out.
  // @returns true when it did (the cell announces it).
  bool Expire(Clock::time_point now, const std::string& cell_id);

  // The oldest queued command of the served session.
  std::optional<msg::TrialCommand> Pop();
  bool empty() const { return queue_.empty(); }

  bool Serves(std::uint64_t session) const { return serving_.session == session; }
  const Serving& serving() const { return serving_; }

 private:
  void Retire(std::uint64_t session);
  // Serves `c`'s session from now on. @returns true when the announcement changes.
  bool Serve(const msg::TrialCommand& c, double lease_s, Clock::time_point now,
             const std::string& cell_id);

  Serving serving_;
  std::set<std::uint64_t> retired_;
  std::deque<std::uint64_t> retired_order_;  // oldest first: only kRetiredKept are kept
  std::deque<msg::TrialCommand> queue_;
};

// An EXECUTE the service sent while the cell still resets
// (TrialCommand.after_reset_trial_id / after_reset_attempt: the service's
// pipelined dispatch) runs only right after that RESET ended RESET_DONE. The
// intake queues commands in order, so the RESET always runs first; if it
// failed, was refused, or something else ran in between, the EXECUTE is
// REFUSED with the reason: a robot never pushes from a failed reset, and the
// service, which saw the reset's status first, has already released the trial.
class ResetGate {
 public:
  // The worker finished a RESET (`done`: RESET_DONE; otherwise `why` it did not).
  void ResetEnded(const msg::TrialCommand& reset, bool done, const std::string& why);
  // The worker finished any other command.
  void OtherEnded() { last_is_reset_ = false; }
  // "" when `execute` may run; otherwise why it is refused.
  std::string Check(const msg::TrialCommand& execute) const;

 private:
  bool last_is_reset_ = false, done_ = false;
  std::uint64_t session_ = 0, trial_id_ = 0;
  std::uint32_t attempt_ = 0;
  std::string why_;
};

}  // namespace arena::executors
