// Every decision the service takes about a trial, as pure functions of typed
// inputs: what happens to the trial (wait, collect its stream, retry, fail,
// close its reset), whom the failure is counted against, whether the cell
// backs off, and the NAME of the rule that decided. The trial driver
// (trial_driver.hpp) only executes decisions; each rule's name goes to the
// trial's audit row (trial_transitions.rule), so "why did trial 17 go to
// resetting?" is answered by one row and one row of the policy's table test
// (tests/orchestrator/trial_policy_test.cpp).
//
// ## Who is to blame (issue 28)
//
//   a failure caused by ...            counts against the cell   backs the cell off
//   the cell (deadline, stream, crash)         yes                      yes
//   the controller (closed loop)               no                       yes
//   the service itself (a command unsent)      no                       yes
//   the store (refused the ground truth)       no                       yes
//   the scene (the simulator cannot run it)    no (the trial fails)     no
//   nobody (the cell lost, restarted, claimed) no                       no
//   (the predictor's failures never reach the cell: a prediction is stored
//    with its status, the trial is done either way.)
//
// A cell that fails `quarantine_after` phases in a row that were ITS fault is
// quarantined; after any failure the cell waits CellBackoff_s before its next
// trial, so a paused controller or a store under load does not burn trial
// after trial in a second.
//
// ## The retry rule
//
// Whether a retried trial runs again or fails for good is db::DecideRetry
// (db/retry_rule.hpp), applied by the store inside RetryTrial's transaction.
#pragma once

#include <string_view>

#include "arena/db/retry_rule.hpp"
#include "arena/db/trial_end.hpp"

namespace arena::orchestrator {

// What a cell is doing, as the driver sees it.
enum class CellPhase { kIdle, kExecuting, kResetting };

// The phase a cell's status is about (msg::Phase).
enum class StatusPhase { kExecute, kReset };

// A cell's status (msg::TrialState).
enum class StatusState { kAccepted, kExecuted, kResetDone, kRefused, kFailed };

// Why a phase FAILED, as the cell typed it (msg::FailureKind).
enum class FailureKind {
  kNone,         // untyped (an older cell)
  kSimulation,   // the cell's simulator cannot run the scene; a re-run is identical
  kDeadline,     // the cell saw the phase's deadline pass
  kInterrupted,  // the cell is shutting down or now serves another service
  kReset,        // the reset did not reach its target
  kInternal,     // a bug, a DDS failure or a failed backend (driver, hardware) in the cell
  kController,   // the closed loop's controller: gone, silent past its hold time, a bad command
};

// What the service itself observed about a cell's phase.
enum class ServiceEvent {
  kDeadlineMissed,     // no final status by the phase's deadline (+ 2 s)
  kStreamIncomplete,   // EXECUTED, but the ground truth did not all arrive in time
  kStreamMalformed,    // a batch out of order, a bad value in a sample
  kCommandNotSent,     // the service could not send the phase's command
  kStoreRefusedTruth,  // the store refused the ground truth (not a busy store: that waits)
  kCellLost,           // its participant or writer went away
  kCellRestarted,      // a new process with its id announced itself
  kCellServesAnother,  // it now serves another service (or nobody)
  kInvalidScene,       // the claimed trial's scene does not parse (found before dispatch)
};

// Whom a failure is counted against.
enum class Party { kNobody, kCell, kController, kService, kStore, kScene };

// What happens to the trial of the phase.
enum class TrialStep {
  kIgnore,         // a late or repeated message of a phase already settled: nothing
  kAwait,          // the phase goes on (ACCEPTED)
  kCollectStream,  // EXECUTED: wait for the rest of the ground truth, then publish it
  kRetry,          // the attempt ended: RetryTrial (the retry rule decides run again / fail)
  kFail,           // the trial fails now, with `outcome`
  kResetDone,      // CompleteReset ok
  kResetFailed,    // CompleteReset not ok (not observed)
};

struct Decision {
  TrialStep trial = TrialStep::kIgnore;
  Party blame = Party::kNobody;                // kCell: counts towards quarantine
  bool back_off = false;                       // the cell waits CellBackoff_s before its next trial
  double pause_s = 0;                          // or (a refusal) this fixed pause
  db::TrialEnd outcome = db::TrialEnd::kNone;  // kFail: the trial's outcome
  const char* rule = "";                       // the rule's name ("execute.controller_fault")

  bool counts_against_cell() const { return blame == Party::kCell; }
  bool ends_phase() const { return trial != TrialStep::kIgnore && trial != TrialStep::kAwait; }
};

// A status of the cell's current (trial, attempt), while the cell is in `phase`.
Decision DecideStatus(CellPhase phase, StatusPhase status_phase, StatusState state,
                      FailureKind failure);

// Something the service observed while the cell is in `phase`.
Decision DecideServiceEvent(CellPhase phase, ServiceEvent event);

// A message (status, ground truth) that names another service session, or
// another trial or attempt than the cell's current one, or arrives while the
// cell is idle: a late or repeated message of a phase already settled.
// nullptr: it is current; otherwise the rule that drops it.
const char* LateMessageRule(bool our_session, CellPhase phase, bool same_trial_and_attempt);

// ## The RESET ahead of the publish (issue 27)
//
// A cell's RESET goes out before the publish of the stream it follows
// commits, so the cell resets while the commit runs. The store moves a trial
// to resetting only with that publish (executed first: store.hpp), so until
// the publish ends the reset is the cell's, not yet the trial's: nothing of
// it may be recorded for the trial before the publish committed.
enum class AheadEvent {
  kResetStatus,       // a status of that reset comes while the publish has not ended
  kPublishCommitted,  // the publish committed: the trial is resetting
  kPublishRefused,    // the store refused the publish (the attempt ends by its own rule)
  kAttemptEnded,      // the attempt ended otherwise first (cell lost, restarted, claimed)
};
enum class AheadStep {
  kHold,      // the status waits for the publish; nothing is recorded yet
  kTakeHeld,  // the reset is the trial's: held statuses are decided now, as any reset's
  kRunOut,    // the cell stays resetting for no trial: its (held or next) status or its
              // deadline frees it, counted and backed off as any reset's; nothing of it
              // is written for the trial, which ended by the refusal's rule
  kDropHeld,  // the cell's phase ends by the event's own rule; held statuses are dropped
};
struct AheadDecision {
  AheadStep step = AheadStep::kDropHeld;
  const char* rule = "";
};
AheadDecision DecideResetAhead(AheadEvent event);

// ## The next trial queued behind the reset (issue 27)
//
// Right after a cell's RESET goes out, the service claims the trial that
// reset is aimed at and sends its EXECUTE at once, marked to run only right
// after that reset ended done (TrialCommand.after_reset_*): the cell goes
// from its reset straight into its next trial, without waiting for the
// service to take the reset's status, claim and send. Until the reset's
// status is taken the queued trial is not the cell's phase: its statuses
// wait, and the reset's outcome decides whether it runs.
enum class QueuedEvent {
  kOwnStatus,       // a status of the queued trial comes before its reset's status was taken
  kResetDone,       // the reset ended done: the cell is running the queued trial
  kResetFailed,     // the reset failed or was refused: the cell refuses the queued trial
  kPublishRefused,  // the publish before it was refused: the reset still runs out, then it
  kPhaseEnded,      // the cell's phase ended otherwise (lost, restarted, serves another,
                    // deadline, a command not sent, a bad stream before it)
  kNotSent,         // its EXECUTE could not be sent
  kTruthRefused,    // the store refused its ingest
};
enum class QueuedStep {
  kHold,     // the status waits until the reset's status was taken
  kRun,      // the queued trial becomes the cell's phase (executing) now
  kKeep,     // it stays queued: the cell still runs it after the reset
  kRelease,  // the cell never runs it (or not for us): back to planned, the
             // attempt not counted (TrialStore::ReleaseTrial); nobody is blamed
};
struct QueuedDecision {
  QueuedStep step = QueuedStep::kRelease;
  const char* rule = "";
};
QueuedDecision DecideQueued(QueuedEvent event);
// The audit rule of the queued trial's claim (planned -> dispatched).
inline constexpr const char* kQueuedClaimRule = "queued.claimed_behind_reset";

// A prediction came back for (trial, attempt).
enum class PredictionStep {
  kDrop,                  // the trial moved on (another attempt): the prediction is stale
  kWaitForReset,          // its reset is still running: recorded when the reset ends
  kCloseResetThenRecord,  // nobody resets it any more: close the reset as not observed, record
  kRecord,                // record it, then finish the trial
};
struct PredictionDecision {
  PredictionStep step = PredictionStep::kRecord;
  const char* rule = "";
};
// `awaiting_reset`: the trial is in executed or resetting.
PredictionDecision DecidePrediction(bool same_attempt, bool awaiting_reset, bool reset_in_flight);

// Why a reset begins (the rule on its audit row).
inline constexpr const char* kResetAfterExecute = "reset.after_execute";
inline constexpr const char* kResetAfterRestart = "reset.after_restart";
inline constexpr const char* kResetUnconfirmedAtPrediction = "reset.unconfirmed_at_prediction";

// How long a cell waits before its next trial after `failures_in_a_row`
// (>= 1) failed phases, whoever caused them: base_s doubling per failure,
// at most max_s. A refused trial waits kRefusedPause_s (another cell may take it).
double CellBackoff_s(int failures_in_a_row, double base_s, double max_s);
inline constexpr double kRefusedPause_s = 0.5;

const char* ToString(CellPhase phase);
const char* ToString(StatusPhase phase);
const char* ToString(StatusState state);
const char* ToString(FailureKind kind);
const char* ToString(ServiceEvent event);
const char* ToString(Party party);
const char* ToString(TrialStep step);
const char* ToString(AheadEvent event);
const char* ToString(QueuedEvent event);
const char* ToString(QueuedStep step);
const char* ToString(AheadStep step);

}  // namespace arena::orchestrator
