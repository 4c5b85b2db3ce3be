// The suspenders at run time (issue 29): the windows of recent resets,
// streams and closed loops per cell and per campaign, the cells' liveness,
// and one SuspenderState per (condition, cell | campaign | service). The
// rules are suspender_policy.hpp's; this class only measures and keeps
// state. The service (service.cpp) feeds it through the trial driver
// (TrialObserver), asks Evaluate() about once a second, writes each action
// to the store and only then Commit()s it, so a busy store repeats the same
// decision on the next pass instead of losing it.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "arena/db/store.hpp"
#include "arena/orchestrator/suspender_policy.hpp"
#include "arena/orchestrator/trial_driver.hpp"

namespace arena::orchestrator {

class Suspenders : public TrialObserver {
 public:
  // now_s: seconds on a steady clock (tests inject one).
  Suspenders(SuspenderConfig config, std::function<double()> now_s);

  // ---- TrialObserver
  void OnReset(const std::string& cell_id, std::int64_t campaign_id, bool ok, bool pose_observed,
               double position_error_m) override;
  void OnStream(const std::string& cell_id, std::int64_t campaign_id, std::int64_t samples,
                std::int64_t dropped) override;
  void OnClosedLoop(const std::string& cell_id, std::int64_t campaign_id, std::int64_t samples,
                    std::int64_t held) override;
  void OnCellAlive(const std::string& cell_id, bool alive) override;
  const char* DispatchGate(const std::string& cell_id) override;

  // One suspender's step to carry out (fire, lift, set aside).
  struct Action {
    Condition condition = Condition::kResetFailureRate;
    std::string cell_id;           // cell scope
    std::int64_t campaign_id = 0;  // campaign scope
    SuspenderDecision decision;
    std::int64_t suspension_id = 0;  // a lift: the store row it lifts
  };
  // Every suspender's decision now (free_bytes: the store folder's free
  // space, nullopt when it could not be read). Changes nothing: Commit() does.
  std::vector<Action> Evaluate(std::optional<double> free_bytes) const;
  // The action is in the store (a fire: as row suspension_id).
  void Commit(const Action& action, std::int64_t suspension_id = 0);
  // A suspension the store holds that this instance does not (a restart):
  // held anew from now.
  void Adopt(const db::Suspension& s);
  // The store's active suspensions: those this instance holds that are no
  // longer active there were lifted by `arena resume` (hold and budget
  // reset). @returns them.
  std::vector<Action> Reconcile(const std::vector<db::Suspension>& active);

  // The cell's quarantine was lifted (`arena cells release`): its set-aside
  // conditions watch again, with their budget.
  void CellReleased(const std::string& cell_id);

  // Suspended now.
  std::vector<ActiveSuspension> Active() const;
  const SuspenderConfig& config() const { return config_; }

 private:
  using Key = std::tuple<Condition, std::string, std::int64_t>;
  struct Slot {
    SuspenderState state;
    std::int64_t suspension_id = 0;
    // Observations numbered below this are not counted (a fire empties the
    // window: the trials after the hold probe again).
    std::uint64_t measured_from = 0;
  };
  struct Observation {
    std::uint64_t seq = 0;  // in the order observed
    double a = 0, b = 0;    // (failed, 1) | (error, 1) | (dropped, samples) | (held, samples)
  };
  static Key KeyOf(Condition c, const std::string& cell, std::int64_t campaign);
  Reading Read(Condition c, const std::string& cell, std::int64_t campaign, std::uint64_t from,
               std::optional<double> free_bytes) const;
  void Push(std::deque<Observation>& window, Observation o);
  Slot& SlotOf(const Key& k) { return slots_[k]; }

  SuspenderConfig config_;
  std::function<double()> now_;
  std::map<Key, Slot> slots_;
  std::uint64_t seq_ = 1;  // the next observation's number
  // Windows: cell -> resets (failed?), observed reset errors, streams; campaign -> closed loops.
  std::map<std::string, std::deque<Observation>> resets_, drift_, streams_;
  std::map<std::int64_t, std::deque<Observation>> loops_;
  struct Liveness {
    bool alive = true;
    double since = 0;
  };
  std::map<std::string, Liveness> cells_;
};

}  // namespace arena::orchestrator
