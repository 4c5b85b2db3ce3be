// The trial policy (trial_policy.hpp) as one table: one row per (cell phase,
// status phase, status state, failure kind) and per (cell phase, service
// event), with the step, whom it blames, whether the cell backs off and the
// rule's name. The test checks every row AND that the table covers every
// combination, so a new enum value cannot slip through undecided.
#include "arena/orchestrator/trial_policy.hpp"

#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

namespace arena::orchestrator {
namespace {

using CP = CellPhase;
using SP = StatusPhase;
using SS = StatusState;
using FK = FailureKind;
using TS = TrialStep;
using P = Party;

struct StatusRow {
  CP phase;
  SP status_phase;
  SS state;
  FK failure;
  TS step;
  P blame;
  bool back_off;
  const char* rule;
};

constexpr CP kPhases[] = {CP::kIdle, CP::kExecuting, CP::kResetting};
constexpr SP kStatusPhases[] = {SP::kExecute, SP::kReset};
constexpr SS kStates[] = {SS::kAccepted, SS::kExecuted, SS::kResetDone, SS::kRefused, SS::kFailed};
constexpr FK kKinds[] = {FK::kNone,  FK::kSimulation, FK::kDeadline,  FK::kInterrupted,
                         FK::kReset, FK::kInternal,   FK::kController};
constexpr ServiceEvent kEvents[] = {
    ServiceEvent::kDeadlineMissed, ServiceEvent::kStreamIncomplete,  ServiceEvent::kStreamMalformed,
    ServiceEvent::kCommandNotSent, ServiceEvent::kStoreRefusedTruth, ServiceEvent::kCellLost,
    ServiceEvent::kCellRestarted,  ServiceEvent::kCellServesAnother, ServiceEvent::kInvalidScene};

// A status carries a failure kind only when FAILED: the other states have one row (kNone).
std::vector<StatusRow> StatusTable() {
  std::vector<StatusRow> t;
  // An idle cell: whatever it says is late.
  for (SP sp : kStatusPhases)
    for (SS s : kStates)
      for (FK k : kKinds)
        if (s == SS::kFailed || k == FK::kNone)
          t.push_back({CP::kIdle, sp, s, k, TS::kIgnore, P::kNobody, false, "late.cell_idle"});
  // A status of the other phase than the cell's: late.
  for (SS s : kStates)
    for (FK k : kKinds)
      if (s == SS::kFailed || k == FK::kNone) {
        t.push_back({CP::kExecuting, SP::kReset, s, k, TS::kIgnore, P::kNobody, false,
                     "late.status_of_another_phase"});
        t.push_back({CP::kResetting, SP::kExecute, s, k, TS::kIgnore, P::kNobody, false,
                     "late.status_of_another_phase"});
      }
  const std::vector<StatusRow> execute = {
      {CP::kExecuting, SP::kExecute, SS::kAccepted, FK::kNone, TS::kAwait, P::kNobody, false,
       "execute.accepted"},
      {CP::kExecuting, SP::kExecute, SS::kExecuted, FK::kNone, TS::kCollectStream, P::kNobody,
       false, "execute.executed"},
      {CP::kExecuting, SP::kExecute, SS::kResetDone, FK::kNone, TS::kIgnore, P::kNobody, false,
       "late.state_of_another_phase"},
      {CP::kExecuting, SP::kExecute, SS::kRefused, FK::kNone, TS::kRetry, P::kNobody, false,
       "execute.refused_by_cell"},
      {CP::kExecuting, SP::kExecute, SS::kFailed, FK::kNone, TS::kRetry, P::kCell, true,
       "execute.cell_failure_untyped"},
      {CP::kExecuting, SP::kExecute, SS::kFailed, FK::kSimulation, TS::kFail, P::kScene, false,
       "execute.simulation_failure"},
      {CP::kExecuting, SP::kExecute, SS::kFailed, FK::kDeadline, TS::kRetry, P::kCell, true,
       "execute.cell_deadline"},
      {CP::kExecuting, SP::kExecute, SS::kFailed, FK::kInterrupted, TS::kRetry, P::kCell, true,
       "execute.cell_interrupted"},
      {CP::kExecuting, SP::kExecute, SS::kFailed, FK::kReset, TS::kRetry, P::kCell, true,
       "execute.cell_failure_typed_as_reset"},
      {CP::kExecuting, SP::kExecute, SS::kFailed, FK::kInternal, TS::kRetry, P::kCell, true,
       "execute.cell_failure"},
      // Issue 28: a paused controller fails the trial, never the cell; the cell backs off.
      {CP::kExecuting, SP::kExecute, SS::kFailed, FK::kController, TS::kRetry, P::kController, true,
       "execute.controller_fault"},
      {CP::kResetting, SP::kReset, SS::kAccepted, FK::kNone, TS::kAwait, P::kNobody, false,
       "reset.accepted"},
      {CP::kResetting, SP::kReset, SS::kExecuted, FK::kNone, TS::kIgnore, P::kNobody, false,
       "late.state_of_another_phase"},
      {CP::kResetting, SP::kReset, SS::kResetDone, FK::kNone, TS::kResetDone, P::kNobody, false,
       "reset.verified"},
      {CP::kResetting, SP::kReset, SS::kRefused, FK::kNone, TS::kIgnore, P::kNobody, false,
       "reset.refused_waits_for_deadline"},
  };
  t.insert(t.end(), execute.begin(), execute.end());
  for (FK k : kKinds)  // a failed reset is the cell's, whatever its kind
    t.push_back({CP::kResetting, SP::kReset, SS::kFailed, k, TS::kResetFailed, P::kCell, true,
                 "reset.failed"});
  return t;
}

TEST(TrialPolicy, EveryStatusRowDecidesAsTheTableSays) {
  for (const StatusRow& r : StatusTable()) {
    const Decision d = DecideStatus(r.phase, r.status_phase, r.state, r.failure);
    const std::string row = std::string(ToString(r.phase)) + " / " + ToString(r.status_phase) +
                            " " + ToString(r.state) + " (" + ToString(r.failure) + ")";
    EXPECT_EQ(d.trial, r.step) << row << ": " << ToString(d.trial);
    EXPECT_EQ(d.blame, r.blame) << row << ": " << ToString(d.blame);
    EXPECT_EQ(d.back_off, r.back_off) << row;
    EXPECT_STREQ(d.rule, r.rule) << row;
    EXPECT_EQ(d.counts_against_cell(), r.blame == P::kCell) << row;
  }
}

TEST(TrialPolicy, TheStatusTableHasOneRowPerPhaseStateAndFailureKind) {
  std::set<std::tuple<CP, SP, SS, FK>> rows;
  for (const StatusRow& r : StatusTable())
    EXPECT_TRUE(rows.insert({r.phase, r.status_phase, r.state, r.failure}).second)
        << "two rows for " << ToString(r.phase) << " " << ToString(r.state);
  for (CP p : kPhases)
    for (SP sp : kStatusPhases)
      for (SS s : kStates)
        for (FK k : kKinds)
          if (s == SS::kFailed || k == FK::kNone) {
            EXPECT_TRUE(rows.count({p, sp, s, k}))
                << "no row for " << ToString(p) << " / " << ToString(sp) << " " << ToString(s)
                << " (" << ToString(k) << ")";
          }
}

struct EventRow {
  CP phase;
  ServiceEvent event;
  TS step;
  P blame;
  bool back_off;
  const char* rule;
};

std::vector<EventRow> EventTable() {
  std::vector<EventRow> t = {
      // Executing: the cell's own faults count; the service's, the store's and
      // a lost / restarted / claimed cell's do not.
      {CP::kExecuting, ServiceEvent::kDeadlineMissed, TS::kRetry, P::kCell, true,
       "execute.deadline_missed"},
      {CP::kExecuting, ServiceEvent::kStreamIncomplete, TS::kRetry, P::kCell, true,
       "execute.stream_incomplete"},
      {CP::kExecuting, ServiceEvent::kStreamMalformed, TS::kRetry, P::kCell, true,
       "execute.stream_malformed"},
      {CP::kExecuting, ServiceEvent::kCommandNotSent, TS::kRetry, P::kService, true,
       "execute.command_not_sent"},
      {CP::kExecuting, ServiceEvent::kStoreRefusedTruth, TS::kRetry, P::kStore, true,
       "execute.store_refused_truth"},
      {CP::kExecuting, ServiceEvent::kCellLost, TS::kRetry, P::kNobody, false, "execute.cell_lost"},
      {CP::kExecuting, ServiceEvent::kCellRestarted, TS::kRetry, P::kNobody, false,
       "execute.cell_restarted"},
      {CP::kExecuting, ServiceEvent::kCellServesAnother, TS::kRetry, P::kNobody, false,
       "execute.cell_claimed_elsewhere"},
      {CP::kResetting, ServiceEvent::kDeadlineMissed, TS::kResetFailed, P::kCell, true,
       "reset.deadline_missed"},
      {CP::kResetting, ServiceEvent::kCommandNotSent, TS::kResetFailed, P::kService, true,
       "reset.command_not_sent"},
      {CP::kResetting, ServiceEvent::kCellLost, TS::kResetFailed, P::kNobody, false,
       "reset.cell_lost"},
      {CP::kResetting, ServiceEvent::kCellRestarted, TS::kResetFailed, P::kNobody, false,
       "reset.cell_restarted"},
      {CP::kResetting, ServiceEvent::kCellServesAnother, TS::kResetFailed, P::kNobody, false,
       "reset.cell_claimed_elsewhere"},
      {CP::kResetting, ServiceEvent::kStreamIncomplete, TS::kIgnore, P::kNobody, false,
       "late.stream_event_in_reset"},
      {CP::kResetting, ServiceEvent::kStreamMalformed, TS::kIgnore, P::kNobody, false,
       "late.stream_event_in_reset"},
      {CP::kResetting, ServiceEvent::kStoreRefusedTruth, TS::kIgnore, P::kNobody, false,
       "late.stream_event_in_reset"},
  };
  for (CP p : kPhases)  // a scene that does not parse fails its trial before any phase
    t.push_back(
        {p, ServiceEvent::kInvalidScene, TS::kFail, P::kScene, false, "dispatch.invalid_scene"});
  for (ServiceEvent e : kEvents)
    if (e != ServiceEvent::kInvalidScene)
      t.push_back({CP::kIdle, e, TS::kIgnore, P::kNobody, false, "late.cell_idle"});
  return t;
}

TEST(TrialPolicy, EveryServiceEventRowDecidesAsTheTableSays) {
  std::set<std::pair<CP, ServiceEvent>> rows;
  for (const EventRow& r : EventTable()) {
    EXPECT_TRUE(rows.insert({r.phase, r.event}).second) << "two rows";
    const Decision d = DecideServiceEvent(r.phase, r.event);
    const std::string row = std::string(ToString(r.phase)) + " / " + ToString(r.event);
    EXPECT_EQ(d.trial, r.step) << row << ": " << ToString(d.trial);
    EXPECT_EQ(d.blame, r.blame) << row << ": " << ToString(d.blame);
    EXPECT_EQ(d.back_off, r.back_off) << row;
    EXPECT_STREQ(d.rule, r.rule) << row;
  }
  for (CP p : kPhases)
    for (ServiceEvent e : kEvents)
      EXPECT_TRUE(rows.count({p, e})) << "no row for " << ToString(p) << " / " << ToString(e);
}

TEST(TrialPolicy, NoFailureCausedByTheControllerTheServiceOrTheStoreCountsAgainstTheCell) {
  for (const StatusRow& r : StatusTable())
    if (r.failure == FK::kController && r.status_phase == SP::kExecute) {
      EXPECT_FALSE(DecideStatus(r.phase, r.status_phase, r.state, r.failure).counts_against_cell());
    }
  for (CP p : kPhases)
    for (ServiceEvent e : {ServiceEvent::kCommandNotSent, ServiceEvent::kStoreRefusedTruth,
                           ServiceEvent::kCellLost, ServiceEvent::kCellRestarted,
                           ServiceEvent::kCellServesAnother, ServiceEvent::kInvalidScene})
      EXPECT_FALSE(DecideServiceEvent(p, e).counts_against_cell()) << ToString(e);
}

TEST(TrialPolicy, ARefusalPausesTheCellBrieflyWithoutBackingOff) {
  const Decision d = DecideStatus(CP::kExecuting, SP::kExecute, SS::kRefused, FK::kNone);
  EXPECT_FALSE(d.back_off);
  EXPECT_EQ(d.pause_s, kRefusedPause_s);
  EXPECT_EQ(DecideStatus(CP::kExecuting, SP::kExecute, SS::kFailed, FK::kSimulation).outcome,
            db::TrialEnd::kSolverFailure);
  EXPECT_EQ(DecideServiceEvent(CP::kIdle, ServiceEvent::kInvalidScene).outcome,
            db::TrialEnd::kInvalidScene);
}

TEST(TrialPolicy, LateMessagesAreDroppedByName) {
  EXPECT_STREQ(LateMessageRule(false, CP::kExecuting, true), "late.other_session");
  EXPECT_STREQ(LateMessageRule(true, CP::kIdle, true), "late.cell_idle");
  EXPECT_STREQ(LateMessageRule(true, CP::kResetting, false), "late.other_trial_or_attempt");
  EXPECT_EQ(LateMessageRule(true, CP::kExecuting, true), nullptr);
}

// Issue 27: a RESET sent before the publish it follows committed. Nothing of
// it is the trial's until the publish committed; a refused publish leaves
// the cell to be freed by the reset it runs. One row per event, every event.
TEST(TrialPolicy, AResetAheadOfItsPublishIsTheTrialsOnlyOnceThePublishCommitted) {
  using E = AheadEvent;
  using S = AheadStep;
  struct Row {
    E event;
    S step;
    const char* rule;
  };
  const Row rows[] = {
      {E::kResetStatus, S::kHold, "reset.held_until_published"},
      {E::kPublishCommitted, S::kTakeHeld, "reset.ahead_of_committed_publish"},
      {E::kPublishRefused, S::kRunOut, "reset.ahead_of_refused_publish"},
      {E::kAttemptEnded, S::kDropHeld, "reset.ahead_of_ended_attempt"},
  };
  std::set<E> seen;
  for (const Row& r : rows) {
    EXPECT_TRUE(seen.insert(r.event).second) << "two rows for " << ToString(r.event);
    const AheadDecision d = DecideResetAhead(r.event);
    EXPECT_EQ(d.step, r.step) << ToString(r.event) << ": " << ToString(d.step);
    EXPECT_STREQ(d.rule, r.rule) << ToString(r.event);
  }
  for (E e : {E::kResetStatus, E::kPublishCommitted, E::kPublishRefused, E::kAttemptEnded})
    EXPECT_TRUE(seen.count(e)) << "no row for " << ToString(e);
}

// Issue 27: the next trial's EXECUTE queued behind the cell's reset. It runs
// only after a reset that ended done; whenever the cell will not run it for
// us, it goes back to planned without counting. One row per event.
TEST(TrialPolicy, AQueuedTrialRunsOnlyAfterItsResetEndedDone) {
  using E = QueuedEvent;
  using S = QueuedStep;
  struct Row {
    E event;
    S step;
    const char* rule;
  };
  const Row rows[] = {
      {E::kOwnStatus, S::kHold, "queued.held_until_reset_taken"},
      {E::kResetDone, S::kRun, "queued.runs_after_reset_done"},
      {E::kResetFailed, S::kRelease, "queued.behind_failed_reset"},
      {E::kPublishRefused, S::kKeep, "queued.runs_after_run_out_reset"},
      {E::kPhaseEnded, S::kRelease, "queued.cell_phase_ended"},
      {E::kNotSent, S::kRelease, "queued.command_not_sent"},
      {E::kTruthRefused, S::kRelease, "queued.truth_refused"},
  };
  std::set<E> seen;
  for (const Row& r : rows) {
    EXPECT_TRUE(seen.insert(r.event).second) << "two rows for " << ToString(r.event);
    const QueuedDecision d = DecideQueued(r.event);
    EXPECT_EQ(d.step, r.step) << ToString(r.event) << ": " << ToString(d.step);
    EXPECT_STREQ(d.rule, r.rule) << ToString(r.event);
  }
  for (E e : {E::kOwnStatus, E::kResetDone, E::kResetFailed, E::kPublishRefused, E::kPhaseEnded,
              E::kNotSent, E::kTruthRefused})
    EXPECT_TRUE(seen.count(e)) << "no row for " << ToString(e);
}

TEST(TrialPolicy, APredictionWaitsForItsResetOrClosesAnUnconfirmedOne) {
  using PS = PredictionStep;
  struct Row {
    bool same_attempt, awaiting_reset, in_flight;
    PS step;
    const char* rule;
  };
  const Row rows[] = {
      {false, false, false, PS::kDrop, "predict.stale_attempt"},
      {false, true, true, PS::kDrop, "predict.stale_attempt"},
      {false, true, false, PS::kDrop, "predict.stale_attempt"},
      {true, true, true, PS::kWaitForReset, "predict.wait_for_reset"},
      {true, true, false, PS::kCloseResetThenRecord, kResetUnconfirmedAtPrediction},
      {true, false, false, PS::kRecord, "predict.record"},
      {true, false, true, PS::kRecord, "predict.record"},
  };
  for (const Row& r : rows) {
    const PredictionDecision d = DecidePrediction(r.same_attempt, r.awaiting_reset, r.in_flight);
    EXPECT_EQ(d.step, r.step) << r.same_attempt << r.awaiting_reset << r.in_flight;
    EXPECT_STREQ(d.rule, r.rule);
  }
}

TEST(TrialPolicy, TheCellBacksOffDoublingToItsCap) {
  EXPECT_EQ(CellBackoff_s(0, 0.5, 8), 0);
  EXPECT_EQ(CellBackoff_s(1, 0.5, 8), 0.5);
  EXPECT_EQ(CellBackoff_s(2, 0.5, 8), 1.0);
  EXPECT_EQ(CellBackoff_s(4, 0.5, 8), 4.0);
  EXPECT_EQ(CellBackoff_s(5, 0.5, 8), 8.0);
  EXPECT_EQ(CellBackoff_s(1000, 0.5, 8), 8.0);
  EXPECT_EQ(CellBackoff_s(3, 0, 8), 0);
}

// The one retry rule (db/retry_rule.hpp), the store's and every fake's.
TEST(TrialPolicy, TheRetryRuleCountsAttemptsButNotServiceRestarts) {
  struct Row {
    int attempt, restarts, max;
    bool give_up;
    int counted;
    const char* rule;
  };
  const Row rows[] = {
      {1, 0, 3, false, 1, "retry.attempts_left"},
      {2, 0, 3, false, 2, "retry.attempts_left"},
      {3, 0, 3, true, 3, "retry.attempts_exhausted"},
      {3, 1, 3, false, 2, "retry.attempts_left"},
      {4, 1, 3, true, 3, "retry.attempts_exhausted"},
      {1, 0, 1, true, 1, "retry.attempts_exhausted"},
  };
  for (const Row& r : rows) {
    const db::RetryVerdict v = db::DecideRetry(r.attempt, r.restarts, r.max);
    EXPECT_EQ(v.give_up, r.give_up) << r.attempt << " " << r.restarts << " " << r.max;
    EXPECT_EQ(v.counted, r.counted);
    EXPECT_STREQ(v.rule, r.rule);
  }
}

}  // namespace
}  // namespace arena::orchestrator
