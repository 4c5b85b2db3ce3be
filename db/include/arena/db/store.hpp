// arena's store: campaigns, trials, their state machine, ground truth,
// predictions and cells in one SQLite file (WAL). db/README.md documents
// every table and column; this header is the API the service and the CLI use.
//
// ## Contract
//
// * One `Store` is one SQLite connection. It is NOT thread-safe: use one
//   Store per thread (several Stores, in several threads or processes, on the
//   same file are fine: SQLite's locking serialises writers, WAL lets readers
//   run beside the writer). An `Ingest` borrows its Store and must not
//   outlive it.
// * Every public write is one SQLite transaction: it happens entirely or not
//   at all. Writes use BEGIN IMMEDIATE, so two writers never deadlock; a
//   writer waits up to `busy_timeout_ms` for the lock, then throws kBusy.
// * Misuse and bad input throw `StoreError` whose message starts with the
//   function's name; nothing is written in that case.
//
// ## Invariants (checked by the code that writes them, tested in tests/db)
//
// 1. A trial's state changes only along the edges drawn below, each edge by
//    exactly one function (table below), and each change writes one row to
//    `trial_transitions` in the same transaction.
// 2. A trial's `attempt` only grows; a call naming another attempt than the
//    trial's current one is refused (kStaleAttempt): late messages from an
//    earlier attempt cannot move a trial.
// 3. A trial's ground truth becomes visible (trials.gt_stream_id set) in the
//    same transaction that moves it to `executed`; a reader that follows
//    trials.gt_stream_id never sees a half-written stream.
// 4. Re-ingesting a (trial, attempt) replaces its stream; there is at most
//    one stream per (trial, attempt) with complete = 1.
// 5. No NaN or infinity is ever stored: inputs are checked and refused.
//
// ## Trial state machine
//
//                 ClaimNextTrial                Ingest::Finish
//    planned ─────────────────────▶ dispatched ───────────────▶ executed
//      ▲  │                            │  │                        │
//      │  │ CancelCampaign   RetryTrial│  │FailTrial       BeginReset
//      │  ▼                 (attempt+1)│  ▼                        ▼
//      │ cancelled                     │ failed ◀── FailTrial ── resetting ◀──┐
//      └───────────────────────────────┘  (from any non-terminal)  │   │      │BeginReset
//         also RecoverAfterRestart                  CompleteReset ok│   │fail  │(retry)
//                                                                   ▼   ▼      │
//                                                       reset_done   reset_failed
//                                                             │         │
//                                                RecordPrediction (either)
//                                                             ▼         ▼
//                                                            predicted ───▶ done
//                                                                FinishTrial
//
//   terminal: done, failed, cancelled.  "running" = dispatched .. predicted.
//
// | from                      | to           | function                         |
// |---------------------------|--------------|----------------------------------|
// | planned                   | dispatched   | ClaimNextTrial                   |
// | planned                   | cancelled    | CancelCampaign                   |
// | dispatched                | executed     | Ingest::Finish                   |
// | dispatched                | planned (+1) | RetryTrial, RecoverAfterRestart, ReleaseTrial |
// | dispatched                | failed       | RetryTrial (attempts exhausted)  |
// | executed, reset_failed    | resetting    | BeginReset                       |
// | resetting                 | reset_done   | CompleteReset (ok)               |
// | resetting                 | reset_failed | CompleteReset (!ok), RecoverAfterRestart |
// | reset_done, reset_failed  | predicted    | RecordPrediction(AndFinish)      |
// | predicted                 | done         | FinishTrial, RecordPredictionAndFinish |
// | any non-terminal          | failed       | FailTrial                        |
//
// A failed reset does not spoil the trial (its ground truth is complete); it
// counts against the cell and leaves the next start state to be observed.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "arena/db/outcomes.hpp"
#include "arena/db/prediction_status.hpp"
#include "arena/db/sample.hpp"
#include "arena/db/scene_facts.hpp"
#include "arena/db/trial_end.hpp"
#include "arena/errors/error.hpp"

namespace arena::db {

// ---------------------------------------------------------------- errors

class StoreError : public Error {
 public:
  enum class Kind {
    kBadInput,           // a field is missing, out of range, NaN or infinite
    kNotFound,           // no such campaign / trial / cell
    kIllegalTransition,  // the state machine does not have this edge
    kStaleAttempt,       // the call names an attempt that is not the trial's current one
    kReadOnly,           // a write through a read-only store or query
    kBusy,               // the database stayed locked past busy_timeout_ms
    kTooNew,             // the file's schema is newer than this binary
    kCorrupt,            // integrity check failed, malformed block, not a database
    kFull,               // disk or SQLite size limit full
    kIo,                 // cannot open / read / write the file
    kOutput,             // an output outside the store (an export directory) cannot be written
  };
  StoreError(Kind kind, const std::string& message)
      : Error(CategoryOf(kind), message), kind_(kind) {}
  Kind kind() const { return kind_; }

  // The caller's input (2); an output outside the store that cannot be
  // written is a failure of the command (1); the rest is the store's (3).
  static constexpr ErrorCategory CategoryOf(Kind kind) {
    switch (kind) {
      case Kind::kBadInput:
      case Kind::kNotFound:
      case Kind::kIllegalTransition:
      case Kind::kStaleAttempt:
        return ErrorCategory::kBadInput;
      case Kind::kOutput:
        return ErrorCategory::kFailure;
      default:
        return ErrorCategory::kStore;
    }
  }

 private:
  Kind kind_;
};

// ---------------------------------------------------------------- enums

enum class TrialState {
  kPlanned,
  kDispatched,
  kExecuted,
  kResetting,
  kResetDone,
  kResetFailed,
  kPredicted,
  kDone,
  kFailed,
  kCancelled,
};
const char* ToString(TrialState state);
std::optional<TrialState> ParseTrialState(const std::string& text);
bool IsTerminal(TrialState state);
// The edges of the diagram above (RetryTrial's dispatched->planned included).
bool IsLegalTransition(TrialState from, TrialState to);

enum class CampaignState { kActive, kPaused, kCancelled, kDone };
const char* ToString(CampaignState state);

enum class CellState { kHealthy, kQuarantined, kGone };
const char* ToString(CellState state);

// Contact types a trial needs / a cell offers, as a bit mask.
enum ContactTypeBit : int { kPointBit = 1, kLineBit = 2, kPatchBit = 4 };
// "point" -> kPointBit, ...; throws StoreError(kBadInput) for another name.
int ContactTypeMask(const std::vector<std::string>& types);

// ---------------------------------------------------------------- records

struct StoreOptions {
  bool read_only = false;  // SQLITE_OPEN_READONLY: every write fails with kReadOnly
  bool create = true;      // read-write only: create the file if missing
  // FULL: a commit is on disk when it returns (survives power loss).
  // NORMAL (default): a commit survives any process crash (SIGKILL); an OS
  // crash or power loss may roll back the last commits since the last WAL
  // checkpoint, never corrupting the file. README: "What survives which crash".
  bool synchronous_full = false;
  int busy_timeout_ms = 5000;
  // 0: no limit. Otherwise the file may not grow past this many 4096-byte
  // units (PRAGMA max_page_count, converted to the file's page size, rounded
  // down); a write that would is refused with kFull. Lets tests and cautious
  // deployments bound the store's size.
  std::int64_t max_pages = 0;
  // WAL size (bytes) at which a commit checkpoints it into the database file
  // (PRAGMA wal_autocheckpoint, converted to pages). Larger: fewer fsyncs
  // and faster ingest; with synchronous NORMAL, at most about this much of
  // the latest commits can be rolled back by an OS crash or power loss
  // (db/README.md, "What survives which crash").
  std::int64_t wal_autocheckpoint_bytes = std::int64_t{16} << 20;
  // Who checkpoints. Empty (default): the commit that grows the WAL past
  // wal_autocheckpoint_bytes checkpoints it itself (SQLite's autocheckpoint:
  // a 14-18 ms stall of that commit every ~40 trials, bench/README.md,
  // "Overhead, part X"). Set: such a commit calls this instead (cheap, no
  // throw: it wakes another thread that runs CheckpointWal() on its own
  // connection), and checkpoints itself only past 4 x wal_autocheckpoint_bytes,
  // so the WAL stays bounded if that thread falls behind.
  std::function<void()> wal_checkpoint_due;
  // Page size of a new file (512..65536, a power of two); an existing file
  // keeps its own. 8192: see db/README.md, "Pragmas".
  int new_file_page_size = 8192;
  // A read-write open first runs SQLite's quick check (PRAGMA quick_check:
  // every page and record, not the index contents) for up to this many
  // seconds and refuses a corrupt file with kCorrupt before writing anything.
  // A larger store than it can check in time opens with the check incomplete
  // (Store::open_check()); `arena serve` finishes it in the background
  // (db/README.md, "Integrity"). <= 0: no check (benchmarks only).
  double open_check_budget_s = 10.0;
  // Seconds since the Unix epoch; tests inject a clock. Default: system clock.
  std::function<double()> clock;
  // The contact sites of a stored scene, for the one migration that needs
  // them (6: the outcomes of streams stored before it). A file that needs it
  // and is opened without it is refused (kIo), nothing written.
  SceneFactsFn scene_facts;
};

struct NewCampaign {
  std::string name;                       // non-empty
  std::string spec_json;                  // the submitted campaign, as validated (JSON object)
  int priority = 0;                       // higher runs first
  std::uint64_t seed = 0;                 // the campaign seed
  std::string sampler_state_json = "{}";  // where the sampler stands after the planned trials
  // An adaptive sampler that will add trials as results come in
  // (PlanAdaptiveRound): the campaign is not done while this is true.
  bool sampler_open = false;
};

struct PlannedTrial {
  int condition = 0;               // condition index (>= 0)
  int replicate = 0;               // replicate of that condition (>= 0)
  std::uint64_t seed = 0;          // per-trial seed: re-runs the trial bit for bit
  std::string scene_json;          // scene (docs/scene.md; JSON object), stored as given
  SceneFacts facts;                // what the store indexes of it (the caller's: db reads no scene)
  std::string params_json = "{}";  // the sampler's own parameter values (JSON object)
  std::string defects_json = "{}";  // the campaign's defect profile for this trial
};

struct Campaign {
  std::int64_t id = 0;
  std::string name;
  std::string spec_json;
  CampaignState state = CampaignState::kActive;
  std::string state_reason;  // why it is paused / cancelled ("" when active)
  int priority = 0;
  std::uint64_t seed = 0;
  std::string sampler_state_json;
  double created_at = 0;  // s since epoch
  double updated_at = 0;
  bool sampler_open = false;  // an adaptive sampler may still add trials
};

// One decision of an adaptive sampler (orchestrator/adaptive.hpp): a trial it
// planned and why, or (trial_id absent) why it stopped.
struct SamplerDecision {
  std::int64_t id = 0;
  std::int64_t campaign_id = 0;
  int round = 0;                         // 0 = the first batch
  std::optional<std::int64_t> trial_id;  // the trial it planned; absent: it stopped
  std::string reason;                    // e.g. "bisect between trial 4 (stick) and 7 (slide)"
  std::string basis_json = "{}";         // what it was based on (outcomes seen, neighbours)
  double created_at = 0;                 // s since epoch
};

// One adaptive round, written by PlanAdaptiveRound in one transaction.
struct AdaptiveRound {
  int round = 0;
  std::vector<PlannedTrial> trials;
  std::vector<std::string> reasons;     // one per trial
  std::vector<std::string> bases_json;  // one per trial (JSON objects)
  std::string sampler_state_json = "{}";
  bool open = true;         // false: the sampler has finished (stop_reason says why)
  std::string stop_reason;  // stored as a decision without a trial when !open
  // The rounds whose outcomes the decision used: 0 .. known_through_round
  // (their trials must all be finished; later rounds may still run: a
  // pipelined round). nullopt: every trial of the campaign so far.
  std::optional<int> known_through_round;
};

// A fit of model parameters to a campaign's ground truth (arena calibrate).
struct Calibration {
  std::int64_t id = 0;
  std::int64_t campaign_id = 0;
  double created_at = 0;
  std::string params_json = "{}";    // fitted values with uncertainty, by parameter name
  std::string settings_json = "{}";  // parameters, bounds, weights, hold-out, predictor
  double heldout_error_before = 0;   // weighted loss on held-out trials, uncalibrated (>= 0)
  double heldout_error_after = 0;    // the same with the fitted values (>= 0)
  bool applied = false;              // true only when it improved the held-out error
  std::string report_json = "{}";
};

struct Trial {
  std::int64_t id = 0;
  std::int64_t campaign_id = 0;
  int index = 0;  // 0.. within the campaign
  int condition = 0;
  int replicate = 0;
  std::uint64_t seed = 0;
  TrialState state = TrialState::kPlanned;
  int attempt = 1;      // 1 for the first execution
  std::string cell_id;  // last cell it was dispatched to ("" if never)
  std::string scene_json;
  std::string params_json;
  std::string defects_json;
  TrialEnd outcome = TrialEnd::kNone;        // kNone until set
  std::optional<std::int64_t> gt_stream_id;  // the published ground truth
  double not_before = 0;                     // s since epoch: a retry waits until then
  double created_at = 0;
  double updated_at = 0;
  std::optional<double> dispatched_at;  // s since epoch, last dispatch (absent if never)
  std::optional<double> executed_at;
  std::optional<double> finished_at;  // reached a terminal state
};

// Issue 26 (migration 18): why no live cell can host a campaign's trials
// (orchestrator/claim_gate.hpp); its trials wait, unclaimed.
struct CampaignWait {
  std::int64_t campaign_id = 0;
  std::string kind;    // defects | contact_types | workspace | pusher_speed
  std::string reason;  // e.g. "no live cell can emulate defect ... (cells a, b: replay backend)"
  std::string rule;    // the gate's rule ("claim_gate.waits")
  double since = 0;    // s since epoch
};

// Planned trials of an active campaign alike in what they need of a cell.
struct PlannedNeed {
  std::int64_t campaign_id = 0;
  int contact_mask = 0;             // point 1, line 2, patch 4
  double position[3] = {0, 0, 0};   // nominal object position, gripper frame (m)
  double pusher_speed = 0;          // m/s (pusher.motion.velocity's norm; 0: none or a path)
  std::string defects_json = "{}";  // the campaign's defect profile
  std::int64_t trials = 0;          // how many planned trials are alike
};

// What ClaimNextTrial hands the service: everything it needs to send EXECUTE.
struct ClaimedTrial {
  std::int64_t trial_id = 0;
  std::int64_t campaign_id = 0;
  int attempt = 1;
  std::uint64_t seed = 0;
  std::string scene_json;
  std::string defects_json;
  std::int64_t index = 0;  // its plan position in the campaign (trials.idx)
};

// One change of a cell's fixtures (issue 29, migration 17): during which
// trial's phase ("reset": preparing the next trial; "execute": right before
// the trial ran), what ("finger", "pusher", "object"), from and to which
// fixture (arena::schemas::Fixtures keys; from "" = nothing known mounted)
// and the seconds the cell declared for it.
struct FixtureChangeRecord {
  std::int64_t trial_id = 0;
  int attempt = 1;
  std::string cell_id;
  std::string phase;
  std::string what;
  std::string from_key;
  std::string to_key;
  double seconds = 0;
  double at = 0;  // s since epoch (set by the store)
};

struct Transition {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::string from_state;  // "" for the insert that created the trial
  std::string to_state;
  double at = 0;  // s since epoch
  std::string cell_id;
  std::string reason;
  // The name of the rule that decided it (the service's trial policy,
  // orchestrator/trial_policy.hpp, or the store's own edge, e.g.
  // "dispatch.claimed"); "" in rows written before migration 15.
  std::string rule;
};

// A cell's reset report (TrialStatus of a RESET phase).
struct ResetReport {
  bool ok = false;
  std::array<double, 7> observed_pose{0, 0, 0, 1, 0, 0, 0};  // object start pose it saw (m, quat)
  double position_error = 0;                                 // m, the cell's own observed-vs-target
  double angle_error = 0;                                    // rad
  int reset_attempts = 1;
  std::string reason;  // why it failed ("" if ok)
  // false: nothing was observed (e.g. the service restarted mid-reset), so
  // observed_pose is ignored and the next trial on the cell has no known start state.
  bool pose_observed = true;
  // The trial this reset prepared the start of: the one the service expected
  // next on the cell (0: none). The observed start is charged only to that
  // trial; a trial the cell claims after a reset aimed at another one (two
  // cells expected the same trial) has no observed start. nullopt: not known,
  // and the start goes to whichever trial the cell claims next.
  std::optional<std::int64_t> aimed_at_trial;
};

struct Prediction {
  std::string model_key;          // fidelity label, e.g. "g8_k3_dt0.004" (non-empty)
  std::string model_json = "{}";  // the model settings used
  PredictionStatus status = PredictionStatus::kOk;
  std::optional<double> final_position_error;  // m, predicted vs true final object position
  std::optional<double> final_angle_error;     // rad
  std::optional<double> force_error;           // N, RMS over samples and contacts
  std::optional<double> mode_agreement;        // [0, 1], fraction of contact-samples with same mode
  double wall_s = 0;                           // predictor wall time (s), >= 0
  std::string detail_json = "{}";              // residuals, solver statistics
};

// A closed-loop trial attempt (issue 19): its controller, the controller's
// own outcome, and every pusher command the cell applied.
struct ClosedLoopCommand {
  int sample = 0;                     // the sample it answered (applied from the next step)
  double t = 0;                       // s
  std::array<double, 3> commanded{};  // m/s, as the controller sent it
  std::array<double, 3> applied{};    // m/s, with the cell's actuation noise
  std::optional<double> loop_ms;      // live sample -> command accepted; absent: held
};
struct ClosedLoopRun {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::string controller;
  bool lockstep = false;
  double target = 0, gain = 0, tolerance = 0, hold_s = 0;
  std::optional<bool> reached;  // absent: not scored (not a library law)
  std::optional<double> final_error;
  std::optional<double> settle_time_s;  // absent: never settled
  int held = 0;
  std::optional<double> loop_p50_ms, loop_p99_ms;
  std::string failure;  // "" when the phase ran through
  std::vector<ClosedLoopCommand> commands;
};

// One trial's result in an evaluation run (`arena evaluate`): the trial
// replayed through the model at one fidelity setting, scored against its
// ground truth. Same fields as a prediction; stored apart from `predictions`
// so that evaluating never touches a trial's own prediction or its state.
struct EvaluationResult {
  std::int64_t trial_id = 0;
  int attempt = 0;        // the trial's attempt whose ground truth was used
  Prediction prediction;  // model_key names the setting
};

// One evaluation run over a campaign's done trials.
struct Evaluation {
  std::int64_t id = 0;
  std::int64_t campaign_id = 0;
  double created_at = 0;             // s since epoch
  std::string settings_json = "{}";  // the grid of settings and the budget asked for
  std::string report_json = "{}";    // per-setting summary, Pareto front, recommendation
};

struct CellInfo {
  std::string id;
  CellState state = CellState::kHealthy;
  double last_seen = 0;
  int consecutive_failures = 0;
  int total_failures = 0;
  std::string capabilities_json;
  std::string quarantine_reason;
  // The service's liveliness lease for this cell (s; 0 unknown): `status`
  // shows a healthy cell whose last_seen is older than this as gone.
  double lease_s = 0;
  // "" while this store's service serves the cell; otherwise who holds it,
  // e.g. "service 1a2b... on host lab2 (pid 4242)".
  std::string serving;
};

// One start of `arena serve` (or `arena run`) on this store: its heartbeat.
struct ServiceRecord {
  std::string session;  // hex of the service session (TrialCommand.service_session)
  std::int64_t pid = 0;
  std::string host;
  int domain = 0;
  double started_at = 0;  // s since epoch
  double last_beat = 0;
  std::optional<double> stopped_at;  // a clean stop
};

// An operator's or the service's act on a cell (cell_events).
struct CellEvent {
  std::string cell_id;
  double at = 0;
  std::string event;  // quarantined, released
  std::string reason;
  std::string by_whom;
};

// A condition that paused dispatch (issue 29, orchestrator/suspender_policy.hpp).
struct Suspension {
  std::int64_t id = 0;
  std::string condition;         // reset_failure_rate, start_pose_drift, sample_drop_rate,
                                 // cell_silence, store_free_space, deadline_misses
  std::string scope;             // cell, campaign, service
  std::int64_t campaign_id = 0;  // campaign scope (0 otherwise)
  std::string cell_id;           // cell scope ("" otherwise)
  std::string rule;              // the rule that fired it
  std::string evidence;          // the reading against its limit
  double fired_at = 0;           // s since epoch
  std::optional<double> lifted_at;
  std::string lifted_by;  // the rule that lifted it, or "arena resume"
  std::string lift_reason;
};

// One event of the service (campaign done, cell gone, suspension fired, ...),
// as given to `arena serve --notify` (event_json) and logged.
struct EventRecord {
  std::int64_t id = 0;
  double at = 0;  // s since epoch
  std::string kind;
  std::int64_t campaign_id = 0;  // 0: none
  std::string cell_id;
  std::string message;
  std::string event_json = "{}";
};

struct CampaignStatus {
  std::int64_t id = 0;
  std::string name;
  CampaignState state = CampaignState::kActive;
  int priority = 0;
  std::int64_t planned = 0;  // all trials of the campaign
  std::int64_t pending = 0;  // state planned
  std::int64_t running = 0;  // dispatched .. predicted
  // Of running: ground truth stored, prediction not yet (executed ..
  // reset_failed). The service predicts them off the trials' path; one it
  // leaves (stopped, killed) predicts them after its restart.
  std::int64_t awaiting_prediction = 0;
  std::int64_t done = 0;
  std::int64_t failed = 0;
  std::int64_t cancelled = 0;
  double rate_per_hour = 0;     // finished (done+failed) trials per hour, recent window
  std::optional<double> eta_s;  // (pending+running)/rate; absent when rate is 0
};

// Start state each trial's cell measured (the first sample of its ground
// truth, stored when the execution is published), against the trial's nominal
// start pose: the reset's bias per campaign and cell.
struct StartStateDrift {
  std::int64_t campaign_id = 0;
  std::string cell_id;
  std::int64_t trials = 0;
  double mean_dx = 0, mean_dy = 0, mean_dz = 0;  // m, observed - nominal (bias)
  double mean_position_error = 0;                // m
  double max_position_error = 0;                 // m
  double mean_angle_error = 0;                   // rad
  double max_angle_error = 0;                    // rad
};

struct StatusSummary {
  std::vector<CampaignStatus> campaigns;
  std::vector<CellInfo> cells;
  std::vector<StartStateDrift> drift;
};

struct RecoveryReport {
  std::vector<std::int64_t> requeued;       // dispatched -> planned, attempt+1
  std::vector<std::int64_t> reset_failed;   // resetting -> reset_failed
  std::int64_t orphan_streams_deleted = 0;  // incomplete ground truth of requeued attempts
};

// trials.truth of a measured trial whose contact forces were not measured
// or failed their import check (the cell states it; the service checks the
// stream against it): its samples carry no contacts, its poses are scored,
// its forces never. The same words as dds::kTruthMeasuredNoForces.
inline constexpr const char* kTruthMeasuredNoForces = "measured:no-forces";

struct GroundTruth {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::string cell_id;
  // The trial's kind of truth (trials.truth, RecordExecution; "" when none
  // was reported). kTruthMeasuredNoForces: no sample has contacts.
  std::string truth;
  std::vector<Sample> samples;
  bool forces_measured() const { return truth != kTruthMeasuredNoForces; }
};

struct IngestOptions {
  int samples_per_chunk = 250;         // samples per BLOB row (1 s at 250 Hz)
  int samples_per_commit = 2000;       // commit when this many samples are buffered
  double max_commit_interval_s = 0.5;  // ... or when the oldest buffered sample is this old
  // Store chunks in the packed block format "AGT2" (lossless; db/README.md)
  // when it is smaller; false writes the raw "AGT1" (both read the same).
  bool pack_chunks = true;
};

class Store;

// What executed a trial (the cell's EXECUTED status): Store::RecordExecution's fields.
struct ExecutionRecord {
  std::string backend;
  std::string truth;
  std::string defects_applied_json;
};

// Writes Ingest::Finish adds to its own transaction: on the trial's path one
// commit where there were three (a commit costs by the pages it writes, not
// by its statements: bench/README.md, "Overhead, part IV").
struct FinishAlso {
  // Written first, as Store::RecordExecution.
  std::optional<ExecutionRecord> execution;
  // Non-empty: the trial then moves executed -> resetting, as Store::BeginReset
  // with this rule (its audit row and edge check the same).
  std::string begin_reset_rule;
};

// Buffers the ground truth of one (trial, attempt) and writes it in batched
// transactions (prepared statements, BLOB chunks). Nothing it writes is
// visible to readers until Finish() publishes it. Not thread-safe.
class Ingest {
 public:
  ~Ingest();  // an unfinished stream stays unpublished (cleaned up on re-ingest/recovery)
  Ingest(const Ingest&) = delete;
  Ingest& operator=(const Ingest&) = delete;

  // @throws StoreError(kBadInput) naming the sample index and field for NaN /
  //   infinity / sizes; nothing of that call is buffered then.
  void Add(const Sample& sample);
  void Add(const std::vector<Sample>& samples);
  // Commits buffered samples if max_commit_interval_s has passed (call from a timer).
  void Poll();
  // Commits buffered samples now.
  void Flush();
  // Commits the rest, writes the per-trial summary, publishes the stream and
  // moves the trial dispatched -> executed (or, on a re-ingest of a trial
  // already past executed at this attempt, swaps the stream in) -- all in one
  // transaction. `outcome` is the cell's result ("ok" normally). `also`: the
  // writes that join that transaction; any refusal rolls back all of them.
  // @returns the number of samples published.
  std::int64_t Finish(TrialEnd outcome = TrialEnd::kOk);
  std::int64_t Finish(TrialEnd outcome, const FinishAlso& also);
  std::int64_t samples() const;

 private:
  friend class Store;
  struct Impl;
  explicit Ingest(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

class Store {
 public:
  // Opens (and in read-write mode creates and migrates) the store at `path`.
  // @throws StoreError(kTooNew) when the file was written by a newer arena,
  //   kIo when it cannot be opened (read-only: also when it does not exist or
  //   has an older schema that only a read-write open migrates), kCorrupt when
  //   it is not a database, kReadOnly when read-write but the file is write-protected.
  static std::unique_ptr<Store> Open(const std::string& path, const StoreOptions& options = {});
  ~Store();
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  static int SchemaVersion();     // the schema this binary writes
  int FileSchemaVersion() const;  // PRAGMA user_version of the open file
  bool read_only() const;
  const std::string& path() const;
  double Now() const;
  // "ok" or SQLite's list of problems (PRAGMA integrity_check).
  std::string IntegrityCheck() const;
  // PRAGMA quick_check for up to budget_s seconds (<= 0: no limit; another
  // thread's Interrupt() also stops it).
  struct QuickCheckResult {
    bool complete = false;  // false: the budget ran out (or interrupted) first
    std::string problems;   // "" when complete and the file is sound
    double seconds = 0;
  };
  QuickCheckResult QuickCheck(double budget_s) const;
  // What the read-write open's check found (complete = false when it ran out
  // of StoreOptions::open_check_budget_s, or was skipped).
  const QuickCheckResult& open_check() const;
  // Copies the WAL's committed frames into the database file: a PASSIVE
  // checkpoint, which waits for no reader or writer (frames a reader still
  // needs stay). @returns how many of the WAL's frames are now in the
  // database file (0 when another connection's checkpoint runs).
  // @throws StoreError (kIo, kFull...) when it fails.
  std::int64_t CheckpointWal();
  // Stops this connection's running statement (SQLITE_INTERRUPT); the one
  // call that may come from another thread.
  void Interrupt() const;
  // The state machine's invariants over the whole file (e.g. a trial at or
  // past executed has a complete stream of its attempt; done has a
  // prediction; the last audit row of each trial matches its state).
  // @returns one message per violation; empty when all hold.
  std::vector<std::string> CheckInvariants() const;

  // ---- campaigns
  // Inserts the campaign and its planned trials in one transaction.
  // @returns the campaign id. @throws kBadInput naming the trial and field.
  std::int64_t CreateCampaign(const NewCampaign& campaign, const std::vector<PlannedTrial>& trials);
  // The same for a campaign too big for memory: asks next_chunk for planned
  // trials until it returns none, all in ONE transaction. If next_chunk (or a
  // write) throws -- an interrupt, a full disk -- nothing is stored.
  std::int64_t CreateCampaign(const NewCampaign& campaign,
                              const std::function<std::vector<PlannedTrial>()>& next_chunk);
  // Adds more planned trials (a budget-driven sampler) and stores the sampler's new position.
  void AppendPlannedTrials(std::int64_t campaign_id, const std::vector<PlannedTrial>& trials,
                           const std::string& sampler_state_json);
  Campaign GetCampaign(std::int64_t campaign_id) const;
  std::vector<Campaign> ListCampaigns() const;
  // active -> paused (idempotent). `reason` tells an operator's pause from
  // an automatic suspension (RecordSuspension: "suspended: <condition>: ...").
  void PauseCampaign(std::int64_t campaign_id, const std::string& reason = "paused by operator");
  void ResumeCampaign(std::int64_t campaign_id);  // paused -> active
  // -> cancelled; its planned trials become cancelled, running ones run out.
  void CancelCampaign(std::int64_t campaign_id,
                      const std::string& reason = "cancelled by operator");
  // Marks active campaigns whose trials are all terminal and whose sampler is
  // not open (AdaptiveRound::open) as done; returns their ids.
  std::vector<std::int64_t> CompleteFinishedCampaigns();

  // ---- adaptive samplers
  // Appends the round's planned trials, one decision row each (and a stop
  // row when !round.open), the sampler's new state and sampler_open, in one
  // transaction -- only if the campaign is active, its sampler is open, its
  // sampler state is still `expected_state_json` and none of the trials the
  // decision was based on (round.known_through_round; all when unset) is
  // planned or running (so two services cannot both advance it, and no
  // decision is written from outcomes that are not final). Registers new
  // parameter names in the result views, as CreateCampaign does.
  // @returns false (nothing written) when one of those does not hold.
  // @throws kBadInput for bad fields (reasons/bases not one per trial, ...).
  bool PlanAdaptiveRound(std::int64_t campaign_id, const std::string& expected_state_json,
                         const AdaptiveRound& round);
  // An adaptive campaign and its first round in ONE transaction (arena
  // submit): the campaign row, then `plan_first(id)` -- called inside the
  // transaction; it may read the store and sees the new campaign, but must
  // not write -- whose round is written as PlanAdaptiveRound writes one. If
  // plan_first or a write throws, nothing is stored; a crash leaves either
  // nothing or the campaign with its round.
  // @returns the campaign id. @throws kBadInput (campaign or round fields).
  std::int64_t CreateAdaptiveCampaign(
      const NewCampaign& campaign,
      const std::function<AdaptiveRound(std::int64_t campaign_id)>& plan_first);
  std::vector<SamplerDecision> ListDecisions(std::int64_t campaign_id) const;

  // ---- calibrations (arena calibrate)
  // @returns the calibration id. @throws kNotFound (campaign), kBadInput (NaN, bad JSON).
  std::int64_t RecordCalibration(const Calibration& calibration);
  // @throws kNotFound.
  Calibration GetCalibration(std::int64_t calibration_id) const;
  std::vector<Calibration> ListCalibrations(std::int64_t campaign_id) const;

  // ---- trial state machine (see the table above)
  // Atomically picks the next planned trial, by campaign priority (then
  // campaign id, then trial index), of an active campaign, whose contact
  // types the cell offers and whose not_before has passed; moves it to
  // dispatched on `cell_id`, moves the cell's last observed start state into
  // it (the cell's copy is cleared: the trial will move the object) and
  // computes its error against the trial's nominal start pose. The write is
  // committed before this returns, so the caller acts after.
  // @returns nullopt when nothing is pending or the cell is not healthy.
  std::optional<ClaimedTrial> ClaimNextTrial(const std::string& cell_id);
  // What ClaimNextTrial would return now, without writing (to aim a reset).
  std::optional<ClaimedTrial> PeekNextTrial(const std::string& cell_id) const;
  // Change-aware scheduling (issue 29, orchestrator/claim_chooser.hpp): the
  // first `limit` (1..1000) trials, in plan order, of the campaign
  // ClaimNextTrial would take from (the same filters: healthy cell, active
  // campaign by priority, planned, due, contact types offered). Empty: none.
  std::vector<ClaimedTrial> ClaimWindow(const std::string& cell_id, int limit) const;
  // As ClaimNextTrial, but claims `trial_id` (one of the window), if it is
  // still claimable by the cell. The audit row's rule is "dispatch.claimed"
  // as always; its reason names the chooser's `rule` ("claimed by
  // claim.least_change"). @returns nullopt when it no longer is.
  std::optional<ClaimedTrial> ClaimTrial(const std::string& cell_id, std::int64_t trial_id,
                                         std::string_view rule);
  // Records a cell's fixture changes (migration 17), one transaction.
  // @throws kBadInput (phase, what, seconds), kNotFound (trial, cell).
  void RecordFixtureChanges(const std::vector<FixtureChangeRecord>& changes);
  // A campaign's changes (0: all), oldest first.
  std::vector<FixtureChangeRecord> ListFixtureChanges(std::int64_t campaign_id) const;
  // `rule` (these four): the name of the caller's rule that decided the
  // step, written to the audit row (trial_transitions.rule).
  //
  // dispatched -> planned with attempt+1 and not_before = now + backoff_s; or
  // -> failed (outcome "failed") when the retry rule (retry_rule.hpp:
  // DecideRetry, which does not count attempts a service restart cut short)
  // gives up. The audit row names `rule` and the retry rule's verdict.
  // @returns the new state.
  TrialState RetryTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                        int max_attempts, double backoff_s, std::string_view rule = {});
  // dispatched -> planned with attempt+1, not counted against the trial (as
  // an attempt a service restart cut short: trials.service_restarts + 1) and
  // no backoff: an attempt that never started on its cell through no fault
  // of its own (an EXECUTE queued behind a reset that failed, or whose cell
  // was lost before it could run it). The audit row names `rule`.
  void ReleaseTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                    std::string_view rule);
  // any non-terminal -> failed, outcome `outcome` (e.g. kRefused).
  void FailTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                 TrialEnd outcome = TrialEnd::kFailed, std::string_view rule = {});
  // executed | reset_failed -> resetting.
  void BeginReset(std::int64_t trial_id, int attempt, std::string_view rule = {});
  // resetting -> reset_done | reset_failed; stores the observed start state on
  // the cell (the next trial claimed there inherits it; a claim consumes it)
  // and the report on the trial.
  void CompleteReset(std::int64_t trial_id, int attempt, const ResetReport& report,
                     std::string_view rule = {});
  // Stores a prediction (replacing one with the same model_key for this
  // attempt); reset_done | reset_failed -> predicted on the first one.
  // Allowed in reset_done, reset_failed, predicted.
  void RecordPrediction(std::int64_t trial_id, int attempt, const Prediction& prediction);
  // Closed loop (issue 19): replaces what was stored for (trial, attempt).
  void RecordClosedLoop(const ClosedLoopRun& run);
  // The newest attempt's closed-loop run of a trial; nullopt: not closed-loop.
  std::optional<ClosedLoopRun> GetClosedLoop(std::int64_t trial_id) const;
  // predicted -> done.
  void FinishTrial(std::int64_t trial_id, int attempt);
  // RecordPrediction then FinishTrial in one transaction (the service's
  // clean trial: one commit where there were two; both audit rows written).
  // A refusal of either refuses both.
  void RecordPredictionAndFinish(std::int64_t trial_id, int attempt, const Prediction& prediction);
  // What executed the trial (from the cell's EXECUTED status): the backend
  // ("model", "mujoco", "exec:...", "replay:..."), its kind of truth
  // ("self-consistency", "simulator", "robot", "recorded") and the defects
  // really applied (JSON object, executors/README.md). Migration 10.
  void RecordExecution(std::int64_t trial_id, int attempt, const std::string& backend,
                       const std::string& truth, const std::string& defects_applied_json);
  // Per (truth, backend): how many of the campaign's trials were executed
  // against it (trials executed by a cell that reported none count under "").
  struct TruthCount {
    std::string truth;
    std::string backend;
    std::int64_t trials = 0;
  };
  std::vector<TruthCount> CampaignTruths(std::int64_t campaign_id) const;
  // After a crash: dispatched -> planned (attempt+1), resetting -> reset_failed,
  // incomplete streams of the old attempts deleted. Idempotent.
  RecoveryReport RecoverAfterRestart(const std::string& reason = "service restarted");

  Trial GetTrial(std::int64_t trial_id) const;
  std::vector<Trial> ListTrials(std::int64_t campaign_id) const;
  // Trials of all campaigns in any of `states`, by id (e.g. the running ones
  // whose phase deadlines a restarted service must track again).
  std::vector<Trial> ListTrialsByState(const std::vector<TrialState>& states) const;
  std::vector<Transition> ListTransitions(std::int64_t trial_id) const;
  std::vector<Prediction> ListPredictions(std::int64_t trial_id) const;

  // ---- evaluations (arena evaluate): never change a trial's state
  // Stores one run and all its per-trial results in one transaction.
  // @returns the evaluation id.
  // @throws kNotFound for an unknown campaign or trial; kBadInput for a trial
  //   of another campaign, a repeated (trial, model_key), or a bad field (as
  //   RecordPrediction); kIllegalTransition for a trial that is not done;
  //   kStaleAttempt when the attempt is not the trial's.
  std::int64_t RecordEvaluation(std::int64_t campaign_id, const std::string& settings_json,
                                const std::string& report_json,
                                const std::vector<EvaluationResult>& results);
  // The campaign's evaluation runs, oldest first.
  std::vector<Evaluation> ListEvaluations(std::int64_t campaign_id) const;
  // @throws kNotFound for an unknown evaluation.
  Evaluation GetEvaluation(std::int64_t evaluation_id) const;
  // A run's per-trial results, by trial id then model_key.
  std::vector<EvaluationResult> ListEvaluationResults(std::int64_t evaluation_id) const;

  // ---- ground truth
  // @throws kNotFound / kStaleAttempt / kIllegalTransition unless the trial is
  //   dispatched (or past executed with its ground truth) at `attempt`.
  // `sites`: the trial's contacts (outcomes.hpp; SceneFacts::contacts) from
  // the caller, which has the scene parsed (db reads no scene).
  std::unique_ptr<Ingest> BeginIngest(std::int64_t trial_id, int attempt,
                                      std::vector<ContactSite> sites,
                                      const IngestOptions& options = {});
  // The published stream of the trial, read in one snapshot.
  // @throws kNotFound when the trial has no published ground truth.
  GroundTruth ReadGroundTruth(std::int64_t trial_id) const;
  // The outcomes stored with each published stream of the campaign's trials
  // (contact_outcomes and gt_summary's net motion, computed at ingest from
  // the samples: db/outcomes.hpp), by trial id, read in one snapshot. Only
  // the stream a trial points at (its last published attempt); a trial
  // without a stored outcome is absent.
  std::map<std::int64_t, TrialOutcome> ReadTrialOutcomes(std::int64_t campaign_id) const;

  // ---- cells
  // A cell announced itself: insert or refresh it (capabilities, last_seen).
  // A gone cell comes back healthy; a quarantined one stays quarantined.
  void UpsertCell(const std::string& cell_id, const std::vector<std::string>& contact_types,
                  const std::string& capabilities_json = "{}",
                  const std::string& defects_json = "{}");
  void TouchCell(const std::string& cell_id);
  // Counts a phase result against the cell; @returns consecutive failures now.
  int RecordCellResult(const std::string& cell_id, bool ok);
  void QuarantineCell(const std::string& cell_id, const std::string& reason);
  // quarantined|gone -> healthy, failures reset; writes a `released` row to
  // cell_events (who and why) in the same transaction.
  void ReleaseCell(const std::string& cell_id, const std::string& reason = "",
                   const std::string& by_whom = "");
  std::vector<CellEvent> ListCellEvents(const std::string& cell_id) const;
  // The service's view of a cell: the lease it judges it by, and who else
  // serves it ("" = us / nobody).
  void SetCellServing(const std::string& cell_id, double lease_s, const std::string& serving);
  void MarkCellGone(const std::string& cell_id, const std::string& reason);
  CellInfo GetCell(const std::string& cell_id) const;
  std::vector<CellInfo> ListCells() const;

  // ---- services (heartbeat; one service per store)
  // This store's random id (made by migration 5): a restarted service of the
  // same store may take its cells over at once.
  std::string StoreId() const;
  // Registers `me` as the store's service unless another one still holds it:
  // the latest unstopped service whose last beat is younger than fresh_s and
  // for which holder_alive() is true (it may check the pid on this host).
  // @returns that holder (nothing written) or nullopt (me registered).
  std::optional<ServiceRecord> RegisterService(
      const ServiceRecord& me, double fresh_s,
      const std::function<bool(const ServiceRecord&)>& holder_alive);
  // The service's heartbeat; also refreshes last_seen of the cells it hears.
  void ServiceBeat(const std::string& session, const std::vector<std::string>& cells_alive);
  void ServiceStopped(const std::string& session);
  // The most recently started service, if any ever ran.
  std::optional<ServiceRecord> LatestService() const;
  // @throws StoreError(kIo) naming the path when the file opened is no
  //   longer at its path (deleted, renamed or replaced by another file).
  void CheckFileIdentity() const;
  // How long a write waits for another process's lock before kBusy, from
  // now on (StoreOptions::busy_timeout_ms applies while opening). A service
  // lowers it so that a foreign lock never stalls its loop for long: it
  // retries the step instead and keeps renewing its cells' claims.
  // @throws std::invalid_argument when ms is negative.
  void SetBusyTimeout(int ms);

  // ---- suspensions and service events (issue 29; suspensions.cpp)
  // Records a suspension. Campaign scope: an active campaign is paused, its
  // reason "suspended: <condition>: <evidence>" (an operator's pause stays
  // as it is). One transaction. @returns its id. @throws kBadInput (scope,
  // condition), kNotFound (campaign).
  std::int64_t RecordSuspension(const Suspension& suspension);
  // Lifts an active suspension (`by`: the rule or "arena resume"). A
  // campaign paused by its suspensions resumes when none of them is left.
  // @returns false when it was already lifted.
  bool LiftSuspension(std::int64_t id, const std::string& by, const std::string& reason);
  // `arena resume CAMPAIGN [--cell C]`: lifts the campaign's and the
  // service's active suspensions (and, with a cell, that cell's) by
  // "arena resume", and resumes the campaign if it is paused. @returns those lifted.
  std::vector<Suspension> ResumeSuspended(std::int64_t campaign_id,
                                          const std::optional<std::string>& cell_id);
  // Active only, or all (newest first, at most `limit`).
  std::vector<Suspension> ListSuspensions(bool active_only, std::size_t limit = 1000) const;
  // A condition set aside for a campaign: its planned trials end failed with
  // `reason` (rule on the audit rows). @returns how many.
  int SetAsideTrials(std::int64_t campaign_id, const std::string& reason, const std::string& rule);
  std::int64_t RecordEvent(const EventRecord& event);
  // Events with id > after_id, oldest first, at most `limit`.
  std::vector<EventRecord> ListEvents(std::int64_t after_id = 0, std::size_t limit = 1000) const;

  // ---- the claim gate (issue 26, migration 18; campaign_waits.cpp)
  // What an active campaign's planned trials need of a cell, alike trials
  // grouped (at most `limit` groups per campaign), for
  // orchestrator/claim_gate.hpp.
  std::vector<PlannedNeed> PlannedNeeds(std::size_t limit = 1000) const;
  // The campaign waits: the claim skips it until ClearCampaignWait. Replaces
  // an earlier wait of the campaign. @throws kBadInput (kind, empty reason),
  // kNotFound (campaign).
  void SetCampaignWait(std::int64_t campaign_id, const std::string& kind, const std::string& reason,
                       const std::string& rule);
  // @returns false when the campaign did not wait.
  bool ClearCampaignWait(std::int64_t campaign_id);
  std::vector<CampaignWait> ListCampaignWaits() const;
  // The campaigns this Store's claims (ClaimNextTrial, PeekNextTrial,
  // ClaimWindow, ClaimTrial) may take from; nullopt (the default): every
  // active one. Not stored: `arena serve` allows only the campaigns its
  // claim gate has decided open, so a campaign submitted or resumed between
  // two gate runs waits for the gate instead of reaching a cell that must
  // refuse it.
  void RestrictClaimsTo(std::optional<std::vector<std::int64_t>> campaigns);
  // Active campaigns' ids, ascending (a cheap look: the gate's change check).
  std::vector<std::int64_t> ActiveCampaignIds() const;

  // ---- read side
  StatusSummary Status() const;
  std::vector<StartStateDrift> Drift(std::optional<std::int64_t> campaign_id = {}) const;

  // For the query and export code in this room.
  struct Impl;
  Impl& impl() { return *impl_; }
  const Impl& impl() const { return *impl_; }

 private:
  explicit Store(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  friend class Ingest;
};

// Runs `write` (one store write) until it does not fail with kBusy: a long
// computation (an evaluation, a calibration) that ends while another process
// holds the write lock waits for it instead of discarding its result.
// Between tries (0.1 s, doubling to 2 s) on_wait(seconds waited so far,
// SQLite's message) is called; it returns false to give up, and then the
// last kBusy is rethrown. Any other error is thrown at once.
void RetryWhileBusy(const std::function<void()>& write,
                    const std::function<bool(double, const std::string&)>& on_wait);

}  // namespace arena::db
