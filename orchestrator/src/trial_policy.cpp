// The trial policy's rules; the contract and the blame table are in trial_policy.hpp.
#include "arena/orchestrator/trial_policy.hpp"

#include <algorithm>
#include <cmath>

namespace arena::orchestrator {
namespace {

Decision Ignore(const char* rule) {
  return {TrialStep::kIgnore, Party::kNobody, false, 0, db::TrialEnd::kNone, rule};
}
Decision Await(const char* rule) {
  return {TrialStep::kAwait, Party::kNobody, false, 0, db::TrialEnd::kNone, rule};
}
// The attempt ended and `blame` caused it; the cell backs off unless nobody is to blame.
Decision Retry(Party blame, const char* rule) {
  return {TrialStep::kRetry, blame, blame != Party::kNobody, 0, db::TrialEnd::kNone, rule};
}
Decision ResetFailed(Party blame, const char* rule) {
  return {TrialStep::kResetFailed, blame, blame != Party::kNobody, 0, db::TrialEnd::kNone, rule};
}

Decision ExecuteFailed(FailureKind failure) {
  switch (failure) {
    case FailureKind::kSimulation:
      // The cell is fine and a re-run is bit-identical: the trial fails at once.
      return {TrialStep::kFail,
              Party::kScene,
              false,
              0,
              db::TrialEnd::kSolverFailure,
              "execute.simulation_failure"};
    case FailureKind::kController:
      return Retry(Party::kController, "execute.controller_fault");
    case FailureKind::kDeadline:
      return Retry(Party::kCell, "execute.cell_deadline");
    case FailureKind::kInterrupted:
      return Retry(Party::kCell, "execute.cell_interrupted");
    case FailureKind::kReset:
      return Retry(Party::kCell, "execute.cell_failure_typed_as_reset");
    case FailureKind::kInternal:
      return Retry(Party::kCell, "execute.cell_failure");
    case FailureKind::kNone:
      break;
  }
  return Retry(Party::kCell, "execute.cell_failure_untyped");
}

Decision ExecuteStatus(StatusState state, FailureKind failure) {
  switch (state) {
    case StatusState::kAccepted:
      return Await("execute.accepted");
    case StatusState::kExecuted:
      return {TrialStep::kCollectStream, Party::kNobody,    false, 0,
              db::TrialEnd::kNone,       "execute.executed"};
    case StatusState::kRefused:
      // The cell cannot host it (workspace, contact types, defects): not a
      // failure of anyone's; another cell may take it after a short pause.
      return {TrialStep::kRetry, Party::kNobody,      false,
              kRefusedPause_s,   db::TrialEnd::kNone, "execute.refused_by_cell"};
    case StatusState::kFailed:
      return ExecuteFailed(failure);
    case StatusState::kResetDone:
      break;
  }
  return Ignore("late.state_of_another_phase");
}

Decision ResetStatus(StatusState state) {
  switch (state) {
    case StatusState::kAccepted:
      return Await("reset.accepted");
    case StatusState::kResetDone:
      return {TrialStep::kResetDone, Party::kNobody,  false, 0,
              db::TrialEnd::kNone,   "reset.verified"};
    case StatusState::kFailed:
      return ResetFailed(Party::kCell, "reset.failed");
    case StatusState::kRefused:
      // The cell cannot aim at the next trial's start: its deadline ends the phase.
      return Ignore("reset.refused_waits_for_deadline");
    case StatusState::kExecuted:
      break;
  }
  return Ignore("late.state_of_another_phase");
}

}  // namespace

Decision DecideStatus(CellPhase phase, StatusPhase status_phase, StatusState state,
                      FailureKind failure) {
  if (phase == CellPhase::kIdle) return Ignore("late.cell_idle");
  if (phase == CellPhase::kExecuting && status_phase == StatusPhase::kExecute)
    return ExecuteStatus(state, failure);
  if (phase == CellPhase::kResetting && status_phase == StatusPhase::kReset)
    return ResetStatus(state);
  return Ignore("late.status_of_another_phase");
}

Decision DecideServiceEvent(CellPhase phase, ServiceEvent event) {
  if (event == ServiceEvent::kInvalidScene)  // before any phase: the trial cannot run anywhere
    return {TrialStep::kFail,        Party::kScene, false, 0, db::TrialEnd::kInvalidScene,
            "dispatch.invalid_scene"};
  if (phase == CellPhase::kExecuting) {
    switch (event) {
      case ServiceEvent::kDeadlineMissed:
        return Retry(Party::kCell, "execute.deadline_missed");
      case ServiceEvent::kStreamIncomplete:
        return Retry(Party::kCell, "execute.stream_incomplete");
      case ServiceEvent::kStreamMalformed:
        return Retry(Party::kCell, "execute.stream_malformed");
      case ServiceEvent::kCommandNotSent:
        return Retry(Party::kService, "execute.command_not_sent");
      case ServiceEvent::kStoreRefusedTruth:
        return Retry(Party::kStore, "execute.store_refused_truth");
      case ServiceEvent::kCellLost:
        return Retry(Party::kNobody, "execute.cell_lost");
      case ServiceEvent::kCellRestarted:
        return Retry(Party::kNobody, "execute.cell_restarted");
      case ServiceEvent::kCellServesAnother:
        return Retry(Party::kNobody, "execute.cell_claimed_elsewhere");
      case ServiceEvent::kInvalidScene:
        break;
    }
  } else if (phase == CellPhase::kResetting) {
    switch (event) {
      case ServiceEvent::kDeadlineMissed:
        return ResetFailed(Party::kCell, "reset.deadline_missed");
      case ServiceEvent::kCommandNotSent:
        return ResetFailed(Party::kService, "reset.command_not_sent");
      case ServiceEvent::kCellLost:
        return ResetFailed(Party::kNobody, "reset.cell_lost");
      case ServiceEvent::kCellRestarted:
        return ResetFailed(Party::kNobody, "reset.cell_restarted");
      case ServiceEvent::kCellServesAnother:
        return ResetFailed(Party::kNobody, "reset.cell_claimed_elsewhere");
      case ServiceEvent::kStreamIncomplete:
      case ServiceEvent::kStreamMalformed:
      case ServiceEvent::kStoreRefusedTruth:
      case ServiceEvent::kInvalidScene:
        return Ignore("late.stream_event_in_reset");
    }
  }
  return Ignore("late.cell_idle");
}

const char* LateMessageRule(bool our_session, CellPhase phase, bool same_trial_and_attempt) {
  if (!our_session) return "late.other_session";
  if (phase == CellPhase::kIdle) return "late.cell_idle";
  if (!same_trial_and_attempt) return "late.other_trial_or_attempt";
  return nullptr;
}

AheadDecision DecideResetAhead(AheadEvent event) {
  switch (event) {
    case AheadEvent::kResetStatus:
      return {AheadStep::kHold, "reset.held_until_published"};
    case AheadEvent::kPublishCommitted:
      return {AheadStep::kTakeHeld, "reset.ahead_of_committed_publish"};
    case AheadEvent::kPublishRefused:
      // The cell was told to reset and does: it is freed by that reset, not
      // sent a trial while it still moves the object.
      return {AheadStep::kRunOut, "reset.ahead_of_refused_publish"};
    case AheadEvent::kAttemptEnded:
      break;
  }
  return {AheadStep::kDropHeld, "reset.ahead_of_ended_attempt"};
}

QueuedDecision DecideQueued(QueuedEvent event) {
  switch (event) {
    case QueuedEvent::kOwnStatus:
      return {QueuedStep::kHold, "queued.held_until_reset_taken"};
    case QueuedEvent::kResetDone:
      return {QueuedStep::kRun, "queued.runs_after_reset_done"};
    case QueuedEvent::kResetFailed:
      // The cell refuses it (executors' ResetGate): never a push from a failed reset.
      return {QueuedStep::kRelease, "queued.behind_failed_reset"};
    case QueuedEvent::kPublishRefused:
      // The cell resets anyway (reset.ahead_of_refused_publish) and then runs it.
      return {QueuedStep::kKeep, "queued.runs_after_run_out_reset"};
    case QueuedEvent::kPhaseEnded:
      return {QueuedStep::kRelease, "queued.cell_phase_ended"};
    case QueuedEvent::kNotSent:
      return {QueuedStep::kRelease, "queued.command_not_sent"};
    case QueuedEvent::kTruthRefused:
      break;
  }
  return {QueuedStep::kRelease, "queued.truth_refused"};
}

PredictionDecision DecidePrediction(bool same_attempt, bool awaiting_reset, bool reset_in_flight) {
  if (!same_attempt) return {PredictionStep::kDrop, "predict.stale_attempt"};
  if (awaiting_reset && reset_in_flight)
    return {PredictionStep::kWaitForReset, "predict.wait_for_reset"};
  if (awaiting_reset) return {PredictionStep::kCloseResetThenRecord, kResetUnconfirmedAtPrediction};
  return {PredictionStep::kRecord, "predict.record"};
}

double CellBackoff_s(int failures_in_a_row, double base_s, double max_s) {
  if (failures_in_a_row < 1 || !(base_s > 0)) return 0;
  const double b = base_s * std::pow(2.0, std::min(failures_in_a_row - 1, 30));
  return std::min(b, max_s);
}

const char* ToString(CellPhase p) {
  switch (p) {
    case CellPhase::kIdle:
      return "idle";
    case CellPhase::kExecuting:
      return "executing";
    case CellPhase::kResetting:
      return "resetting";
  }
  return "?";
}
const char* ToString(StatusPhase p) { return p == StatusPhase::kExecute ? "EXECUTE" : "RESET"; }
const char* ToString(StatusState s) {
  switch (s) {
    case StatusState::kAccepted:
      return "ACCEPTED";
    case StatusState::kExecuted:
      return "EXECUTED";
    case StatusState::kResetDone:
      return "RESET_DONE";
    case StatusState::kRefused:
      return "REFUSED";
    case StatusState::kFailed:
      return "FAILED";
  }
  return "?";
}
const char* ToString(FailureKind k) {
  switch (k) {
    case FailureKind::kNone:
      return "none";
    case FailureKind::kSimulation:
      return "simulation";
    case FailureKind::kDeadline:
      return "deadline";
    case FailureKind::kInterrupted:
      return "interrupted";
    case FailureKind::kReset:
      return "reset";
    case FailureKind::kInternal:
      return "internal";
    case FailureKind::kController:
      return "controller";
  }
  return "?";
}
const char* ToString(ServiceEvent e) {
  switch (e) {
    case ServiceEvent::kDeadlineMissed:
      return "deadline missed";
    case ServiceEvent::kStreamIncomplete:
      return "stream incomplete";
    case ServiceEvent::kStreamMalformed:
      return "stream malformed";
    case ServiceEvent::kCommandNotSent:
      return "command not sent";
    case ServiceEvent::kStoreRefusedTruth:
      return "store refused truth";
    case ServiceEvent::kCellLost:
      return "cell lost";
    case ServiceEvent::kCellRestarted:
      return "cell restarted";
    case ServiceEvent::kCellServesAnother:
      return "cell serves another";
    case ServiceEvent::kInvalidScene:
      return "invalid scene";
  }
  return "?";
}
const char* ToString(Party p) {
  switch (p) {
    case Party::kNobody:
      return "nobody";
    case Party::kCell:
      return "cell";
    case Party::kController:
      return "controller";
    case Party::kService:
      return "service";
    case Party::kStore:
      return "store";
    case Party::kScene:
      return "scene";
  }
  return "?";
}
const char* ToString(TrialStep s) {
  switch (s) {
    case TrialStep::kIgnore:
      return "ignore";
    case TrialStep::kAwait:
      return "await";
    case TrialStep::kCollectStream:
      return "collect stream";
    case TrialStep::kRetry:
      return "retry";
    case TrialStep::kFail:
      return "fail";
    case TrialStep::kResetDone:
      return "reset done";
    case TrialStep::kResetFailed:
      return "reset failed";
  }
  return "?";
}

const char* ToString(AheadEvent e) {
  switch (e) {
    case AheadEvent::kResetStatus:
      return "reset status";
    case AheadEvent::kPublishCommitted:
      return "publish committed";
    case AheadEvent::kPublishRefused:
      return "publish refused";
    case AheadEvent::kAttemptEnded:
      return "attempt ended";
  }
  return "?";
}
const char* ToString(QueuedEvent e) {
  switch (e) {
    case QueuedEvent::kOwnStatus:
      return "own status";
    case QueuedEvent::kResetDone:
      return "reset done";
    case QueuedEvent::kResetFailed:
      return "reset failed";
    case QueuedEvent::kPublishRefused:
      return "publish refused";
    case QueuedEvent::kPhaseEnded:
      return "phase ended";
    case QueuedEvent::kNotSent:
      return "not sent";
    case QueuedEvent::kTruthRefused:
      return "truth refused";
  }
  return "?";
}
const char* ToString(QueuedStep s) {
  switch (s) {
    case QueuedStep::kHold:
      return "hold";
    case QueuedStep::kRun:
      return "run";
    case QueuedStep::kKeep:
      return "keep";
    case QueuedStep::kRelease:
      return "release";
  }
  return "?";
}
const char* ToString(AheadStep s) {
  switch (s) {
    case AheadStep::kHold:
      return "hold";
    case AheadStep::kTakeHeld:
      return "take held";
    case AheadStep::kRunOut:
      return "run out";
    case AheadStep::kDropHeld:
      return "drop held";
  }
  return "?";
}

}  // namespace arena::orchestrator
