// The service's decisions; the contract and the state machine are in trial_driver.hpp.
#include "arena/orchestrator/trial_driver.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <set>
#include <utility>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/truth.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/claim_chooser.hpp"
#include "arena/orchestrator/claim_gate.hpp"
#include "arena/orchestrator/closed_loop.hpp"
#include "arena/orchestrator/logging.hpp"
#include "arena/orchestrator/trial_data.hpp"
#include "arena/schemas/fixtures.hpp"
#include "arena/schemas/ground_truth.hpp"
#include "store_steps.hpp"

namespace arena::orchestrator {

std::string SessionHex(std::uint64_t session) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(session));
  return buf;
}

namespace {

using assessment::ContactNormals;
using Clock = DriverClock;
using Seconds = std::chrono::duration<double>;

Clock::duration Dur(double seconds) {
  return std::chrono::duration_cast<Clock::duration>(Seconds(seconds));
}

// The wire's words (msg::) as the trial policy's types.
StatusPhase ToPolicy(msg::Phase p) {
  return p == msg::PHASE_RESET ? StatusPhase::kReset : StatusPhase::kExecute;
}
StatusState ToPolicy(msg::TrialState s) {
  switch (s) {
    case msg::STATE_ACCEPTED:
      return StatusState::kAccepted;
    case msg::STATE_EXECUTED:
      return StatusState::kExecuted;
    case msg::STATE_RESET_DONE:
      return StatusState::kResetDone;
    case msg::STATE_REFUSED:
      return StatusState::kRefused;
    case msg::STATE_FAILED:
      break;
  }
  return StatusState::kFailed;
}
FailureKind ToPolicy(msg::FailureKind k) {
  switch (k) {
    case msg::FAILURE_SIMULATION:
      return FailureKind::kSimulation;
    case msg::FAILURE_DEADLINE:
      return FailureKind::kDeadline;
    case msg::FAILURE_INTERRUPTED:
      return FailureKind::kInterrupted;
    case msg::FAILURE_RESET:
      return FailureKind::kReset;
    case msg::FAILURE_INTERNAL:
      return FailureKind::kInternal;
    case msg::FAILURE_CONTROLLER:
      return FailureKind::kController;
    case msg::FAILURE_NONE:
      break;
  }
  return FailureKind::kNone;
}

db::ResetReport UnobservedReset(const std::string& reason) {
  db::ResetReport r;
  r.ok = false;
  r.reason = reason;
  r.pose_observed = false;
  return r;
}

}  // namespace

std::int64_t TrialStore::PublishExecuted(GroundTruthSink& sink, std::int64_t trial_id, int attempt,
                                         const db::FinishAlso& also) {
  if (also.execution)
    RecordExecution(trial_id, attempt, also.execution->backend, also.execution->truth,
                    also.execution->defects_applied_json);
  const std::int64_t n = sink.Finish();
  if (!also.begin_reset_rule.empty()) BeginReset(trial_id, attempt, also.begin_reset_rule);
  return n;
}

struct TrialDriver::Impl {
  DriverOptions opt;
  ServiceIdentity me;
  TrialStore& store;
  CommandTransport& transport;
  PredictionPort& predictions;
  std::function<Clock::time_point()> now;

  mutable std::mutex counters_mu;
  ServiceCounters counters;
  std::function<void(const TrialTiming&)> on_trial_timing;
  std::function<void(const std::string&, bool)> on_path_change;
  TrialObserver* observer = nullptr;  // the suspenders (suspenders.hpp)

  enum class ResetAhead { kNo, kPublishPending, kForNoTrial };

  // A trial's scene parsed ahead, while the cell runs the trial before it
  // (StartExecution), for its claim to use: the parse is then off the path
  // from the cell's RESET_DONE to its EXECUTE (issue 27).
  struct ParsedScene {
    std::int64_t trial_id = 0;
    std::string scene_json;
    mechanics::Scene scene;
    std::vector<Eigen::Vector3d> normals;
  };
  static constexpr std::size_t kMaxHeldStatuses = 4;    // a cell sends two per reset
  static constexpr std::size_t kMaxHeldBatches = 4096;  // a queued trial's, before it runs

  struct CellRun {
    std::string id;
    bool alive = true;
    bool quarantined = false;
    bool ours = false;              // its announce names our session
    std::uint64_t incarnation = 0;  // the announcing process's start (started_unix_ns)
    std::string serving;            // who else it serves ("" = us / nobody), as stored
    int execute_failures = 0;       // phases in a row that failed by the cell's fault
    int reset_failures = 0;
    int failures_in_a_row = 0;  // failed phases in a row, whoever caused them (the backoff)
    std::vector<std::string> contact_types;
    std::string capabilities_json = "{}", defects_json = "{}";
    std::string truth;  // the kind of truth it announced ("measured": an imported recording)
    double speed = 1.0;
    CellPhase phase = CellPhase::kIdle;
    std::int64_t trial_id = 0, campaign_id = 0;
    int attempt = 0;
    Clock::time_point deadline{};
    Clock::time_point next_claim{};
    Clock::time_point claimed_at{};
    Clock::time_point idle_since{};  // when SetPhase last left it idle
    // The path's marks (TrialTiming::service_s): EXECUTE sent, the input that
    // completed the stream (its last batch or its EXECUTED status) taken, the
    // stream's publish begun from it, RESET sent, RESET_DONE taken.
    Clock::time_point execute_sent{}, stream_input_at{}, publish_from{}, reset_sent{},
        reset_taken{};
    double execute_wall_s = -1;
    int store_waits = 0;  // store steps of this cell waiting after kBusy: deadlines held
    std::int64_t reset_aimed_at = 0;   // the trial the running reset prepares (0: none)
    bool store_failures_zero = false;  // the store's count of failures in a row is 0
    // Issue 29: its declared change costs (nullopt: none declared, plan
    // order), what the service last saw it mount (nullopt: not known), what
    // its running reset mounts, and the block of its last claim.
    std::optional<schemas::ChangeCosts> change_costs;
    std::optional<schemas::Fixtures> mounted;
    std::optional<schemas::Fixtures> reset_mounts;
    // The trial this cell most likely runs next, looked up while it executes
    // (the lookup is then off the path from its stream to its RESET);
    // `aim_known` false: not looked up, the reset step looks it up itself.
    std::optional<db::ClaimedTrial> next_aim;
    bool aim_known = false;
    std::shared_ptr<ParsedScene> aim_scene;  // next_aim's, parsed (null: not parsed)
    // Issue 27: its RESET went out before the publish of the stream it
    // follows committed (DecideResetAhead): the statuses of that reset held
    // until the publish ends, and whether the reset still runs for no trial
    // (the publish refused). Both cleared when the cell goes idle.
    ResetAhead reset_ahead = ResetAhead::kNo;
    std::vector<msg::TrialStatus> held_reset;
    std::int64_t block_campaign = 0, block = -1;
    // Issue 27: the trial whose EXECUTE went out behind the cell's RESET
    // (TrialCommand.after_reset_*, QueueNext): the cell runs it right after
    // that reset ended done (DecideQueued). Its Execution exists from the
    // send; its statuses wait in `held` until the reset's status is taken.
    struct Queued {
      std::int64_t trial_id = 0, campaign_id = 0;
      int attempt = 0;
      double budget_s = 0;
      std::vector<msg::TrialStatus> held;
      std::vector<msg::GroundTruth> held_truth;  // its batches, likewise
    };
    std::optional<Queued> queued;
    HostCell host;  // what it announced it can do (the claim gate, claim_gate.hpp)
  };
  std::map<std::string, CellRun> cells;

  struct Execution {
    std::int64_t trial_id = 0, campaign_id = 0;
    int attempt = 0;
    std::string cell_id;
    mechanics::Scene scene;
    std::string scene_json;
    std::vector<Eigen::Vector3d> normals;
    std::unique_ptr<GroundTruthSink> sink;  // null after a busy store broke it: re-ingest
    std::vector<db::Sample> samples;        // everything received, for a re-ingest
    std::uint32_t next_sample = 0;
    std::int64_t expected = -1;
    Clock::time_point stream_deadline{};
    std::vector<mechanics::TrajectorySample> truth;
    // A measured cell may send samples without contacts: a trial whose truth
    // measured no forces. It must say so in its EXECUTE status (truth
    // dds::kTruthMeasuredNoForces), and then every sample must be so.
    bool measured_cell = false;
    std::int64_t contactless = 0;  // samples received without contacts
    // What the EXECUTED status's detail says ran the trial (set with
    // `expected`; nullopt: no status yet, or a detail that is not a JSON
    // object): its truth decides StreamProblem; it becomes `execution` after
    // the RESET went out (ReadExecution). Read in one pass that builds no
    // document (issue 27: the parse was the largest step between the
    // stream's end and the RESET).
    std::optional<ExecutionDetail> detail;
    std::string StatedTruth() const { return detail ? detail->truth : std::string(); }
    assessment::RecordedCommands commands;  // closed loop: the commands the cell applied
    bool publishing = false;  // the publish step is under way (or waiting on the store)
    // What the EXECUTED status said ran the trial, when it is written with the
    // publish (PublishExecuted) instead of on its own.
    std::optional<db::ExecutionRecord> execution;
  };
  std::map<std::int64_t, Execution> executions;
  std::map<std::int64_t, PredictionDone> waiting_predictions;

  // Store steps, and those waiting after a busy store (store_steps.hpp).
  StoreSteps steps;

  Clock::time_point next_claims{}, next_beat{}, next_file_check{}, next_campaigns{};
  // The claim gate (issue 26): each waiting campaign's stored reason; the
  // gate re-decides every kGatePeriod_s, at once when the cells change, and
  // before a claim when the active campaigns are not those it decided on
  // (`gated_active`): the store's claims take only from campaigns it opened.
  std::map<std::int64_t, std::string> campaign_waits;
  std::optional<std::vector<std::int64_t>> gated_active;
  bool waits_loaded = false, gate_dirty = true;
  Clock::time_point next_gate{};
  static constexpr double kGatePeriod_s = 5.0;

  Impl(DriverOptions o, ServiceIdentity m, TrialStore& s, CommandTransport& t, PredictionPort& p,
       std::function<Clock::time_point()> n)
      : opt(std::move(o)),
        me(std::move(m)),
        store(s),
        transport(t),
        predictions(p),
        now(std::move(n)),
        steps(now, [this](const std::string& cell_id, int delta) {
          Cell(cell_id).store_waits += delta;
        }) {}

  void Count(std::int64_t ServiceCounters::*field, std::int64_t n = 1) {
    std::lock_guard lock(counters_mu);
    counters.*field += n;
  }

  // ------------------------------------------------------------ store policy
  // store_steps.hpp: kBusy queues the step again (the cell, if any, waits
  // with its deadlines held); fatal kinds are rethrown; others go to on_moot
  // (or a log line). @returns true when the step ran to its end now.
  bool Step(const std::string& what, const std::string& cell_id, const StoreSteps::Run& run,
            const StoreSteps::OnMoot& on_moot = {}) {
    return steps.Step(what, cell_id, run, on_moot);
  }
  void Attempt(const std::string& what, const StoreSteps::Run& run) { steps.Attempt(what, run); }

  // ------------------------------------------------------------ cells
  CellRun& Cell(const std::string& id) {
    auto [it, inserted] = cells.try_emplace(id);
    if (inserted) it->second.id = id;
    return it->second;
  }

  // The one place a cell's phase changes.
  void SetPhase(CellRun& cell, CellPhase phase, double deadline_s = 0) {
    cell.phase = phase;
    if (on_path_change) on_path_change(cell.id, false);  // handed a phase, or left idle
    if (phase == CellPhase::kIdle) {
      cell.idle_since = now();
      // A reset run out after a refused publish keeps the refusal's backoff.
      cell.next_claim =
          cell.reset_ahead == ResetAhead::kForNoTrial ? std::max(cell.next_claim, now()) : now();
      cell.reset_ahead = ResetAhead::kNo;
      cell.held_reset.clear();
    } else {
      cell.deadline = now() + Dur(deadline_s);
    }
  }

  msg::TrialCommand Command(const CellRun& cell, msg::Phase phase) {
    msg::TrialCommand cmd;
    cmd.cell_id(cell.id);
    cmd.phase(phase);
    cmd.service_session(me.session);
    return cmd;
  }

  void SendClaim(const CellRun& cell) {
    msg::TrialCommand cmd = Command(cell, msg::PHASE_CLAIM);
    cmd.lease_s(opt.claim_lease_s);
    cmd.service_host(me.host);
    cmd.service_pid(me.pid);
    cmd.service_store(me.store_id);
    transport.Send(cmd);
  }

  void OnAnnounce(const msg::CellAnnounce& a) {
    const std::string id = a.cell_id();
    CellRun& cell = Cell(id);
    const bool was_alive = cell.alive;
    const bool restarted = cell.incarnation != 0 && cell.incarnation != a.started_unix_ns();
    cell.incarnation = a.started_unix_ns();
    cell.alive = true;
    if (observer) observer->OnCellAlive(id, true);
    cell.speed = a.speed();
    nlohmann::json caps = {{"workspace_min", a.workspace_min()},
                           {"workspace_max", a.workspace_max()},
                           {"max_pusher_speed", a.max_pusher_speed()},
                           {"speed", a.speed()},
                           {"arena_version", a.arena_version()},
                           {"backend", a.backend()},
                           {"truth", a.truth()}};
    cell.contact_types = a.contact_types();
    cell.truth = a.truth();
    const HostCell host = AnnouncedHost(a);
    if (!SameHost(host, cell.host)) gate_dirty = true;  // announces repeat: decide on a change
    cell.host = host;
    caps["emulates_defects"] = cell.host.emulates_defects;
    cell.change_costs = DeclaredCosts(id, a.backend_json());
    if (cell.change_costs) {
      caps[schemas::kChangeCostsKey] = {{"finger_s", cell.change_costs->finger_s},
                                        {"pusher_s", cell.change_costs->pusher_s},
                                        {"object_s", cell.change_costs->object_s}};
    }
    if (restarted) cell.mounted.reset();  // a new process: nothing known mounted
    cell.capabilities_json = caps.dump();
    cell.defects_json = a.defects_json();
    if (restarted && cell.phase != CellPhase::kIdle)
      EndPhase(cell, DecideServiceEvent(cell.phase, ServiceEvent::kCellRestarted),
               "cell " + id + " restarted");
    Step("cell " + id + ": announcement", "", [this, id, was_alive] {
      CellRun& c = Cell(id);
      store.UpsertCell(id, c.contact_types, c.capabilities_json, c.defects_json);
      c.quarantined = store.CellQuarantined(id);
      if (!was_alive || cells.size() == 1)
        spdlog::info("cell {} announced ({} contact types)", id, c.contact_types.size());
    });
    const bool ours = a.serving_session() == me.session;
    std::string serving;
    if (!ours && a.serving_session() != 0) {
      serving = "serving service " + SessionHex(a.serving_session()) + " on host " +
                (a.serving_host().empty() ? "?" : a.serving_host()) + " (pid " +
                std::to_string(a.serving_pid()) + ")";
    }
    if (cell.ours && !ours && cell.phase != CellPhase::kIdle)
      EndPhase(cell, DecideServiceEvent(cell.phase, ServiceEvent::kCellServesAnother),
               "cell " + id + " now " + (serving.empty() ? "serves nobody" : serving));
    if (ours != cell.ours || serving != cell.serving) {
      if (!serving.empty()) spdlog::warn("cell {} is {}", id, serving);
      if (ours) spdlog::info("cell {}: serving us", id);
      cell.ours = ours;
      cell.serving = serving;
      gate_dirty = true;
      Step("cell " + id + ": serving", "",
           [this, id, serving] { store.SetCellServing(id, opt.cell_lease_s, serving); });
    }
    if (!ours && a.serving_session() == 0) SendClaim(cell);  // free: ask at once
  }

  void OnCellLost(const std::string& id, const std::string& reason, bool another_process) {
    auto it = cells.find(id);
    if (it == cells.end()) return;
    CellRun& cell = it->second;
    if (another_process) {
      // A restart within the lease: the old process's loss arrives after the
      // new one announced. The id stays alive (a phase of the old one is
      // aborted by the new incarnation's announce).
      spdlog::info("cell {}: an older process with this id is gone ({}); the new one stays", id,
                   reason);
      return;
    }
    if (!cell.alive) return;
    spdlog::warn("cell {}: {}", id, reason);
    if (observer) observer->OnCellAlive(id, false);
    cell.alive = false;
    gate_dirty = true;  // (`ours` stays: a process back from a lapse may still serve us;
                        // a new one announces that it serves nobody)
    EndPhase(cell, DecideServiceEvent(cell.phase, ServiceEvent::kCellLost), "cell lost: " + reason);
    Step("cell " + id + ": gone", "", [this, id, reason] { store.MarkCellGone(id, reason); });
  }

  void OnCellAlive(const std::string& id) {
    auto it = cells.find(id);
    if (it == cells.end() || it->second.alive) return;
    CellRun& cell = it->second;
    cell.alive = true;
    gate_dirty = true;
    if (observer) observer->OnCellAlive(id, true);
    cell.next_claim = now();
    SendClaim(cell);
    Step("cell " + id + ": alive again", "", [this, id] {
      CellRun& c = Cell(id);
      store.UpsertCell(id, c.contact_types, c.capabilities_json, c.defects_json);
      spdlog::info("cell {}: alive again", id);
    });
  }

  // Counts a phase result (quarantine after quarantine_after failures with no
  // fully clean trial between them).
  // Store writes no cell waits on (a clean trial's prediction and done, a
  // healthy cell's good result). Tick runs them after Dispatch, so they fall
  // in a cell's execute phase instead of between its stream and its next
  // claim (issue 27: the per-trial overhead). A crash before they run loses
  // nothing the restart does not redo: the trial is predicted again, the
  // cell's count of failures in a row was already 0.
  std::deque<std::function<void()>> background;
  std::function<bool()> input_waiting;  // TrialDriver::OnInputWaiting
  // One at least per Tick (progress under a steady stream of inputs), the
  // rest only while no input waits: a cell whose reset ended meanwhile gets
  // its EXECUTE before these writes, not after them (issue 27).
  void RunBackground() {
    for (bool first = true; !background.empty(); first = false) {
      if (!first && input_waiting && input_waiting()) return;
      auto work = std::move(background.front());
      background.pop_front();
      work();
    }
  }

  void CellResult(CellRun& cell, CellPhase phase, bool ok, const std::string& reason) {
    int& streak = phase == CellPhase::kResetting ? cell.reset_failures : cell.execute_failures;
    const int other = phase == CellPhase::kResetting ? cell.execute_failures : cell.reset_failures;
    const bool was_clean = streak == 0 && other == 0 && cell.store_failures_zero;
    if (ok) {
      streak = 0;
      if (other != 0) return;
    } else {
      ++streak;
      cell.store_failures_zero = false;
    }
    const std::string id = cell.id;
    if (ok && was_clean) {  // only last_seen moves: once per trial, off the critical path
      if (phase != CellPhase::kResetting) return;
      background.push_back([this, id] {
        Step("cell " + id + ": result", "", [this, id] { store.RecordCellResult(id, true); });
      });
      return;
    }
    Step("cell " + id + ": result", id, [this, id, ok, reason] {
      const int failures = store.RecordCellResult(id, ok);
      Cell(id).store_failures_zero = failures == 0;
      if (ok || failures < opt.service.quarantine_after) return;
      const std::string why = std::to_string(failures) + " failures in a row, last: " + reason;
      store.QuarantineCell(id, why);
      Cell(id).quarantined = true;
      Count(&ServiceCounters::quarantined);
      spdlog::error("cell {} quarantined: {}", id, why);
    });
  }

  // Executes a policy decision that ends the cell's phase (trial_policy.hpp):
  // the trial retried or failed, or its reset closed as not observed; the
  // failure counted against the cell only when it was the cell's; the backoff.
  void EndPhase(CellRun& cell, const Decision& d, const std::string& reason) {
    const CellPhase phase = cell.phase;
    if (phase == CellPhase::kIdle || !d.ends_phase()) return;
    EndQueued(cell, QueuedEvent::kPhaseEnded, "its cell's phase before it ended: " + reason);
    if (phase == CellPhase::kExecuting) {
      if (cell.reset_ahead == ResetAhead::kPublishPending)  // its held statuses go (SetPhase)
        spdlog::info("cell {}: {}", cell.id, DecideResetAhead(AheadEvent::kAttemptEnded).rule);
      auto it = executions.find(cell.trial_id);
      if (it != executions.end()) {
        Execution& ex = it->second;
        // What ran the attempt is recorded though its stream is not published.
        ReadExecution(ex);
        if (ex.execution) WriteExecution(ex.trial_id, ex.attempt, *std::exchange(ex.execution, {}));
        if (d.trial == TrialStep::kFail)
          FailTrial(ex.trial_id, ex.campaign_id, ex.attempt, reason, d.outcome, d.rule);
        else
          RetryExecution(ex.trial_id, ex.campaign_id, ex.attempt, reason, d.rule);
        executions.erase(it);
      }
    } else if (phase == CellPhase::kResetting && cell.reset_ahead != ResetAhead::kForNoTrial) {
      CompleteReset(cell.trial_id, cell.attempt, UnobservedReset(reason), cell.id, d.rule);
    }
    if (d.counts_against_cell()) CellResult(cell, phase, false, reason);
    SetPhase(cell, CellPhase::kIdle);
    BackOff(cell, d, reason);
  }

  // After a failed phase the cell waits before its next trial (a paused
  // controller, a store under load: not trial after trial within a second).
  void BackOff(CellRun& cell, const Decision& d, const std::string& reason) {
    if (d.back_off) {
      ++cell.failures_in_a_row;
      const double wait = CellBackoff_s(cell.failures_in_a_row, opt.service.cell_backoff_s,
                                        opt.service.cell_backoff_max_s);
      cell.next_claim = now() + Dur(wait);
      spdlog::warn("cell {}: {} ({}; blame: {}); next trial in {:.2g} s", cell.id, reason, d.rule,
                   ToString(d.blame), wait);
    } else if (d.pause_s > 0) {
      cell.next_claim = now() + Dur(d.pause_s);
    }
  }

  void RetryExecution(std::int64_t trial_id, std::int64_t campaign_id, int attempt,
                      const std::string& reason, const std::string& rule) {
    const std::string tag = TrialTag(campaign_id, trial_id, attempt);
    Step(tag + ": retry", "", [this, tag, trial_id, attempt, reason, rule] {
      const db::TrialState next =
          store.RetryTrial(trial_id, attempt, reason, opt.service.max_attempts,
                           opt.service.retry_backoff_s * std::pow(2.0, attempt - 1), rule);
      if (next == db::TrialState::kFailed) {
        Count(&ServiceCounters::failed);
        spdlog::error("{}: failed, no attempts left: {} ({})", tag, reason, rule);
      } else {
        Count(&ServiceCounters::retried);
        spdlog::warn("{}: will be retried: {} ({})", tag, reason, rule);
      }
    });
  }

  void FailTrial(std::int64_t trial_id, std::int64_t campaign_id, int attempt,
                 const std::string& reason, db::TrialEnd outcome, const std::string& rule) {
    const std::string tag = TrialTag(campaign_id, trial_id, attempt);
    Step(tag + ": fail", "", [this, tag, trial_id, attempt, reason, outcome, rule] {
      store.FailTrial(trial_id, attempt, reason, outcome, rule);
      Count(&ServiceCounters::failed);
      spdlog::error("{}: failed: {} ({})", tag, reason, rule);
    });
  }

  // resetting -> reset_done | reset_failed, then the prediction waiting for it.
  // `after_dispatch`: a clean reset's record is written after Tick's dispatch
  // (Tick's background), so the cell's next EXECUTE goes out before this
  // commit instead of after it (issue 27: the overhead per trial). Nobody
  // waits on it: a busy store retries it while the cell runs its next trial,
  // and a crash before it leaves the trial resetting, which the restart
  // closes as reset_failed (not observed), as for a status lost in flight.
  void CompleteReset(std::int64_t trial_id, int attempt, const db::ResetReport& report,
                     const std::string& cell_id, const std::string& rule,
                     bool after_dispatch = false) {
    resets_completing.insert(trial_id);  // at once: a prediction waits for it (ResetInFlight)
    auto step = [this, trial_id, attempt, report, rule](const std::string& waiting_cell) {
      Step(
          "trial " + std::to_string(trial_id) + ": complete reset", waiting_cell,
          [this, trial_id, attempt, report, rule] {
            store.CompleteReset(trial_id, attempt, report, rule);
            resets_completing.erase(trial_id);
            if (!report.ok) Count(&ServiceCounters::resets_failed);
            AfterReset(trial_id);
          },
          [this, trial_id](const db::StoreError& e) {
            resets_completing.erase(trial_id);
            spdlog::error("trial {}: complete reset: {}", trial_id, e.what());
          });
    };
    if (after_dispatch)
      background.push_back([step] { step(""); });
    else
      step(cell_id);
  }
  std::set<std::int64_t> resets_completing;  // CompleteReset under way (or waiting on the store)

  // ------------------------------------------------------------ fixtures (issue 29)
  // A cell's change costs from its announcement (backend_json, fixtures.hpp);
  // nullopt when it declares none or they are unusable (logged: it then
  // claims in plan order).
  static std::optional<schemas::ChangeCosts> DeclaredCosts(const std::string& id,
                                                           const std::string& backend_json) {
    const auto j = nlohmann::json::parse(backend_json, nullptr, false);
    if (!j.is_object() || !j.contains(schemas::kChangeCostsKey)) return std::nullopt;
    const auto& c = j[schemas::kChangeCostsKey];
    schemas::ChangeCosts costs;
    std::string why;
    if (!c.is_object()) why = "not an object";
    for (auto [key, out] :
         {std::pair{"finger_s", &costs.finger_s}, std::pair{"pusher_s", &costs.pusher_s},
          std::pair{"object_s", &costs.object_s}}) {
      if (!why.empty()) break;
      if (!c.contains(key) || !c[key].is_number()) {
        why = std::string(key) + ": a number is required";
      } else {
        *out = c[key].get<double>();
      }
    }
    if (why.empty()) why = schemas::CheckChangeCosts(costs);
    if (!why.empty()) {
      spdlog::warn("cell {}: announced {}: {}; it claims in plan order", id,
                   schemas::kChangeCostsKey, why);
      return std::nullopt;
    }
    return costs;
  }

  // The fixtures a trial's scene needs (cached: a scene never changes).
  std::map<std::int64_t, schemas::Fixtures> fixtures_of;
  const schemas::Fixtures& FixturesOfTrial(std::int64_t trial_id, const std::string& scene_json) {
    auto it = fixtures_of.find(trial_id);
    if (it != fixtures_of.end()) return it->second;
    if (fixtures_of.size() > 4096) fixtures_of.clear();  // bounded: weeks of trials
    schemas::Fixtures f;
    try {
      f = schemas::FixturesOf(mechanics::ParseScene(scene_json));
    } catch (const std::exception&) {
      f = {"?", "?", "?"};  // the claim fails the trial with the parse error (StartExecution)
    }
    return fixtures_of.emplace(trial_id, std::move(f)).first->second;
  }

  struct CampaignScheduling {
    SchedulingOptions options;
    std::uint64_t seed = 0;
  };
  std::map<std::int64_t, CampaignScheduling> scheduling;
  const CampaignScheduling& SchedulingOf(std::int64_t campaign_id) {
    auto it = scheduling.find(campaign_id);
    if (it != scheduling.end()) return it->second;
    const db::Campaign c = store.GetCampaign(campaign_id);
    CampaignScheduling s;
    s.seed = c.seed;
    try {
      if (!c.spec_json.empty()) s.options = ReadScheduling(c.spec_json);
    } catch (const std::exception& e) {  // validated at submit; an old or edited store
      spdlog::warn("campaign {}: scheduling: {}; claims in plan order", campaign_id, e.what());
      s.options.change_aware = false;
    }
    return scheduling.emplace(campaign_id, s).first->second;
  }

  // How many planned trials the chooser weighs for a claim from the campaign.
  int WindowOf(std::int64_t campaign_id) {
    const SchedulingOptions& o = SchedulingOf(campaign_id).options;
    return o.change_aware ? std::clamp(o.window, 1, kMaxSchedulingWindow) : 1;
  }

  // The aimed trial went to another cell since it was looked up (one service
  // claims for every cell of a store: its own record is the truth).
  bool ClaimedByAnother(const CellRun& cell) const {
    for (const auto& [id, other] : cells)
      if (id != cell.id && (other.trial_id == cell.next_aim->trial_id ||
                            (other.queued && other.queued->trial_id == cell.next_aim->trial_id)))
        return true;
    return false;
  }

  // The one place the claim chooser (claim_chooser.hpp) is called: the trial
  // `cell` claims now (`claim`), or would claim (to aim its reset at).
  std::optional<db::ClaimedTrial> NextTrialFor(CellRun& cell, bool claim) {
    std::vector<db::ClaimedTrial> window;
    if (cell.change_costs) {
      // One block of the campaign it claims from is all the chooser reads:
      // as many trials as that campaign's window (1 in plan order), not
      // kMaxSchedulingWindow scenes on every claim (issue 27). The campaign
      // of its last claim sizes the read; another campaign's, read again.
      const int guess =
          cell.block_campaign != 0 ? WindowOf(cell.block_campaign) : kMaxSchedulingWindow;
      window = store.ClaimWindow(cell.id, guess);
      if (!window.empty() && window.front().campaign_id != cell.block_campaign) {
        const int need = WindowOf(window.front().campaign_id);
        if (need > guess && static_cast<int>(window.size()) == guess)
          window = store.ClaimWindow(cell.id, need);
      }
    }
    if (window.empty()) return claim ? store.ClaimNextTrial(cell.id) : store.PeekNextTrial(cell.id);
    const std::int64_t campaign = window.front().campaign_id;
    const CampaignScheduling& cs = SchedulingOf(campaign);
    const std::int64_t block = BlockOf(window.front().index, cs.options.window);
    std::vector<ClaimCandidate> candidates;
    for (const auto& t : window) {
      if (BlockOf(t.index, cs.options.window) != block) break;
      candidates.push_back({t.trial_id, t.index, FixturesOfTrial(t.trial_id, t.scene_json)});
    }
    ClaimerState who;
    who.mounted = cell.mounted;
    who.costs = cell.change_costs;
    if (cell.block_campaign == campaign) who.last_block = cell.block;
    who.draw_seed = DrawSeed(cs.seed, cell.id);
    const std::optional<ClaimChoice> choice = ChooseClaim(cs.options, candidates, who);
    if (!choice) return std::nullopt;
    if (!claim) {
      for (const auto& t : window)
        if (t.trial_id == choice->trial_id) return t;
      return std::nullopt;
    }
    std::optional<db::ClaimedTrial> claimed =
        store.ClaimTrial(cell.id, choice->trial_id, choice->rule);
    if (claimed) {
      cell.block_campaign = campaign;
      cell.block = choice->block;
    }
    return claimed;
  }

  // Records the changes from what `cell` has mounted to `next` (the cell
  // makes them: executors/trial_start.hpp) and takes `next` as mounted.
  // `after_dispatch`: the records are written after Tick's dispatch (nothing
  // the claim reads: it reads `mounted`, set here at once).
  void RecordChanges(CellRun& cell, std::int64_t trial_id, int attempt, const char* phase,
                     const schemas::Fixtures& next, bool after_dispatch = false) {
    if (!cell.change_costs) return;
    std::vector<db::FixtureChangeRecord> records;
    for (const auto& c : schemas::ChangesBetween(cell.mounted, next, *cell.change_costs)) {
      db::FixtureChangeRecord r;
      r.trial_id = trial_id;
      r.attempt = attempt;
      r.cell_id = cell.id;
      r.phase = phase;
      r.what = c.what;
      r.from_key = c.from;
      r.to_key = c.to;
      r.seconds = c.seconds;
      records.push_back(std::move(r));
    }
    cell.mounted = next;
    if (records.empty()) return;
    auto write = [this, records] {
      Step("cell " + records.front().cell_id + ": fixture changes", "",
           [this, records] { store.RecordFixtureChanges(records); });
    };
    if (after_dispatch)
      background.push_back(write);
    else
      write();
  }

  // ------------------------------------------------------------ the claim gate (issue 26)
  static HostCell AnnouncedHost(const msg::CellAnnounce& a) {
    HostCell h;
    h.id = a.cell_id();
    h.backend = a.backend();
    const auto j = nlohmann::json::parse(a.backend_json(), nullptr, false);
    // An older cell that does not say: as before the gate (it refuses what it cannot).
    h.emulates_defects =
        !(j.is_object() && j.contains("emulates_defects") && j["emulates_defects"].is_boolean() &&
          !j["emulates_defects"].get<bool>());
    for (const auto& t : a.contact_types())
      h.contact_mask |= t == "point" ? 1 : t == "line" ? 2 : t == "patch" ? 4 : 0;
    for (int k = 0; k < 3; ++k) {
      h.workspace_min[k] = a.workspace_min()[k];
      h.workspace_max[k] = a.workspace_max()[k];
    }
    h.max_pusher_speed = a.max_pusher_speed();
    return h;
  }

  static bool SameHost(const HostCell& a, const HostCell& b) {
    return a.id == b.id && a.backend == b.backend && a.emulates_defects == b.emulates_defects &&
           a.contact_mask == b.contact_mask && a.workspace_min == b.workspace_min &&
           a.workspace_max == b.workspace_max && a.max_pusher_speed == b.max_pusher_speed;
  }

  // Decides every active campaign's gate and stores what changed: a
  // campaign no live cell can host waits (the claim skips it), one a cell
  // can host again is released.
  void GateCampaigns() {
    // Read first: a campaign submitted after it is not in `open` below, and
    // the next claim's check sees the active campaigns changed.
    const std::vector<std::int64_t> active = store.ActiveCampaignIds();
    if (!waits_loaded) {  // a restart: the store's waits are decided anew
      for (const auto& w : store.ListCampaignWaits()) campaign_waits[w.campaign_id] = w.reason;
      waits_loaded = true;
    }
    std::vector<HostCell> live;
    for (const auto& [id, cell] : cells)
      if (cell.alive && cell.ours && !cell.quarantined) live.push_back(cell.host);
    std::map<std::int64_t, CampaignNeeds> needs;
    for (const db::PlannedNeed& n : store.PlannedNeeds()) {
      CampaignNeeds& c = needs[n.campaign_id];
      if (c.trials.empty()) {
        c.campaign_id = n.campaign_id;
        c.physics_defects = PhysicsDefects(n.defects_json);
      }
      c.trials.push_back(
          {n.contact_mask, {n.position[0], n.position[1], n.position[2]}, n.pusher_speed});
    }
    for (auto it = campaign_waits.begin(); it != campaign_waits.end();) {
      if (needs.count(it->first)) {
        ++it;
        continue;
      }
      store.ClearCampaignWait(it->first);  // nothing planned (done, paused, cancelled)
      it = campaign_waits.erase(it);
    }
    for (const auto& [id, c] : needs) {
      const GateDecision d = DecideClaimGate(c, live);
      auto it = campaign_waits.find(id);
      if (d.waits && (it == campaign_waits.end() || it->second != d.reason)) {
        store.SetCampaignWait(id, std::string(ToString(d.kind)), d.reason, d.rule);
        campaign_waits[id] = d.reason;
        spdlog::warn("campaign {} waits: {} ({})", id, d.reason, d.rule);
      } else if (!d.waits && it != campaign_waits.end()) {
        store.ClearCampaignWait(id);
        campaign_waits.erase(it);
        spdlog::info("campaign {}: a live cell can host it again; dispatch resumes ({})", id,
                     d.rule);
      }
    }
    std::vector<std::int64_t> open;
    for (const std::int64_t id : active)
      if (!campaign_waits.count(id)) open.push_back(id);
    store.RestrictClaimsTo(std::move(open));
    gated_active = active;
  }

  // Before a claim: a campaign submitted or resumed since the gate last ran
  // is decided now, not dispatched ungated.
  void GateNewCampaigns() {
    if (store.ActiveCampaignIds() == gated_active) return;
    gate_dirty = false;
    next_gate = now() + Dur(kGatePeriod_s);
    GateCampaigns();
  }

  // ------------------------------------------------------------ dispatch
  bool backlog_held = false;          // the prediction backlog holds dispatch (logged once)
  int predictions_queued = 0;         // requests waiting in `background` to be started
  Clock::time_point last_dispatch{};  // when the previous Dispatch pass began
  void Dispatch(bool stopping) {
    const auto t = now();
    const auto previous_pass = std::exchange(last_dispatch, t);
    if (stopping || !recovered) return;
    // A predictor behind by a full backlog: no new trial until it catches up.
    const int backlog = predictions.outstanding() + predictions_queued;
    if (backlog >= opt.service.prediction_backlog) {
      if (!backlog_held)
        spdlog::warn("{} trials wait for their prediction; no new trial until fewer than {} do",
                     backlog, opt.service.prediction_backlog);
      backlog_held = true;
      return;
    }
    backlog_held = false;
    bool gate_checked = false;
    for (auto& [id, cell] : cells) {
      if (!cell.alive || !cell.ours || cell.quarantined || cell.phase != CellPhase::kIdle ||
          cell.store_waits > 0 || t < cell.next_claim)
        continue;
      cell.next_claim = t + Dur(opt.dispatch_poll_s);        // poll the store gently when idle
      if (observer && observer->DispatchGate(id)) continue;  // a suspension holds it back
      if (!gate_checked) {
        gate_checked = true;
        bool gated = true;
        Attempt("the claim gate", [&] {
          gated = false;
          GateNewCampaigns();
          gated = true;
        });
        if (!gated) return;  // a busy store: no claim past an undecided gate
      }
      std::optional<db::ClaimedTrial> claim;
      const std::string cell_id = id;
      Attempt("cell " + id + ": claim", [&] { claim = NextTrialFor(cell, true); });
      if (!claim) continue;
      // A cell freed since the previous pass waited for this one: that wait
      // is the service's time on the trial's path too (TrialTiming).
      cell.claimed_at = cell.idle_since > previous_pass ? cell.idle_since : t;
      cell.campaign_id = claim->campaign_id;
      cell.execute_wall_s = -1;
      StartExecution(cell, *claim);
    }
  }

  void StartExecution(CellRun& cell, const db::ClaimedTrial& claim) {
    const std::optional<double> budget = PrepareExecution(cell, claim);
    if (!budget) return;
    cell.trial_id = claim.trial_id;
    cell.attempt = claim.attempt;
    SetPhase(cell, CellPhase::kExecuting, *budget + 2.0);
    const std::string tag = TrialTag(claim.campaign_id, claim.trial_id, claim.attempt);
    // EXECUTE first, then the sink: no commit between the claim and the
    // command (issue 27). Nothing the cell sends is read before the sink
    // exists (this thread takes both). A busy store leaves no sink: the
    // stream is kept in memory and written whole at its end (the publish
    // step's re-ingest, as after a busy Add); a refusal ends the phase.
    msg::TrialCommand cmd = ExecuteCommand(cell, claim, *budget);
    Count(&ServiceCounters::dispatched);
    if (!transport.Send(cmd)) {
      EndPhase(cell, DecideServiceEvent(cell.phase, ServiceEvent::kCommandNotSent),
               "EXECUTE command could not be sent");
      return;
    }
    cell.execute_sent = now();
    spdlog::info("{}: EXECUTE on cell {}", tag, cell.id);
    if (!BeginSink(cell, claim.trial_id, claim.attempt, tag)) return;
    AimAhead(cell, claim.trial_id, claim.scene_json);
  }

  // The Execution of a claimed trial, in `executions`. @returns its EXECUTE's
  // budget; nullopt when its scene does not parse (the trial is failed).
  std::optional<double> PrepareExecution(CellRun& cell, const db::ClaimedTrial& claim) {
    Execution ex;
    ex.trial_id = claim.trial_id;
    ex.campaign_id = claim.campaign_id;
    ex.attempt = claim.attempt;
    ex.cell_id = cell.id;
    ex.measured_cell = cell.truth == "measured";
    ex.scene_json = claim.scene_json;
    const std::shared_ptr<ParsedScene> ahead = std::exchange(cell.aim_scene, nullptr);
    try {
      if (ahead && ahead->trial_id == claim.trial_id && ahead->scene_json == claim.scene_json) {
        ex.scene = std::move(ahead->scene);
        ex.normals = std::move(ahead->normals);
      } else {
        ex.scene = mechanics::ParseScene(claim.scene_json);
        ex.normals = ContactNormals(ex.scene);
      }
    } catch (const mechanics::SceneError& e) {
      const Decision d = DecideServiceEvent(CellPhase::kIdle, ServiceEvent::kInvalidScene);
      FailTrial(claim.trial_id, claim.campaign_id, claim.attempt,
                std::string("invalid scene: ") + e.what(), d.outcome, d.rule);
      return std::nullopt;
    }
    double budget =
        opt.service.execute_timeout_s + ex.scene.duration * std::max(cell.speed, 0.0) * 1.5;
    // Fixtures other than those mounted are changed first (issue 29): their time too.
    if (cell.change_costs)
      budget += schemas::ChangeSeconds(schemas::ChangesBetween(
                    cell.mounted, FixturesOfTrial(claim.trial_id, claim.scene_json),
                    *cell.change_costs)) *
                std::max(cell.speed, 0.0);
    executions.insert_or_assign(claim.trial_id, std::move(ex));
    return budget;
  }

  msg::TrialCommand ExecuteCommand(const CellRun& cell, const db::ClaimedTrial& claim,
                                   double budget) {
    msg::TrialCommand cmd = Command(cell, msg::PHASE_EXECUTE);
    cmd.trial_id(static_cast<std::uint64_t>(claim.trial_id));
    cmd.attempt(static_cast<std::uint32_t>(claim.attempt));
    cmd.scene_json(claim.scene_json);
    cmd.seed(claim.seed);
    cmd.deadline_s(budget);
    cmd.defects_json(claim.defects_json);  // applied by the cell, or the trial is REFUSED
    return cmd;
  }

  // While it executes: the trial its reset will aim at (see Executed),
  // chosen as if the fixtures of this trial were mounted, as they will be.
  void AimAhead(CellRun& cell, std::int64_t trial_id, const std::string& scene_json) {
    cell.aim_known = false;
    try {
      CellRun probe = cell;
      if (probe.change_costs) probe.mounted = FixturesOfTrial(trial_id, scene_json);
      cell.next_aim = NextTrialFor(probe, false);
      cell.aim_known = true;
    } catch (const db::StoreError& e) {
      if (Judge(e) == StoreVerdict::kStop) throw;  // as any step: the service stops
      spdlog::debug("trial {}: next trial looked up at the reset instead: {}", trial_id, e.what());
    }
    if (cell.next_aim) cell.aim_scene = ParseAhead(*cell.next_aim);
  }

  // ------------------------------------------------------------ the queued trial (issue 27)
  // Right after the RESET after (after_trial, after_attempt) went out: the
  // trial that reset is aimed at is claimed and its EXECUTE sent at once,
  // for the cell to run right after that reset ended done (trial_policy.hpp
  // QueuedEvent). Only where the dispatch would claim for the cell at once:
  // otherwise (or when the aimed trial is no longer claimable, or the store
  // is busy) the dispatch claims after the reset, as ever. The suspenders
  // and the claim gate are asked here, so what the reset itself shows acts
  // from the trial after the queued one.
  bool stopping_now = true;  // the last Tick's `stopping`
  bool MayQueue(const CellRun& cell) const {
    if (!opt.queue_next_execute || stopping_now || !recovered || backlog_held) return false;
    // The trial before it is not yet predicted: it counts.
    if (predictions.outstanding() + predictions_queued + 1 >= opt.service.prediction_backlog)
      return false;
    return cell.alive && cell.ours && !cell.quarantined && cell.store_waits == 0 &&
           cell.failures_in_a_row == 0 && cell.reset_aimed_at != 0 && !cell.queued &&
           !(observer && observer->DispatchGate(cell.id));
  }

  void QueueNext(CellRun& cell, std::int64_t after_trial, int after_attempt) {
    if (!MayQueue(cell)) return;
    std::optional<db::ClaimedTrial> claim;
    try {
      GateNewCampaigns();
      claim = store.ClaimTrial(cell.id, cell.reset_aimed_at, kQueuedClaimRule);
    } catch (const db::StoreError& e) {
      if (Judge(e) == StoreVerdict::kStop) throw;
      spdlog::debug("cell {}: next trial claimed after the reset: {}", cell.id, e.what());
      return;
    }
    if (!claim) return;
    if (cell.change_costs) {
      cell.block_campaign = claim->campaign_id;
      cell.block = BlockOf(claim->index, SchedulingOf(claim->campaign_id).options.window);
    }
    const std::optional<double> budget = PrepareExecution(cell, *claim);
    if (!budget) return;
    const std::string tag = TrialTag(claim->campaign_id, claim->trial_id, claim->attempt);
    cell.queued =
        CellRun::Queued{claim->trial_id, claim->campaign_id, claim->attempt, *budget, {}, {}};
    msg::TrialCommand cmd = ExecuteCommand(cell, *claim, *budget);
    cmd.after_reset_trial_id(static_cast<std::uint64_t>(after_trial));
    cmd.after_reset_attempt(static_cast<std::uint32_t>(after_attempt));
    Count(&ServiceCounters::dispatched);
    if (!transport.Send(cmd)) {
      EndQueued(cell, QueuedEvent::kNotSent, "EXECUTE command could not be sent");
      return;
    }
    spdlog::info("{}: EXECUTE on cell {}, queued behind its reset", tag, cell.id);
    // Its sink after the publish before it (Tick's background): nothing of
    // it arrives before the cell's reset ended. Samples taken before it
    // exists are written whole at the stream's end (the publish's re-ingest).
    const std::string cell_id = cell.id;
    const std::int64_t trial_id = claim->trial_id;
    const int attempt = claim->attempt;
    background.push_back([this, cell_id, trial_id, attempt, tag] {
      auto it = executions.find(trial_id);
      if (it == executions.end() || it->second.attempt != attempt || it->second.sink ||
          it->second.next_sample != 0 || it->second.publishing)
        return;
      BeginSink(Cell(cell_id), trial_id, attempt, tag);
    });
  }

  // The queued trial leaves the cell's queue by `event`'s rule (nothing when
  // the rule keeps it): back to planned, its attempt not counted.
  void EndQueued(CellRun& cell, QueuedEvent event, const std::string& reason) {
    if (!cell.queued) return;
    const QueuedDecision d = DecideQueued(event);
    if (d.step != QueuedStep::kRelease) return;
    const CellRun::Queued q = std::move(*cell.queued);
    cell.queued.reset();
    auto it = executions.find(q.trial_id);
    if (it != executions.end() && it->second.attempt == q.attempt) executions.erase(it);
    const std::string tag = TrialTag(q.campaign_id, q.trial_id, q.attempt);
    spdlog::info("{}: not run on cell {}: {} ({})", tag, cell.id, reason, d.rule);
    const std::string rule = d.rule;
    Step(tag + ": release", "",
         [this, q, reason, rule] { store.ReleaseTrial(q.trial_id, q.attempt, reason, rule); });
  }

  // A message of the cell's queued (trial, attempt) waits for its reset's
  // status to be taken (RunQueued takes it then).
  static bool HoldsForQueued(const CellRun& cell, std::int64_t trial_id, int attempt) {
    return cell.queued && cell.queued->trial_id == trial_id && cell.queued->attempt == attempt &&
           DecideQueued(QueuedEvent::kOwnStatus).step == QueuedStep::kHold;
  }

  // The reset before it ended done: the cell runs the queued trial now.
  // Its time on the cell counts from here (TrialTiming: the cell's cycle).
  void RunQueued(CellRun& cell) {
    const QueuedDecision d = DecideQueued(QueuedEvent::kResetDone);
    if (d.step != QueuedStep::kRun) return;
    CellRun::Queued q = std::move(*cell.queued);
    cell.queued.reset();
    auto it = executions.find(q.trial_id);
    if (it == executions.end() || it->second.attempt != q.attempt) return;
    cell.trial_id = q.trial_id;
    cell.attempt = q.attempt;
    cell.campaign_id = q.campaign_id;
    cell.execute_wall_s = -1;
    cell.claimed_at = cell.execute_sent = now();
    SetPhase(cell, CellPhase::kExecuting, q.budget_s + 2.0);
    spdlog::debug("{}: running on cell {} ({})", TrialTag(q.campaign_id, q.trial_id, q.attempt),
                  cell.id, d.rule);
    AimAhead(cell, q.trial_id, it->second.scene_json);
    for (const msg::GroundTruth& batch : q.held_truth) OnGroundTruth(batch);
    for (const msg::TrialStatus& st : q.held) OnStatus(st);
  }

  // nullptr when the scene does not parse: its claim parses it again and
  // fails the trial with the error (StartExecution).
  static std::shared_ptr<ParsedScene> ParseAhead(const db::ClaimedTrial& trial) {
    auto parsed = std::make_shared<ParsedScene>();
    parsed->trial_id = trial.trial_id;
    parsed->scene_json = trial.scene_json;
    try {
      parsed->scene = mechanics::ParseScene(trial.scene_json);
      parsed->normals = ContactNormals(parsed->scene);
    } catch (const mechanics::SceneError&) {
      return nullptr;
    }
    return parsed;
  }

  // The ingest of a trial whose EXECUTE is sent. @returns false when the
  // store refused it (the phase is ended).
  bool BeginSink(CellRun& cell, std::int64_t trial_id, int attempt, const std::string& tag) {
    auto it = executions.find(trial_id);
    if (it == executions.end() || it->second.attempt != attempt) return false;
    try {
      it->second.sink = store.BeginIngest(trial_id, attempt, ContactSitesOf(it->second.scene));
    } catch (const db::StoreError& e) {
      switch (Judge(e)) {
        case StoreVerdict::kStop:
          throw;
        case StoreVerdict::kRetry:  // no sink: the publish step ingests the whole stream
          spdlog::warn(
              "{}: store busy at the ingest's start ({}); the stream is written at its end", tag,
              e.what());
          return true;
        case StoreVerdict::kMoot:
          if (cell.queued && cell.queued->trial_id == trial_id) {  // not the cell's phase yet
            EndQueued(cell, QueuedEvent::kTruthRefused,
                      std::string("ground truth refused: ") + e.what());
            return false;
          }
          EndPhase(cell, DecideServiceEvent(cell.phase, ServiceEvent::kStoreRefusedTruth),
                   std::string("ground truth refused: ") + e.what());
          return false;
      }
    }
    return true;
  }

  // ------------------------------------------------------------ execute
  void OnGroundTruth(const msg::GroundTruth& batch) {
    if (batch.service_session() != me.session) return;  // another service's trial
    auto it = executions.find(static_cast<std::int64_t>(batch.trial_id()));
    if (it == executions.end() || it->second.attempt != static_cast<int>(batch.attempt()) ||
        it->second.cell_id != batch.cell_id() || it->second.publishing)
      return;
    Execution& ex = it->second;
    CellRun& cell = Cell(ex.cell_id);
    if (HoldsForQueued(cell, ex.trial_id, ex.attempt)) {
      // Before its reset's status was taken (a held RESET_DONE): taken after it (RunQueued).
      if (cell.queued->held_truth.size() < kMaxHeldBatches)
        cell.queued->held_truth.push_back(batch);
      return;  // (past the bound: the stream is incomplete, its deadline retries it)
    }
    cell.stream_input_at = now();
    const std::string problem = dds::CheckBatch(batch, ex.next_sample);
    if (!problem.empty()) {
      FailStream(ex, "malformed ground truth from cell " + batch.cell_id() + ": " + problem,
                 ServiceEvent::kStreamMalformed);
      return;
    }
    std::vector<db::Sample> samples;
    try {
      samples.reserve(batch.samples().size());
      for (const auto& s : batch.samples()) {
        mechanics::TrajectorySample truth;
        samples.push_back(ToStoreSample(s, ex.normals, &truth, ex.measured_cell));
        ex.contactless += truth.contacts.empty() && !ex.normals.empty();
        ex.truth.push_back(std::move(truth));
      }
    } catch (const std::exception& e) {  // a value the store would refuse: the cell's
      FailStream(ex, std::string("ground truth refused: ") + e.what(),
                 ServiceEvent::kStreamMalformed);
      return;
    }
    if (ex.sink) {
      try {
        ex.sink->Add(samples);
      } catch (const db::StoreError& e) {
        switch (Judge(e)) {
          case StoreVerdict::kStop:
            throw;
          case StoreVerdict::kRetry:  // kept in memory; published by a fresh ingest at the end
            spdlog::warn("{}: store busy while ingesting ({}); the stream is re-written at its end",
                         TrialTag(ex.campaign_id, ex.trial_id, ex.attempt), e.what());
            ex.sink.reset();
            break;
          case StoreVerdict::kMoot:
            FailStream(ex, std::string("ground truth refused: ") + e.what(),
                       ServiceEvent::kStoreRefusedTruth);
            return;
        }
      }
    }
    ex.next_sample += static_cast<std::uint32_t>(samples.size());
    Count(&ServiceCounters::samples, static_cast<std::int64_t>(samples.size()));
    ex.samples.insert(ex.samples.end(), std::make_move_iterator(samples.begin()),
                      std::make_move_iterator(samples.end()));
    MaybeFinishExecution(ex.trial_id);
  }

  void FailStream(Execution& ex, const std::string& reason, ServiceEvent event) {
    spdlog::error("{}: {}", TrialTag(ex.campaign_id, ex.trial_id, ex.attempt), reason);
    CellRun& cell = Cell(ex.cell_id);
    EndPhase(cell, DecideServiceEvent(cell.phase, event), reason);
  }

  // Samples without contacts only from a trial whose truth says it measured
  // no forces, and then all of them: never an absence read as a fact.
  // @returns "" when the complete stream may be published.
  static std::string StreamProblem(const Execution& ex) {
    const bool poses_only = ex.StatedTruth() == dds::kTruthMeasuredNoForces;
    if (ex.normals.empty() || !(poses_only ? ex.contactless != ex.next_sample : ex.contactless > 0))
      return "";
    return "ground truth refused: cell " + ex.cell_id + " sent " + std::to_string(ex.contactless) +
           " of " + std::to_string(ex.next_sample) +
           " samples without contacts, and its truth is '" + ex.StatedTruth() +
           "' (only a measured trial that states it measured no forces, '" +
           dds::kTruthMeasuredNoForces + "', may, and then in every sample)";
  }

  void MaybeFinishExecution(std::int64_t trial_id) {
    auto it = executions.find(trial_id);
    if (it == executions.end()) return;
    Execution& ex = it->second;
    if (ex.publishing || ex.expected < 0 || ex.next_sample < ex.expected) return;
    if (const std::string problem = StreamProblem(ex); !problem.empty()) {
      FailStream(ex, problem, ServiceEvent::kStreamMalformed);
      return;
    }
    ex.publishing = true;
    CellRun& cell = Cell(ex.cell_id);
    cell.publish_from = cell.stream_input_at;
    const std::string tag = TrialTag(ex.campaign_id, ex.trial_id, ex.attempt);
    const std::string cell_id = ex.cell_id;
    const int attempt = ex.attempt;
    // Issue 27: the RESET before the publish's commit, so the cell resets
    // while the commit runs (DecideResetAhead). An aim the store cannot look
    // up now, or a RESET not sent: it follows the publish, as it did before.
    try {
      if (SendReset(cell, trial_id, attempt)) {
        cell.reset_ahead = ResetAhead::kPublishPending;
        QueueNext(cell, trial_id, attempt);
      }
    } catch (const db::StoreError& e) {
      if (Judge(e) == StoreVerdict::kStop) throw;
      spdlog::debug("{}: the RESET follows the publish: {}", tag, e.what());
    }
    Step(
        tag + ": publish ground truth", cell_id,
        [this, tag, trial_id, attempt] {
          auto eit = executions.find(trial_id);
          if (eit == executions.end() || eit->second.attempt != attempt) return;
          Execution& e = eit->second;
          if (!e.sink) {  // a busy store broke the ingest: write the whole stream again
            e.sink = store.BeginIngest(e.trial_id, e.attempt, ContactSitesOf(e.scene));
            try {
              e.sink->Add(e.samples);
            } catch (...) {
              e.sink.reset();
              throw;
            }
          }
          std::int64_t n = 0;
          ReadExecution(e);  // the RESET is out: off the cell's path now
          try {
            // The execution record, the publish and the move to resetting: one commit.
            db::FinishAlso also;
            also.execution = e.execution;
            also.begin_reset_rule = kResetAfterExecute;
            n = store.PublishExecuted(*e.sink, e.trial_id, e.attempt, also);
          } catch (const db::StoreError& err) {
            if (Judge(err) == StoreVerdict::kRetry) e.sink.reset();
            throw;
          }
          Count(&ServiceCounters::executed);
          spdlog::info("{}: executed, {} samples stored", tag, n);
          Executed(trial_id);
        },
        [this, tag, trial_id](const db::StoreError& e) {
          auto eit = executions.find(trial_id);
          if (eit == executions.end()) return;
          spdlog::error("{}: {}", tag, e.what());
          // Refused with the publish: EndPhase still records what ran the trial.
          CellRun& c = Cell(eit->second.cell_id);
          const bool ahead = c.reset_ahead == ResetAhead::kPublishPending;
          std::vector<msg::TrialStatus> held = std::move(c.held_reset);
          c.reset_ahead = ResetAhead::kNo;  // decided below, not as an attempt ended otherwise
          // The reset runs out (below) and the cell then runs its queued trial.
          std::optional<CellRun::Queued> queued;
          if (ahead && DecideQueued(QueuedEvent::kPublishRefused).step == QueuedStep::kKeep)
            queued = std::exchange(c.queued, std::nullopt);
          EndPhase(c, DecideServiceEvent(c.phase, ServiceEvent::kStoreRefusedTruth), e.what());
          if (!ahead) return;
          const AheadDecision a = DecideResetAhead(AheadEvent::kPublishRefused);
          c.queued = std::move(queued);
          if (a.step != AheadStep::kRunOut)
            EndQueued(c, QueuedEvent::kPhaseEnded, std::string("publish refused: ") + e.what());
          RunOutReset(c, a, std::move(held));
        });
  }

  // A publish refused after its RESET went out ended its attempt (retried or
  // failed, the cell backed off, by EndPhase): the cell still resets, and
  // that reset, not a new EXECUTE, frees it. Nothing of it is recorded for
  // the trial (its attempt is over; resetting only ever follows executed).
  void RunOutReset(CellRun& cell, const AheadDecision& a, std::vector<msg::TrialStatus> held) {
    if (a.step != AheadStep::kRunOut) return;
    SetPhase(cell, CellPhase::kResetting, opt.service.reset_timeout_s + 2.0);
    cell.reset_ahead = ResetAhead::kForNoTrial;
    spdlog::warn("cell {}: its reset runs out for no trial ({})", cell.id, a.rule);
    for (const msg::TrialStatus& st : held) TakeStatus(cell, st);
  }

  // Sends `c` its RESET after (trial_id, attempt), aimed at the start of the
  // trial it will most likely run next (looked up while it executed; a trial
  // claimed since by another cell only costs the next trial its measured
  // start, as a lookup here could too). @returns false when it could not be
  // sent. @throws db::StoreError from the aim's lookup (nothing sent then).
  bool SendReset(CellRun& c, std::int64_t trial_id, int attempt) {
    const bool aim_current = c.aim_known && (!c.next_aim || !ClaimedByAnother(c));
    std::optional<db::ClaimedTrial> next =
        aim_current ? std::move(c.next_aim) : NextTrialFor(c, false);
    c.aim_known = false;
    c.next_aim.reset();
    c.reset_mounts.reset();
    if (next && c.change_costs) c.reset_mounts = FixturesOfTrial(next->trial_id, next->scene_json);
    msg::TrialCommand cmd = Command(c, msg::PHASE_RESET);
    cmd.trial_id(static_cast<std::uint64_t>(trial_id));
    cmd.attempt(static_cast<std::uint32_t>(attempt));
    cmd.scene_json(next ? next->scene_json : std::string());
    cmd.seed(next ? next->seed : 0);
    c.reset_aimed_at = next ? next->trial_id : 0;
    cmd.deadline_s(opt.service.reset_timeout_s);
    const bool sent = transport.Send(cmd);
    c.reset_sent = now();
    return sent;
  }

  // The stream is published: predict, and reset the cell towards its next trial.
  void Executed(std::int64_t trial_id) {
    auto it = executions.find(trial_id);
    Execution& ex = it->second;
    CellRun& cell = Cell(ex.cell_id);
    CellResult(cell, CellPhase::kExecuting, true, "");
    if (observer) {
      const auto dropped = std::count_if(ex.samples.begin(), ex.samples.end(),
                                         [](const db::Sample& s) { return !s.observed_valid; });
      observer->OnStream(cell.id, ex.campaign_id, static_cast<std::int64_t>(ex.samples.size()),
                         dropped);
    }
    PredictionRequest request{ex.trial_id,
                              ex.campaign_id,
                              ex.attempt,
                              std::move(ex.scene),
                              std::move(ex.truth),
                              ex.scene_json,
                              std::move(ex.commands),
                              std::nullopt};
    if (!ex.samples.empty()) request.first_sample = ex.samples.front();
    // Started after the RESET is sent and the next dispatch (Tick's
    // background): preparing it (its start pose, the campaign's model) is
    // off the trial's path, and the model runs on the predictor's threads.
    auto shared_request = std::make_shared<PredictionRequest>(std::move(request));
    ++predictions_queued;
    background.push_back([this, shared_request] {
      --predictions_queued;
      predictions.Start(std::move(*shared_request));
    });
    const std::string tag = TrialTag(ex.campaign_id, ex.trial_id, ex.attempt);
    const int attempt = ex.attempt;
    const std::string cell_id = ex.cell_id;
    executions.erase(it);
    // executed -> resetting was written with the publish (PublishExecuted).
    const bool ahead = cell.reset_ahead == ResetAhead::kPublishPending;
    cell.reset_ahead = ResetAhead::kNo;
    SetPhase(cell, CellPhase::kResetting, opt.service.reset_timeout_s + 2.0);
    if (ahead) {  // its RESET went out before the commit: what it said meanwhile is taken now
      const AheadDecision a = DecideResetAhead(AheadEvent::kPublishCommitted);
      std::vector<msg::TrialStatus> held = std::move(cell.held_reset);
      cell.held_reset.clear();
      if (a.step == AheadStep::kTakeHeld)
        for (const msg::TrialStatus& st : held) TakeStatus(cell, st);
      return;
    }
    Step(
        tag + ": begin reset", cell_id,
        [this, trial_id, attempt, cell_id] {
          CellRun& c = Cell(cell_id);
          SetPhase(c, CellPhase::kResetting, opt.service.reset_timeout_s + 2.0);
          if (!SendReset(c, trial_id, attempt))
            EndPhase(c, DecideServiceEvent(c.phase, ServiceEvent::kCommandNotSent),
                     "RESET command could not be sent");
        },
        [this, tag, cell_id](const db::StoreError& e) {
          spdlog::error("{}: {}", tag, e.what());
          SetPhase(Cell(cell_id), CellPhase::kIdle);  // the trial moved on (cancelled, failed)
        });
  }

  // ------------------------------------------------------------ statuses
  void OnStatus(const msg::TrialStatus& st) {
    if (st.service_session() != me.session) return;  // another service's (or a dead one's)
    auto cit = cells.find(st.cell_id());
    if (cit == cells.end()) return;
    CellRun& cell = cit->second;
    if (HoldsForQueued(cell, static_cast<std::int64_t>(st.trial_id()),
                       static_cast<int>(st.attempt()))) {
      // Before its reset's status was taken (a held RESET_DONE): taken after it (RunQueued).
      if (cell.queued->held.size() == 2 * kMaxHeldStatuses)
        cell.queued->held.erase(cell.queued->held.begin());
      cell.queued->held.push_back(st);
      return;
    }
    if (LateMessageRule(true, cell.phase, SameAttempt(cell, st))) return;  // a phase settled
    if (cell.reset_ahead == ResetAhead::kPublishPending && st.phase() == msg::PHASE_RESET) {
      // Its RESET went out before the publish, which has not committed (a
      // busy store): recorded only once it has (Executed, RunOutReset).
      if (DecideResetAhead(AheadEvent::kResetStatus).step == AheadStep::kHold) {
        if (cell.held_reset.size() == kMaxHeldStatuses)
          cell.held_reset.erase(cell.held_reset.begin());
        cell.held_reset.push_back(st);
        cell.reset_taken = now();  // the wait for the publish is the service's time
        return;
      }
    }
    (cell.phase == CellPhase::kResetting ? cell.reset_taken : cell.stream_input_at) = now();
    // A phase ended: the cell waits on the service until SetPhase hands it the next.
    if (on_path_change && st.state() != msg::STATE_ACCEPTED) on_path_change(cell.id, true);
    TakeStatus(cell, st);
  }

  static bool SameAttempt(const CellRun& cell, const msg::TrialStatus& st) {
    return cell.trial_id == static_cast<std::int64_t>(st.trial_id()) &&
           cell.attempt == static_cast<int>(st.attempt());
  }

  // A status of ours, decided by the policy for the cell's phase now.
  void TakeStatus(CellRun& cell, const msg::TrialStatus& st) {
    if (LateMessageRule(true, cell.phase, SameAttempt(cell, st))) return;  // a phase settled
    const Decision d = DecideStatus(cell.phase, ToPolicy(st.phase()), ToPolicy(st.state()),
                                    ToPolicy(st.failure()));
    if (cell.phase == CellPhase::kExecuting && st.phase() == msg::PHASE_EXECUTE) {
      OnExecuteStatus(cell, st, d);
    } else if (cell.phase == CellPhase::kResetting && st.phase() == msg::PHASE_RESET) {
      OnResetStatus(cell, st, d);
    }
  }

  // What the trial ran on and which defects were applied (the cell's word).
  // Metadata: a store error here is logged by Step's policy, never blocks the trial.
  // Kept until the stream is published, to join the publish's transaction
  // (PublishExecuted): no commit of its own between the status and the RESET,
  // also when the status arrives before the stream's last batch. A phase that
  // ends without a publish writes it then (EndPhase).
  // The record is made when first needed after the RESET went out (the
  // publish step) or when the attempt ends unpublished (EndPhase).
  static void ReadExecution(Execution& ex) {
    if (!ex.detail) return;
    ExecutionDetail& d = *ex.detail;
    ex.execution = db::ExecutionRecord{std::move(d.backend), std::move(d.truth),
                                       d.defects_applied.value_or(std::string())};
    ex.detail.reset();
  }
  void WriteExecution(std::int64_t trial_id, int attempt, db::ExecutionRecord r) {
    Step("trial " + std::to_string(trial_id) + ": record execution", "",
         [this, trial_id, attempt, r] {
           store.RecordExecution(trial_id, attempt, r.backend, r.truth, r.defects_applied_json);
         });
  }

  // Closed loop (issue 19): the commands the cell applied and the
  // controller's outcome (detail_json "closed_loop"), stored with the attempt
  // like RecordExecution; the commands also go to the prediction (replayed).
  void RecordClosedLoop(Execution& ex, const msg::TrialStatus& st) {
    const std::string tag = TrialTag(ex.campaign_id, ex.trial_id, ex.attempt);
    // Most runs are open loop: no parse of the detail to learn that.
    if (st.detail_json().find("\"closed_loop\"") == std::string::npos) return;
    std::optional<db::ClosedLoopRun> run;
    try {
      run = ClosedLoopFromDetail(ex.trial_id, ex.attempt, st.reason(), st.detail_json());
    } catch (const std::exception& e) {
      spdlog::error("{}: closed-loop record: {}", tag, e.what());
      return;
    }
    if (!run) return;
    ex.commands = assessment::CommandsOf(*run);
    if (observer && !run->commands.empty())
      observer->OnClosedLoop(ex.cell_id, ex.campaign_id,
                             static_cast<std::int64_t>(run->commands.size()), run->held);
    auto shared = std::make_shared<db::ClosedLoopRun>(std::move(*run));
    Step(tag + ": record closed loop", "", [this, shared] { store.RecordClosedLoop(*shared); });
  }

  void OnExecuteStatus(CellRun& cell, const msg::TrialStatus& st, const Decision& d) {
    auto it = executions.find(cell.trial_id);
    if (it == executions.end() || it->second.publishing) return;
    Execution& ex = it->second;
    switch (d.trial) {
      case TrialStep::kIgnore:
      case TrialStep::kAwait:
        return;
      case TrialStep::kCollectStream: {
        // The stated truth decides whether the stream may be published
        // (StreamProblem): read now, without building the document.
        ex.detail = ReadExecutionDetail(st.detail_json());
        // The cell changed what differed before it ran (executors/trial_start.hpp).
        // Only cells that declared change costs track fixtures: no other
        // cell's path parses a scene for them (issue 27).
        if (cell.change_costs)
          RecordChanges(cell, ex.trial_id, ex.attempt, "execute",
                        FixturesOfTrial(ex.trial_id, ex.scene_json), /*after_dispatch=*/true);
        ex.expected = st.samples();
      }
        RecordClosedLoop(ex, st);
        cell.execute_wall_s = st.phase_wall_s();
        ex.expected = st.samples();  // also when the detail was not an object
        ex.stream_deadline = now() + Dur(opt.service.stream_grace_s);
        MaybeFinishExecution(ex.trial_id);
        return;
      default:
        break;
    }
    if (st.state() == msg::STATE_REFUSED) {
      EndPhase(cell, d, "refused by cell " + cell.id + ": " + st.reason());
      return;
    }
    RecordClosedLoop(ex, st);  // a failed closed loop: why, and the commands up to then
    EndPhase(cell, d,
             d.trial == TrialStep::kFail ? "cell " + cell.id + ": " + st.reason()
                                         : "cell " + cell.id + " failed: " + st.reason());
  }

  void OnResetStatus(CellRun& cell, const msg::TrialStatus& st, const Decision& d) {
    if (d.trial != TrialStep::kResetDone && d.trial != TrialStep::kResetFailed) return;
    const bool ok = d.trial == TrialStep::kResetDone;
    db::ResetReport report;
    report.ok = ok;
    std::copy(st.observed_pose().begin(), st.observed_pose().end(), report.observed_pose.begin());
    report.position_error = st.reset_position_error();
    report.angle_error = st.reset_angle_error();
    report.reset_attempts = static_cast<int>(st.reset_attempts());
    report.reason = st.reason();
    report.aimed_at_trial = cell.reset_aimed_at;
    if (observer && (ok || d.counts_against_cell()))  // the resets CellResult counts
      observer->OnReset(cell.id, cell.campaign_id, ok, report.pose_observed, report.position_error);
    if (!ok) {
      spdlog::warn("trial {} attempt {}: reset on cell {} failed: {}", cell.trial_id, cell.attempt,
                   cell.id, st.reason());
    }
    // A reset run out after a refused publish is no trial's (RunOutReset).
    const bool for_trial = cell.reset_ahead != ResetAhead::kForNoTrial;
    // A clean reset is written after the cell's next EXECUTE is sent (Tick's
    // dispatch comes first); a failed one before the cell is idle, as ever.
    if (for_trial) CompleteReset(cell.trial_id, cell.attempt, report, cell.id, d.rule, ok);
    // A reset aimed at a trial mounted its fixtures (only a successful one).
    if (ok && cell.reset_mounts)
      RecordChanges(cell, cell.trial_id, cell.attempt, "reset", *cell.reset_mounts, true);
    cell.reset_mounts.reset();
    if (ok || d.counts_against_cell()) CellResult(cell, CellPhase::kResetting, ok, st.reason());
    if (ok && for_trial) ReportTiming(cell, st.phase_wall_s());
    SetPhase(cell, CellPhase::kIdle);
    if (ok && for_trial) cell.failures_in_a_row = 0;  // a whole clean trial: backoff starts over
    BackOff(cell, d, "reset failed: " + st.reason());
    if (!cell.queued) return;
    if (ok)
      RunQueued(cell);
    else
      EndQueued(cell, QueuedEvent::kResetFailed,
                "queued behind a reset that failed: " + st.reason());
  }

  // The split of a clean trial's time on its cell (TrialTiming). A cell's
  // reported phase times are its word: non-finite or negative ones give no figure.
  void ReportTiming(const CellRun& cell, double reset_wall_s) {
    const double busy = Seconds(now() - cell.claimed_at).count();
    const double exec = cell.execute_wall_s;
    if (!std::isfinite(exec) || exec < 0 || !std::isfinite(reset_wall_s) || reset_wall_s < 0)
      return;
    TrialTiming t;
    t.trial_id = cell.trial_id;
    t.attempt = cell.attempt;
    t.cell_id = cell.id;
    t.cell_busy_s = busy;
    t.execute_s = exec;
    t.reset_s = reset_wall_s;
    t.overhead_s = busy - exec - reset_wall_s;
    t.campaign_id = cell.campaign_id;
    t.service_s = Seconds((cell.execute_sent - cell.claimed_at) +
                          (cell.reset_sent - cell.publish_from) + (now() - cell.reset_taken))
                      .count();
    t.claim_to_execute_s = Seconds(cell.execute_sent - cell.claimed_at).count();
    t.execute_round_trip_s = Seconds(cell.stream_input_at - cell.execute_sent).count() - exec;
    t.stream_to_reset_s = Seconds(cell.reset_sent - cell.stream_input_at).count();
    t.reset_round_trip_s = Seconds(now() - cell.reset_sent).count() - reset_wall_s;
    if (on_trial_timing) on_trial_timing(t);
  }

  // ------------------------------------------------------------ predictions
  void AfterReset(std::int64_t trial_id) {
    auto it = waiting_predictions.find(trial_id);
    if (it == waiting_predictions.end()) return;
    auto done = std::make_shared<PredictionDone>(std::move(it->second));
    waiting_predictions.erase(it);
    background.push_back([this, done] { RecordPrediction(std::move(*done)); });
  }

  void OnPrediction(PredictionDone done) {
    const std::int64_t trial_id = done.trial_id;
    auto shared = std::make_shared<PredictionDone>(std::move(done));
    Step("trial " + std::to_string(trial_id) + ": prediction", "", [this, shared] {
      const db::Trial t = store.GetTrial(shared->trial_id);
      const bool awaiting_reset =
          t.state == db::TrialState::kResetting || t.state == db::TrialState::kExecuted;
      const PredictionDecision d = DecidePrediction(
          t.attempt == shared->attempt, awaiting_reset,
          awaiting_reset && t.attempt == shared->attempt && ResetInFlight(t.id, t.attempt));
      switch (d.step) {
        case PredictionStep::kDrop:  // the trial moved on (re-run)
          return;
        case PredictionStep::kWaitForReset:  // recorded when the reset ends (AfterReset)
          waiting_predictions[shared->trial_id] = std::move(*shared);
          return;
        case PredictionStep::kCloseResetThenRecord:
          // Nobody resets it any more (its reset step was moot, or its status
          // lost): close the reset as not observed, then record.
          if (t.state == db::TrialState::kExecuted) store.BeginReset(t.id, t.attempt, d.rule);
          store.CompleteReset(t.id, t.attempt, UnobservedReset("its reset was not confirmed"),
                              d.rule);
          break;
        case PredictionStep::kRecord:
          break;
      }
      RecordPrediction(std::move(*shared));
    });
  }

  bool ResetInFlight(std::int64_t trial_id, int attempt) const {
    if (resets_completing.count(trial_id)) return true;
    for (const auto& [id, cell] : cells)
      if (cell.phase == CellPhase::kResetting && cell.trial_id == trial_id &&
          cell.attempt == attempt)
        return true;
    return false;
  }

  void RecordPrediction(PredictionDone done) {
    const std::string tag = TrialTag(done.campaign_id, done.trial_id, done.attempt);
    auto shared = std::make_shared<PredictionDone>(std::move(done));
    // The prediction and `done` in one commit (off the path: after a dispatch).
    Step(tag + ": record prediction", "", [this, tag, shared] {
      store.RecordPredictionAndFinish(shared->trial_id, shared->attempt, shared->prediction);
      spdlog::info("{}: predicted ({}, final position error {:.3g} m)", tag,
                   db::ToString(shared->prediction.status),
                   shared->prediction.final_position_error.value_or(NAN));
      Count(&ServiceCounters::done);
      spdlog::info("{}: done", tag);
    });
  }

  void Finish(std::int64_t trial_id, std::int64_t campaign_id, int attempt) {
    const std::string tag = TrialTag(campaign_id, trial_id, attempt);
    Step(tag + ": finish", "", [this, tag, trial_id, attempt] {
      store.FinishTrial(trial_id, attempt);
      Count(&ServiceCounters::done);
      spdlog::info("{}: done", tag);
    });
  }

  // ------------------------------------------------------------ resume
  // Recovery first (a busy store: the same step again at the next tick); no
  // trial is dispatched before it ran, or it would re-queue our own claims.
  bool recovered = false;
  void Resume() {
    store.RestrictClaimsTo(std::vector<std::int64_t>{});  // nothing claimable before the gate ran
    Step(
        "recovery after restart", "",
        [this] {
          const db::RecoveryReport report = store.RecoverAfterRestart();
          if (!report.requeued.empty() || !report.reset_failed.empty()) {
            spdlog::warn("recovered after restart: {} trials re-queued, {} resets marked failed",
                         report.requeued.size(), report.reset_failed.size());
          }
          Count(&ServiceCounters::recovered,
                static_cast<std::int64_t>(report.requeued.size() + report.reset_failed.size()));
          const auto unfinished =
              store.ListTrialsByState({db::TrialState::kExecuted, db::TrialState::kResetDone,
                                       db::TrialState::kResetFailed, db::TrialState::kPredicted});
          recovered = true;
          for (const auto& t : unfinished) ResumeTrial(t);
        },
        [this](const db::StoreError& e) {
          spdlog::error("recovery after restart: {}", e.what());
          recovered = true;  // not fatal: schedule anyway
        });
  }

  void ResumeTrial(const db::Trial& t) {
    const std::string tag = TrialTag(t.campaign_id, t.id, t.attempt);
    switch (t.state) {
      case db::TrialState::kExecuted:
        Step(tag + ": reset after restart", "", [this, t] {
          store.BeginReset(t.id, t.attempt, kResetAfterRestart);
          store.CompleteReset(t.id, t.attempt,
                              UnobservedReset("service restarted before the reset"),
                              kResetAfterRestart);
          StartStoredPrediction(t);
        });
        return;
      case db::TrialState::kResetDone:
      case db::TrialState::kResetFailed:
        StartStoredPrediction(t);
        return;
      case db::TrialState::kPredicted:
        Finish(t.id, t.campaign_id, t.attempt);
        return;
      default:
        return;
    }
  }

  void StartStoredPrediction(const db::Trial& t) {
    spdlog::info("{}: predicting after restart", TrialTag(t.campaign_id, t.id, t.attempt));
    PredictionRequest request;
    request.trial_id = t.id;
    request.campaign_id = t.campaign_id;
    request.attempt = t.attempt;
    request.scene_json = t.scene_json;
    predictions.Start(std::move(request));
  }

  // ------------------------------------------------------------ tick
  void CheckDeadlines() {
    const auto t = now();
    for (auto& [id, cell] : cells) {
      if (cell.phase == CellPhase::kIdle || cell.store_waits > 0) continue;
      if (cell.phase == CellPhase::kExecuting) {
        auto it = executions.find(cell.trial_id);
        if (it != executions.end() && it->second.publishing) continue;
        if (it != executions.end() && it->second.expected >= 0 && t > it->second.stream_deadline) {
          EndPhase(cell, DecideServiceEvent(cell.phase, ServiceEvent::kStreamIncomplete),
                   "ground truth incomplete: " + std::to_string(it->second.next_sample) + " of " +
                       std::to_string(it->second.expected) + " samples");
          continue;
        }
      }
      if (t > cell.deadline) {
        EndPhase(cell, DecideServiceEvent(cell.phase, ServiceEvent::kDeadlineMissed),
                 std::string(cell.phase == CellPhase::kExecuting ? "EXECUTE" : "RESET") +
                     " missed its deadline on cell " + id);
      }
    }
  }

  void Tick(bool stopping) {
    const auto t = now();
    stopping_now = stopping;
    if (t >= next_file_check) {
      next_file_check = t + Dur(0.1);
      store.CheckFileIdentity();  // throws kIo: the service stops naming the file
    }
    steps.RunDue();
    CheckDeadlines();
    if (t >= next_claims) {
      next_claims = t + Dur(opt.claim_period_s);
      for (auto& [id, cell] : cells)  // also while draining: phases in flight keep their cell
        if (cell.alive) SendClaim(cell);
    }
    if (recovered && (gate_dirty || t >= next_gate)) {
      gate_dirty = false;
      next_gate = t + Dur(kGatePeriod_s);
      Attempt("the claim gate", [&] { GateCampaigns(); });
    }
    Dispatch(stopping);
    // The periodic writes no claim reads, after the dispatch: a cell whose
    // reset just ended gets its EXECUTE before these commits (issue 27).
    if (t >= next_beat) {
      next_beat = t + Dur(opt.beat_period_s);
      std::vector<std::string> alive;
      for (const auto& [id, cell] : cells)
        if (cell.alive) alive.push_back(id);  // serving us or another service: alive
      Attempt("service heartbeat", [&] { store.ServiceBeat(alive); });
    }
    if (t >= next_campaigns) {  // `arena serve` marks finished campaigns done
      next_campaigns = t + Dur(1.0);
      Attempt("completing finished campaigns", [&] { store.CompleteFinishedCampaigns(0); });
    }
    RunBackground();
  }

  bool InFlight() const {
    for (const auto& [id, cell] : cells)
      if (cell.phase != CellPhase::kIdle) return true;
    return predictions.outstanding() > 0 || !waiting_predictions.empty() || steps.pending() > 0 ||
           !background.empty();
  }

  ServiceCounters Snapshot() const {
    int known = 0, usable = 0;
    for (const auto& [id, cell] : cells) {
      ++known;
      usable += cell.alive && !cell.quarantined;
    }
    std::lock_guard lock(counters_mu);
    ServiceCounters c = counters;
    c.cells_known = known;
    c.cells_usable = usable;
    return c;
  }
};

TrialDriver::TrialDriver(DriverOptions options, ServiceIdentity me, TrialStore& store,
                         CommandTransport& transport, PredictionPort& predictions,
                         std::function<DriverClock::time_point()> now)
    : impl_(std::make_unique<Impl>(std::move(options), std::move(me), store, transport, predictions,
                                   std::move(now))) {}
TrialDriver::~TrialDriver() = default;

void TrialDriver::Resume() { impl_->Resume(); }
void TrialDriver::OnAnnounce(const msg::CellAnnounce& a) { impl_->OnAnnounce(a); }
void TrialDriver::OnCellLost(const std::string& id, const std::string& reason, bool another) {
  impl_->OnCellLost(id, reason, another);
}
void TrialDriver::OnCellAlive(const std::string& id) { impl_->OnCellAlive(id); }
void TrialDriver::OnStatus(const msg::TrialStatus& st) { impl_->OnStatus(st); }
void TrialDriver::OnGroundTruth(const msg::GroundTruth& b) { impl_->OnGroundTruth(b); }
void TrialDriver::OnPrediction(PredictionDone done) { impl_->OnPrediction(std::move(done)); }
void TrialDriver::Tick(bool stopping) { impl_->Tick(stopping); }
bool TrialDriver::InFlight() const { return impl_->InFlight(); }
int TrialDriver::IdleCells() const {
  int n = 0;
  for (const auto& [id, cell] : impl_->cells)
    n += cell.alive && cell.ours && !cell.quarantined && cell.phase == CellPhase::kIdle;
  return n;
}
bool TrialDriver::CampaignsFinished() {
  bool finished = false;
  impl_->Attempt("completing finished campaigns", [&] {
    finished = impl_->store.CompleteFinishedCampaigns(impl_->opt.service.only_campaign);
  });
  return finished;
}
ServiceCounters TrialDriver::counters() const { return impl_->Snapshot(); }
void TrialDriver::OnInputWaiting(std::function<bool()> waiting) {
  impl_->input_waiting = std::move(waiting);
}
void TrialDriver::OnTrialTiming(std::function<void(const TrialTiming&)> callback) {
  impl_->on_trial_timing = std::move(callback);
}
void TrialDriver::OnPathChange(std::function<void(const std::string&, bool)> callback) {
  impl_->on_path_change = std::move(callback);
}
std::size_t TrialDriver::pending_store_steps() const { return impl_->steps.pending(); }
void TrialDriver::SetObserver(TrialObserver* observer) { impl_->observer = observer; }

}  // namespace arena::orchestrator
