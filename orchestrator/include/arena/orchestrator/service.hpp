// The campaign service (`arena serve`): schedules the pending trials of every
// active campaign onto idle healthy cells, drives each through EXECUTE and
// RESET over DDS, ingests the ground truth, predicts the trial with the
// campaign's model settings, scores the prediction and marks the trial done.
//
// One trial, as the service drives it (store states in brackets; every
// transition is written to the store BEFORE the service acts on it):
//
//   idle cell --ClaimNextTrial--> [dispatched] --send EXECUTE--> cell
//   GroundTruth batches ---------> Ingest (batched transactions, unpublished)
//   TrialStatus EXECUTED + all samples --Ingest::Finish--> [executed]
//   --BeginReset--> [resetting] --send RESET (aimed at the next trial's start)
//   TrialStatus RESET_DONE/FAILED --CompleteReset--> [reset_done|reset_failed]
//   prediction (worker thread) --RecordPrediction--> [predicted]
//   --FinishTrial--> [done]
//
// The decisions live in TrialDriver (trial_driver.hpp: the cell state machine,
// the store-error policy, sessions and claims); this class is the shell
// around it: DDS endpoints, the SQLite store, predictor threads, heartbeat.
// One service per store: a second one on the same store refuses to start
// (db::StoreError kBusy naming the first one's pid and host).
//
// Failures: a REFUSED/FAILED execute, a malformed or out-of-order stream, a
// missed deadline or a cell that died (liveliness lost, participant gone)
// send the trial back to planned with attempt + 1 after a backoff
// (RetryTrial; lineage kept), or to failed when attempts run out. A cell that
// fails `quarantine_after` phases in a row by its own fault, or whose reset
// keeps failing, is quarantined and gets no more trials; a failure caused by
// the controller, the service itself or the store never counts against the
// cell, and after any failure the cell backs off (cell_backoff_s, doubling)
// before its next trial (trial_policy.hpp decides all of it, by named rules
// written to each trial's audit rows). A late message from an older attempt
// is ignored (the store refuses stale attempts). A store that can no longer
// be written (full, read-only, corrupt, I/O error) is nobody's trial or cell
// fault: Run() throws that db::StoreError and the service stops (`arena
// serve` exits 3); what was committed stays intact and a restart resumes. A
// busy store (another process's write lock) is retried, step by step.
//
// Crash safety: at start the service calls RecoverAfterRestart (dispatched ->
// planned with attempt + 1, resetting -> reset_failed) and then finishes every
// trial left between executed and predicted, so a SIGKILL at any moment loses
// and duplicates nothing. Stop() (SIGTERM) stops dispatching, lets phases in
// flight finish for up to drain_timeout_s, and exits; anything still in
// flight is re-run after the next start.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "arena/orchestrator/suspender_policy.hpp"
#include "arena/schemas/dds.hpp"

namespace arena::orchestrator {

struct ServiceOptions {
  std::string db_path;              // the SQLite store (created if missing)
  int domain_id = 0;                // DDS domain, 0..dds::kMaxDomainId (231)
  dds::NetworkOptions network;      // default: this host only
  int max_attempts = 3;             // executions per trial before it fails
  double retry_backoff_s = 1.0;     // first retry waits this long; doubles per attempt
  int quarantine_after = 3;         // consecutive failed phases of a cell (its own fault)
  double cell_backoff_s = 0.5;      // after a failed phase the cell waits this long before
  double cell_backoff_max_s = 8.0;  //   its next trial, doubling per failure in a row, to this
  double execute_timeout_s = 30.0;  // wall-clock budget of EXECUTE beyond the trial's
                                    //   duration x the cell's speed
  double reset_timeout_s = 60.0;    // wall-clock budget of RESET
  double stream_grace_s = 5.0;      // after EXECUTED: wait this long for missing batches
  double drain_timeout_s = 30.0;    // on Stop(): how long phases in flight may finish
  int predictor_threads = 1;        // worker threads predicting trials
  // The predictor threads' niceness, added to the process's (0..19; Linux
  // threads each have one). A trial's prediction is off its path (it is
  // stored after the next EXECUTE is sent); at a lower priority its model
  // yields a shared core to the service thread and the cells at once
  // (issue 27: the overhead per trial is wall time on shared cores).
  int predictor_nice = 10;
  // At most this many trials wait for their prediction; more, and no cell
  // claims a new trial until the predictor catches up (memory bounded, and a
  // slow predictor is never left behind for good).
  int prediction_backlog = 64;
  bool exit_when_done = false;     // `arena run`: stop when no active campaign is left
  std::int64_t only_campaign = 0;  // > 0: exit_when_done looks at this campaign only
  // A cell's next trial sent right behind its RESET (issue 27: the queued
  // trial, DriverOptions::queue_next_execute). Off only to measure what it
  // saves (orchestration_bench's BM_CampaignEndToEndUnqueued); no option sets it.
  bool queue_next_execute = true;
  std::int64_t store_max_pages = 0;  // > 0: the store may not grow past this many 4 KiB
                                     //   pages (db::StoreOptions::max_pages; fault tests)
  // Once serving, a write waits this long for another process's lock before
  // the step is retried later (the retry policy of trial_driver.hpp). Short,
  // so that a long foreign lock never stalls the loop that renews the cells'
  // claims (their lease is claim_lease_s) and reads their statuses.
  int store_busy_timeout_ms = 250;
  // While serving, a second connection runs the store's quick check
  // (PRAGMA quick_check) this often; damage found stops the service with
  // kCorrupt (exit 3) naming it. The open's own check is bounded in time
  // (db::StoreOptions::open_check_budget_s); this one finishes the file.
  double integrity_check_period_s = 300.0;
  // Issue 29 (docs/operations.md): the suspenders' limits (`--suspenders
  // FILE`), the command told of each event (`--notify`, notifier.hpp), and
  // the failed share of a campaign's finished trials that is an event.
  SuspenderConfig suspenders;
  std::string notify_command;  // "": events go to the log and the store only
  double notify_timeout_s = 10.0;
  int notify_queue = 256;
  double notify_failure_rate = 0.2;
  double watch_period_s = 1.0;  // suspenders evaluated, events looked for
};

// What the service has done since it started (for `arena run`'s summary and tests).
struct ServiceCounters {
  std::int64_t dispatched = 0;  // EXECUTE commands sent
  std::int64_t executed = 0;    // streams published
  std::int64_t done = 0;        // trials finished
  std::int64_t retried = 0;     // attempts sent back to planned
  std::int64_t failed = 0;      // trials that ran out of attempts or were refused
  std::int64_t resets_failed = 0;
  std::int64_t quarantined = 0;  // cells quarantined
  std::int64_t recovered = 0;    // trials picked up after a restart
  std::int64_t samples = 0;      // ground-truth samples ingested
  int cells_known = 0;           // cells that announced themselves
  int cells_usable = 0;          // of those: alive and not quarantined
};

// Where one clean trial's time went on its cell, for the orchestration-overhead
// figure (issue 5): the cell is busy from the claim of the trial until the
// service has taken its RESET_DONE; the cell reports how long it spent in
// EXECUTE and RESET itself; the rest is arena's (store transactions, DDS
// hops, polling). A cell freed since the service's previous dispatch pass is
// busy from its freeing, not the claim: the loop's work before the claim
// kept it waiting too. A trial queued behind its cell's reset (issue 27:
// its EXECUTE went out with that RESET) is busy from the previous trial's
// RESET_DONE taken: the figure is then the cell's cycle between two
// RESET_DONEs less its execute and reset. Its claim leg is 0, and its
// EXECUTE leg may be below 0 by the head start the queue gave the cell (it
// began before the service took the RESET_DONE that frees it).
struct TrialTiming {
  std::int64_t trial_id = 0, campaign_id = 0;
  int attempt = 0;
  std::string cell_id;
  double cell_busy_s = 0;  // claim (or freeing, above) -> RESET_DONE taken, service clock (s)
  double execute_s = 0;    // the cell's own EXECUTE wall time (s)
  double reset_s = 0;      // the cell's own RESET wall time (s)
  double overhead_s = 0;   // cell_busy_s - execute_s - reset_s
  // Of overhead_s, the service's own work on the trial's path: the claim up to
  // EXECUTE sent, the stream's last input taken up to RESET sent, RESET_DONE
  // taken up to this figure. The rest (overhead_s - service_s) is the wire:
  // four DDS hops, the cell's time outside its phases, the service loop's waits.
  double service_s = 0;
  // overhead_s in the four legs of the trial's path, which add up to it (s):
  // the claim (or freeing) until the EXECUTE is sent; the EXECUTE's round
  // trip beyond the cell's execute (until the input that completed the
  // stream is taken); from that input until the RESET is sent; the RESET's
  // round trip beyond the cell's reset (until its RESET_DONE is taken).
  double claim_to_execute_s = 0;
  double execute_round_trip_s = 0;
  double stream_to_reset_s = 0;
  double reset_round_trip_s = 0;
};

// @throws std::invalid_argument naming the option ("--reset-timeout: ...")
//   for a value that would break the service (NaN, infinite, negative, absurd).
void ValidateServiceOptions(const ServiceOptions& options);

class Service {
 public:
  // Opens the store, registers as its service (heartbeat) and joins the domain.
  // @throws db::StoreError (kBusy naming pid and host when another service
  //   serves the store), dds::DdsError, std::invalid_argument (bad options).
  explicit Service(const ServiceOptions& options);
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  // Runs until Stop() (or, with exit_when_done, until the campaigns are done).
  // @returns 0 on a clean stop.
  int Run();
  // Thread-safe and async-signal-safe (sets a flag): stop dispatching and drain.
  void Stop();
  ServiceCounters counters() const;
  // Called from Run()'s thread about every 100 ms (progress bars).
  void OnTick(std::function<void(const ServiceCounters&)> callback);
  // Called from Run()'s thread once per trial whose EXECUTE and RESET both
  // succeeded (failed or retried phases have no meaningful split).
  void OnTrialTiming(std::function<void(const TrialTiming&)> callback);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arena::orchestrator
