// The service's trial lifecycle, without DDS, SQLite or a real clock: events in
// (a cell announced / lost / a status / a ground-truth batch / a prediction /
// a tick), actions out through three ports (the store's trial steps, the
// command transport, the predictor). Service (service.hpp) is the thin shell
// that owns the DDS endpoints, the SQLite store and the predictor threads and
// feeds this driver; tests drive it with a fake clock, transport and store.
// Every decision about a trial (retry, fail, blame the cell, back off, begin
// or close a reset, drop a late message) is a rule of trial_policy.hpp; the
// driver executes it and writes the rule's name to the trial's audit row.
//
// ## One cell, as the driver sees it (one function, SetPhase, changes it)
//
//   announced ──claim sent──▶ (serving us? per the cell's announce)
//        │                          │ yes
//        │                          ▼            ClaimNextTrial
//        │  ┌──────────────────▶  idle ──────────────────────────▶ executing
//        │  │                       ▲                                 │
//        │  │   status RESET_DONE/  │ CompleteReset                   │ all samples +
//        │  │   FAILED, deadline ───┘                                 │ EXECUTED:
//        │  │                    resetting ◀──── BeginReset ──────────┘ Ingest::Finish
//        │  │                                                         │
//        │  └── REFUSED / FAILED / malformed stream / deadline ───────┘ RetryTrial|FailTrial
//        │      (trial_policy.hpp decides which, whom to blame, the backoff)
//        ▼
//   lost (liveliness, participant gone): phase aborted, cell `gone`; back on
//   its next announce, its liveliness, or when another process with its id is
//   still there (a restart within the lease).
//
// The trial's path (issue 27): a clean RESET_DONE is answered by the cell's
// next EXECUTE (Tick's dispatch) before its CompleteReset, its fixture
// changes and the periodic writes (Tick's background); the EXECUTE goes out
// before BeginIngest (a busy store: the stream is ingested whole at its end);
// the RESET goes out before the publish's commit (Ingest::Finish +
// BeginReset), so the cell resets while it runs. Until that commit the
// reset is not the trial's (DecideResetAhead, trial_policy.hpp): a status of
// it is held and taken once the publish committed; a refused publish ends
// the attempt by its own rule and the cell, still resetting for no trial,
// is freed by that reset's status or deadline, nothing of it recorded.
// Right after that RESET the trial it is aimed at is claimed and its EXECUTE
// sent too (DriverOptions::queue_next_execute; DecideQueued): the cell runs
// it right after the reset ended done, the driver takes its statuses only
// after the reset's, and releases it (back to planned, not counted) when the
// reset fails or the cell's phase ends otherwise first.
//
// A cell serves one service session at a time (TrialCommand PHASE_CLAIM,
// renewed every claim_period_s while we live): the driver dispatches only to
// cells whose announce names our session; a cell serving another service is
// written to the store as "serving service S on host H" for `arena status`.
// Statuses and ground truth of another session are dropped.
//
// ## One policy for store errors (StorePolicy)
//
//   kBusy (the write lock is held elsewhere)  -> the SAME step is retried
//       after a backoff (50 ms doubling to 2 s); the trial and the cell stay
//       where they are (deadlines of a trial waiting on the store are held)
//   kFull, kIo, kCorrupt, kReadOnly, kTooNew  -> Stop: Tick() throws that
//       db::StoreError; `arena serve` exits 3. Nothing half-done is left
//       behind: every step is one transaction and a restart resumes.
//   other kinds (stale attempt, illegal edge, not found, bad input)
//       -> that step is moot (a late message, an operator's cancel); logged.
//
// ## Resume (a restarted service)
//
//   RecoverAfterRestart (dispatched -> planned+1, resetting -> reset_failed),
//   then ListTrialsByState(executed, reset_done, reset_failed, predicted)
//   and each goes through the same steps as the live path. A service killed
//   after a RESET went out and before its publish committed left the trial
//   dispatched (its stream unpublished): it is re-queued, as a trial killed
//   before its publish always was; the cell's status goes to a dead session.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "arena/assessment/prediction.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/service.hpp"
#include "arena/orchestrator/trial_policy.hpp"
#include "arena/schemas/arena.h"

namespace arena::orchestrator {

using DriverClock = std::chrono::steady_clock;

// The ground truth of one (trial, attempt) being written (db::Ingest in production).
class GroundTruthSink {
 public:
  virtual ~GroundTruthSink() = default;
  virtual void Add(const std::vector<db::Sample>& samples) = 0;
  virtual void Poll() = 0;
  // Publishes the stream and moves the trial to executed; @returns samples stored.
  virtual std::int64_t Finish() = 0;
};

// The store steps the driver takes (db::Store in production). Every call is
// one transaction; a db::StoreError says what went wrong.
class TrialStore {
 public:
  virtual ~TrialStore() = default;
  virtual db::RecoveryReport RecoverAfterRestart() = 0;
  virtual std::vector<db::Trial> ListTrialsByState(const std::vector<db::TrialState>& states) = 0;
  virtual db::Trial GetTrial(std::int64_t trial_id) = 0;
  virtual std::optional<db::ClaimedTrial> ClaimNextTrial(const std::string& cell_id) = 0;
  virtual std::optional<db::ClaimedTrial> PeekNextTrial(const std::string& cell_id) = 0;
  // `sites`: the trial's contacts (ContactSitesOf its scene), for the outcomes stored at ingest.
  virtual std::unique_ptr<GroundTruthSink> BeginIngest(std::int64_t trial_id, int attempt,
                                                       std::vector<db::ContactSite> sites) = 0;
  // `rule` (these four): the trial policy's rule that decided the step
  // (trial_policy.hpp), for the audit row. RetryTrial applies db::DecideRetry
  // (db/retry_rule.hpp), as every implementation must.
  virtual db::TrialState RetryTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                                    int max_attempts, double backoff_s,
                                    const std::string& rule) = 0;
  // dispatched -> planned (+1), the attempt not counted and no backoff
  // (db::Store::ReleaseTrial): an EXECUTE queued behind a reset that never
  // ran it.
  virtual void ReleaseTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                            const std::string& rule) = 0;
  virtual void FailTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                         db::TrialEnd outcome, const std::string& rule) = 0;
  virtual void BeginReset(std::int64_t trial_id, int attempt, const std::string& rule) = 0;
  // Publishes the stream (sink.Finish) with, in the same step, the trial's
  // execution record before it (`also.execution`) and its move to resetting
  // after it (`also.begin_reset_rule`): one transaction in production, so one
  // commit on the trial's path where there were three; a refusal of any part
  // refuses all. The default runs the parts one after another.
  virtual std::int64_t PublishExecuted(GroundTruthSink& sink, std::int64_t trial_id, int attempt,
                                       const db::FinishAlso& also);
  virtual void CompleteReset(std::int64_t trial_id, int attempt, const db::ResetReport& report,
                             const std::string& rule) = 0;
  // RecordPrediction then FinishTrial (each its own transaction; both idempotent enough
  // to be retried: a prediction of the same model_key replaces the previous one).
  virtual void RecordPrediction(std::int64_t trial_id, int attempt, const db::Prediction& p) = 0;
  virtual void FinishTrial(std::int64_t trial_id, int attempt) = 0;
  // Both in one transaction in production (one commit per clean trial less);
  // the default runs them one after another.
  virtual void RecordPredictionAndFinish(std::int64_t trial_id, int attempt,
                                         const db::Prediction& p) {
    RecordPrediction(trial_id, attempt, p);
    FinishTrial(trial_id, attempt);
  }
  // What executed the trial: backend, its kind of truth, the defects applied.
  virtual void RecordExecution(std::int64_t trial_id, int attempt, const std::string& backend,
                               const std::string& truth, const std::string& defects_applied) = 0;
  // Closed loop (issue 19): the commands a cell applied and the controller's
  // outcome, for one attempt (replaces that attempt's earlier record).
  virtual void RecordClosedLoop(const db::ClosedLoopRun& run) = 0;
  virtual void UpsertCell(const std::string& cell_id, const std::vector<std::string>& contact_types,
                          const std::string& capabilities_json,
                          const std::string& defects_json) = 0;
  virtual bool CellQuarantined(const std::string& cell_id) = 0;
  virtual int RecordCellResult(const std::string& cell_id, bool ok) = 0;
  virtual void QuarantineCell(const std::string& cell_id, const std::string& reason) = 0;
  virtual void MarkCellGone(const std::string& cell_id, const std::string& reason) = 0;
  virtual void SetCellServing(const std::string& cell_id, double lease_s,
                              const std::string& serving) = 0;
  // Marks finished campaigns done; @returns whether every campaign (or `only`) is over.
  virtual bool CompleteFinishedCampaigns(std::int64_t only) = 0;
  virtual void ServiceBeat(const std::vector<std::string>& cells_alive) = 0;
  // @throws StoreError(kIo) when the file was deleted, renamed or replaced.
  virtual void CheckFileIdentity() = 0;
  // Change-aware scheduling (issue 29, claim_chooser.hpp). The defaults are a
  // store without it (the tests' fakes): an empty window, so every cell
  // claims in plan order through ClaimNextTrial, and no changes recorded.
  virtual std::vector<db::ClaimedTrial> ClaimWindow(const std::string& /*cell_id*/, int /*limit*/) {
    return {};
  }
  virtual std::optional<db::ClaimedTrial> ClaimTrial(const std::string& /*cell_id*/,
                                                     std::int64_t /*trial_id*/,
                                                     const std::string& /*rule*/) {
    return std::nullopt;
  }
  // The campaign's seed and stored document (its "scheduling" block).
  virtual db::Campaign GetCampaign(std::int64_t campaign_id) {
    db::Campaign c;
    c.id = campaign_id;
    return c;
  }
  virtual void RecordFixtureChanges(const std::vector<db::FixtureChangeRecord>& /*changes*/) {}
  // The claim gate (issue 26, claim_gate.hpp). The defaults are a store
  // without it (the tests' fakes): nothing planned to gate, nothing waits.
  virtual std::vector<db::PlannedNeed> PlannedNeeds() { return {}; }
  virtual void SetCampaignWait(std::int64_t /*campaign_id*/, const std::string& /*kind*/,
                               const std::string& /*reason*/, const std::string& /*rule*/) {}
  virtual void ClearCampaignWait(std::int64_t /*campaign_id*/) {}
  virtual std::vector<db::CampaignWait> ListCampaignWaits() { return {}; }
  // db::Store::RestrictClaimsTo and ActiveCampaignIds: the claims take only
  // from campaigns the gate decided open.
  virtual void RestrictClaimsTo(std::optional<std::vector<std::int64_t>> /*campaigns*/) {}
  virtual std::vector<std::int64_t> ActiveCampaignIds() { return {}; }
};

// Sends commands to cells (the DDS TrialCommand writer in production).
class CommandTransport {
 public:
  virtual ~CommandTransport() = default;
  // @returns false when the command could not be sent.
  virtual bool Send(msg::TrialCommand& command) = 0;
};

// What the driver asks of the predictor (worker threads in production).
struct PredictionRequest {
  std::int64_t trial_id = 0, campaign_id = 0;
  int attempt = 0;
  mechanics::Scene scene;  // the trial's scene (the shell applies the campaign's model)
  // The true trajectory; empty: read it from the store (a resumed trial).
  std::vector<mechanics::TrajectorySample> truth;
  std::string scene_json;
  // Closed loop (issue 19): the commands the cell applied, replayed through
  // the model; empty: an open-loop trial, or (a resumed trial) read them
  // from the store.
  assessment::RecordedCommands commands;
  // The first sample of the cell's stream: the start pose it measured, which
  // the prediction starts from (issue 26); absent: read it from the store.
  std::optional<db::Sample> first_sample;
};

struct PredictionDone {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::int64_t campaign_id = 0;
  db::Prediction prediction;
};

class PredictionPort {
 public:
  virtual ~PredictionPort() = default;
  virtual void Start(PredictionRequest request) = 0;
  virtual int outstanding() const = 0;
};

// What the driver sees of each trial that a watcher of the campaign's health
// needs (the suspenders, suspenders.hpp), and the one dispatch gate: asked
// for every idle cell right before its claim.
class TrialObserver {
 public:
  virtual ~TrialObserver() = default;
  virtual void OnReset(const std::string& cell_id, std::int64_t campaign_id, bool ok,
                       bool pose_observed, double position_error_m) = 0;
  virtual void OnStream(const std::string& cell_id, std::int64_t campaign_id, std::int64_t samples,
                        std::int64_t dropped) = 0;
  // A closed-loop attempt: its samples and those held (no fresh command in time).
  virtual void OnClosedLoop(const std::string& cell_id, std::int64_t campaign_id,
                            std::int64_t samples, std::int64_t held) = 0;
  virtual void OnCellAlive(const std::string& cell_id, bool alive) = 0;
  // nullptr: the cell may claim a trial now; otherwise the rule that holds it back.
  virtual const char* DispatchGate(const std::string& cell_id) = 0;
};

// Who this service is, as cells and other services see it.
struct ServiceIdentity {
  std::uint64_t session = 0;
  std::string host;
  std::uint32_t pid = 0;
  std::string store_id;
};

struct DriverOptions {
  ServiceOptions service;
  double claim_lease_s = 10.0;   // a cell serves us this long without renewal
  double claim_period_s = 1.0;   // we renew (and claim free cells) this often
  double beat_period_s = 1.0;    // the store heartbeat
  double cell_lease_s = 10.0;    // `status` shows a cell gone after this long without a sign
  double dispatch_poll_s = 0.2;  // an idle cell asks the store for work this often
  // Issue 27: a cell's next trial is claimed and its EXECUTE sent right after
  // its RESET, for the cell to run right after that reset ended done
  // (trial_policy.hpp QueuedEvent). The service turns it on; off, the
  // dispatch claims only for idle cells (the driver's tests of that path).
  bool queue_next_execute = false;
};

class TrialDriver {
 public:
  TrialDriver(DriverOptions options, ServiceIdentity me, TrialStore& store,
              CommandTransport& transport, PredictionPort& predictions,
              std::function<DriverClock::time_point()> now = DriverClock::now);
  ~TrialDriver();
  TrialDriver(const TrialDriver&) = delete;
  TrialDriver& operator=(const TrialDriver&) = delete;

  // Start-up: recovery and the trials a previous service left unfinished.
  void Resume();

  // ---- events
  void OnAnnounce(const msg::CellAnnounce& announce);
  // A cell's participant or writer went away. `another_process` is true when
  // another participant with the cell's id is still there (it was restarted).
  void OnCellLost(const std::string& cell_id, const std::string& reason, bool another_process);
  void OnCellAlive(const std::string& cell_id);
  void OnStatus(const msg::TrialStatus& status);
  void OnGroundTruth(const msg::GroundTruth& batch);
  void OnPrediction(PredictionDone done);
  // Deadlines, store steps waiting after a busy store, claims, heartbeat,
  // dispatch. `stopping`: no new trials. @throws db::StoreError (fatal kinds).
  void Tick(bool stopping);

  // ---- state
  bool InFlight() const;
  // Cells alive, serving us, not quarantined and idle (an adaptive batch's size).
  int IdleCells() const;
  // Every campaign (or options.only_campaign) is over; marks finished campaigns done.
  bool CampaignsFinished();
  ServiceCounters counters() const;
  void OnTrialTiming(std::function<void(const TrialTiming&)> callback);
  // Called with (cell, true) when the service takes the status that ended a
  // cell's phase, (cell, false) when it hands the cell its next phase or
  // leaves it idle: the trials' path, which the predictor yields to
  // (predictor_yield.hpp).
  void OnPathChange(std::function<void(const std::string& cell_id, bool on_path)> callback);
  // True while an input (a status, ground truth) waits to be taken: Tick's
  // writes that no cell waits on then yield to it. None: they never yield.
  void OnInputWaiting(std::function<bool()> waiting);
  // Store steps waiting for a busy store to free up.
  std::size_t pending_store_steps() const;
  // The suspenders (or nullptr): fed every reset, stream, closed loop and
  // cell liveness; asked before every claim. Not owned.
  void SetObserver(TrialObserver* observer);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// "1a2b3c4d5e6f7a8b": a session as the store and status show it.
std::string SessionHex(std::uint64_t session);

}  // namespace arena::orchestrator
