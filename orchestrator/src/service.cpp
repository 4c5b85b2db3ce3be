// The campaign service; the contract and the trial's path are in service.hpp.
#include "arena/orchestrator/service.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/closed_loop.hpp"
#include "arena/orchestrator/logging.hpp"
#include "arena/orchestrator/prediction.hpp"
#include "arena/orchestrator/scoring.hpp"
#include "arena/orchestrator/trial_data.hpp"
#include "arena/schemas/arena.h"
#include "arena/schemas/ground_truth.hpp"

namespace arena::orchestrator {

namespace {

using Clock = std::chrono::steady_clock;
using Seconds = std::chrono::duration<double>;

constexpr char kCellPrefix[] = "arena.cell.";

std::string CellOfParticipant(const std::string& participant) {
  const std::string prefix = kCellPrefix;
  return participant.rfind(prefix, 0) == 0 ? participant.substr(prefix.size()) : "";
}

Clock::time_point After(double seconds) {
  return Clock::now() + std::chrono::duration_cast<Clock::duration>(Seconds(seconds));
}

// A prediction to compute off the service thread.
// A store that cannot take writes any more (full, read-only, unreadable,
// corrupt) is not a trial's or a cell's fault: the service stops (Run()
// rethrows; `arena serve` exits 3 with the message) instead of blaming the
// cell and retrying into the same wall. Busy and bad-input errors are local.
bool StoreFailed(const std::exception& e) {
  const auto* se = dynamic_cast<const db::StoreError*>(&e);
  if (!se) return false;
  using K = db::StoreError::Kind;
  switch (se->kind()) {
    case K::kFull:
    case K::kIo:
    case K::kCorrupt:
    case K::kReadOnly:
    case K::kTooNew:
      return true;
    default:
      return false;
  }
}

struct PredictionJob {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::int64_t campaign_id = 0;
  mechanics::Scene scene;  // with the campaign's model settings applied
  std::vector<mechanics::TrajectorySample> truth;
  RecordedCommands commands;  // closed loop: replayed through the model; empty otherwise
};

struct PredictionDone {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::int64_t campaign_id = 0;
  db::Prediction prediction;
};

// Worker threads that run the predictor; jobs in, results out.
class PredictorPool {
 public:
  explicit PredictorPool(int threads) {
    for (int i = 0; i < std::max(1, threads); ++i) workers_.emplace_back([this] { Work(); });
  }
  ~PredictorPool() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    for (auto& w : workers_) w.join();
  }
  void Submit(PredictionJob job) {
    {
      std::lock_guard lock(mu_);
      jobs_.push_back(std::move(job));
      ++outstanding_;
    }
    cv_.notify_one();
  }
  std::vector<PredictionDone> TakeResults() {
    std::lock_guard lock(mu_);
    std::vector<PredictionDone> out(std::make_move_iterator(results_.begin()),
                                    std::make_move_iterator(results_.end()));
    results_.clear();
    outstanding_ -= static_cast<int>(out.size());
    return out;
  }
  int outstanding() const {
    std::lock_guard lock(mu_);
    return outstanding_;
  }

 private:
  void Work() {
    for (;;) {
      PredictionJob job;
      {
        std::unique_lock lock(mu_);
        cv_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
        if (stop_) return;
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      PredictionDone done{
          job.trial_id, job.attempt, job.campaign_id,
          PredictTrial(job.scene, job.truth, job.commands.empty() ? nullptr : &job.commands)};
      std::lock_guard lock(mu_);
      results_.push_back(std::move(done));
    }
  }

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<PredictionJob> jobs_;
  std::vector<PredictionDone> results_;
  int outstanding_ = 0;
  bool stop_ = false;
  std::vector<std::thread> workers_;
};

}  // namespace

struct Service::Impl {
  ServiceOptions opt;
  dds::Participant participant;
  dds::Writer<msg::TrialCommand> commands;
  dds::Reader<msg::CellAnnounce> announces;
  dds::Reader<msg::TrialStatus> statuses;
  dds::Reader<msg::GroundTruth> truth_reader;
  PredictorPool predictor;
  // After the participant: a bad network or security setting fails before
  // the store file is created or touched (bad input changes nothing stored).
  std::unique_ptr<db::Store> store;

  // This run's identity on the command topic (TrialCommand.service_session).
  const std::uint64_t session = std::random_device{}() * 0x100000000ull + std::random_device{}();
  std::atomic<bool> stop_requested{false};
  mutable std::mutex counters_mu;
  ServiceCounters counters;
  std::function<void(const ServiceCounters&)> on_tick;
  std::function<void(const TrialTiming&)> on_trial_timing;

  enum class CellPhase { kIdle, kExecuting, kResetting };
  struct CellRun {
    std::string id;
    bool alive = true;
    bool quarantined = false;
    int execute_failures = 0;  // consecutive failed EXECUTE phases
    int reset_failures = 0;    // consecutive failed RESET phases
    // The last announcement, to re-register a cell whose liveliness returns.
    std::vector<std::string> contact_types;
    std::string capabilities_json = "{}", defects_json = "{}";
    double speed = 1.0;  // the cell's announced pacing (wall s per simulated s)
    CellPhase phase = CellPhase::kIdle;
    std::int64_t trial_id = 0, campaign_id = 0;
    int attempt = 0;
    Clock::time_point deadline{};
    Clock::time_point next_claim{};
    Clock::time_point claimed_at{};  // when the current trial's claim began
    double execute_wall_s = -1;      // the cell's EXECUTE time of the current trial; -1 unknown
  };
  std::map<std::string, CellRun> cells;

  // A trial whose EXECUTE is in flight: its stream is being ingested.
  struct Execution {
    std::int64_t trial_id = 0, campaign_id = 0;
    int attempt = 0;
    std::string cell_id;
    mechanics::Scene scene;
    std::vector<Eigen::Vector3d> normals;
    std::unique_ptr<db::Ingest> ingest;
    std::uint32_t next_sample = 0;
    std::int64_t expected = -1;           // samples the cell says it sent; -1 before EXECUTED
    Clock::time_point stream_deadline{};  // after EXECUTED, for missing batches
    std::vector<mechanics::TrajectorySample> truth;
    RecordedCommands commands;  // closed loop: the commands the cell applied
  };
  std::map<std::int64_t, Execution> executions;

  // Predictions computed before their reset finished, waiting for it.
  std::map<std::int64_t, PredictionDone> waiting_predictions;
  // Campaign model settings: campaign id -> spec "prediction" (or null).
  std::map<std::int64_t, nlohmann::json> campaign_models;

  static db::StoreOptions StoreOptionsFor(const ServiceOptions& o) {
    db::StoreOptions so;
    so.max_pages = o.store_max_pages;
    return so;
  }

  Impl(const ServiceOptions& o)
      : opt(o),
        participant(dds::ParticipantOptions{o.domain_id, "arena.service", o.network, 2.5}),
        commands(participant),
        announces(participant),
        statuses(participant),
        truth_reader(participant),
        predictor(o.predictor_threads),
        store(db::Store::Open(o.db_path, StoreOptionsFor(o))) {}

  void Count(std::int64_t ServiceCounters::*field, std::int64_t n = 1) {
    std::lock_guard lock(counters_mu);
    counters.*field += n;
  }

  // ------------------------------------------------------------ start-up
  // Finishes what a previous service left between executed and predicted.
  void Resume() {
    const db::RecoveryReport report = store->RecoverAfterRestart();
    if (!report.requeued.empty() || !report.reset_failed.empty()) {
      spdlog::warn("recovered after restart: {} trials re-queued, {} resets marked failed",
                   report.requeued.size(), report.reset_failed.size());
    }
    Count(&ServiceCounters::recovered,
          static_cast<std::int64_t>(report.requeued.size() + report.reset_failed.size()));
    for (const auto& campaign : store->ListCampaigns()) {
      for (const auto& t : store->ListTrials(campaign.id)) {
        const std::string tag = TrialTag(t.campaign_id, t.id, t.attempt);
        switch (t.state) {
          case db::TrialState::kExecuted:
            store->BeginReset(t.id, t.attempt);
            store->CompleteReset(t.id, t.attempt,
                                 db::ResetReport{false,
                                                 {0, 0, 0, 1, 0, 0, 0},
                                                 0,
                                                 0,
                                                 0,
                                                 "service restarted before the reset",
                                                 /*pose_observed=*/false});
            [[fallthrough]];
          case db::TrialState::kResetDone:
          case db::TrialState::kResetFailed:
            spdlog::info("{}: predicting after restart", tag);
            PredictFromStore(t);
            break;
          case db::TrialState::kPredicted:
            store->FinishTrial(t.id, t.attempt);
            Count(&ServiceCounters::done);
            break;
          default:
            break;
        }
      }
    }
  }

  void PredictFromStore(const db::Trial& t) {
    try {
      const mechanics::Scene scene = mechanics::ParseScene(t.scene_json);
      const db::GroundTruth gt = store->ReadGroundTruth(t.id);
      const auto normals = ContactNormals(scene);
      PredictionJob job{t.id, t.attempt, t.campaign_id, ScenesForPrediction(scene, t.campaign_id),
                        {},   {}};
      for (const auto& s : gt.samples)
        job.truth.push_back(ToTrajectorySample(s, normals, scene.pusher.has_value()));
      if (auto run = store->GetClosedLoop(t.id)) job.commands = CommandsOf(*run);
      predictor.Submit(std::move(job));
    } catch (const std::exception& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("{}: cannot predict: {}", TrialTag(t.campaign_id, t.id, t.attempt), e.what());
      RecordPrediction(
          PredictionDone{t.id, t.attempt, t.campaign_id, PredictionFailure("error", e.what())});
    }
  }

  mechanics::Scene ScenesForPrediction(const mechanics::Scene& scene, std::int64_t campaign_id) {
    auto it = campaign_models.find(campaign_id);
    if (it == campaign_models.end()) {
      nlohmann::json model;
      try {
        const auto spec = nlohmann::json::parse(store->GetCampaign(campaign_id).spec_json);
        if (spec.is_object() && spec.contains("prediction")) model = spec["prediction"];
      } catch (const std::exception& e) {
        if (StoreFailed(e)) throw;
        spdlog::warn("campaign {}: spec unreadable ({}), predicting with the scene's model",
                     campaign_id, e.what());
      }
      it = campaign_models.emplace(campaign_id, model).first;
    }
    return ApplyModelSettings(scene, it->second);
  }

  // ------------------------------------------------------------ cells
  CellRun& Cell(const std::string& id) {
    auto [it, inserted] = cells.try_emplace(id);
    if (inserted) it->second.id = id;
    return it->second;
  }

  void OnAnnounce(const msg::CellAnnounce& a) {
    const std::string id = a.cell_id();
    CellRun& cell = Cell(id);
    const bool was_alive = cell.alive;
    cell.alive = true;
    cell.speed = a.speed();
    nlohmann::json caps = {{"workspace_min", a.workspace_min()},
                           {"workspace_max", a.workspace_max()},
                           {"max_pusher_speed", a.max_pusher_speed()},
                           {"speed", a.speed()},
                           {"arena_version", a.arena_version()}};
    cell.contact_types = a.contact_types();
    cell.capabilities_json = caps.dump();
    cell.defects_json = a.defects_json();
    try {
      store->UpsertCell(id, a.contact_types(), caps.dump(), a.defects_json());
      cell.quarantined = store->GetCell(id).state == db::CellState::kQuarantined;
      if (!was_alive || cells.size() == 1)
        spdlog::info("cell {} announced ({} contact types)", id, a.contact_types().size());
    } catch (const db::StoreError& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("cell {}: announcement refused: {}", id, e.what());
    }
  }

  void OnPeerEvent(const dds::PeerEvent& e) {
    const std::string id = CellOfParticipant(e.participant);
    if (id.empty() || !cells.count(id)) return;
    CellRun& cell = cells[id];
    using Kind = dds::PeerEvent::Kind;
    if ((e.kind == Kind::kParticipantLeft || e.kind == Kind::kWriterLost) && cell.alive) {
      CellLost(cell, std::string("liveliness lost (") + dds::ToString(e.kind) + ")");
    } else if (e.kind == Kind::kWriterAlive && !cell.alive) {
      // The same cell process is back (a liveliness lapse, not a death): a
      // cell announces itself only once, so its liveliness is what revives it.
      cell.alive = true;
      cell.next_claim = Clock::now();
      try {
        store->UpsertCell(id, cell.contact_types, cell.capabilities_json,
                          cell.defects_json);  // gone -> healthy
        spdlog::info("cell {}: alive again", id);
      } catch (const std::exception& ex) {
        spdlog::error("cell {}: {}", id, ex.what());
      }
    }
  }

  void CellLost(CellRun& cell, const std::string& reason) {
    spdlog::warn("cell {}: {}", cell.id, reason);
    cell.alive = false;
    AbortPhase(cell, "cell lost: " + reason, /*count_against_cell=*/false);
    try {
      store->MarkCellGone(cell.id, reason);
    } catch (const db::StoreError& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("cell {}: {}", cell.id, e.what());
    }
  }

  // Counts a phase result; quarantines the cell after quarantine_after
  // failures with no fully clean trial between them. A success of one phase
  // does not excuse failures of the other: a cell whose every reset fails
  // while its executes succeed is still broken.
  void CellResult(CellRun& cell, bool ok, const std::string& reason) {
    int& streak = cell.phase == CellPhase::kResetting ? cell.reset_failures : cell.execute_failures;
    const int other =
        cell.phase == CellPhase::kResetting ? cell.execute_failures : cell.reset_failures;
    if (ok) {
      streak = 0;
      if (other == 0) store->RecordCellResult(cell.id, true);
      return;
    }
    ++streak;
    const int failures = store->RecordCellResult(cell.id, false);
    if (!ok && failures >= opt.quarantine_after) {
      const std::string why = std::to_string(failures) + " failures in a row, last: " + reason;
      store->QuarantineCell(cell.id, why);
      cell.quarantined = true;
      Count(&ServiceCounters::quarantined);
      spdlog::error("cell {} quarantined: {}", cell.id, why);
    }
  }

  // Ends whatever phase the cell is in as a failure.
  void AbortPhase(CellRun& cell, const std::string& reason, bool count_against_cell) {
    if (cell.phase == CellPhase::kExecuting) {
      auto it = executions.find(cell.trial_id);
      if (it != executions.end()) {
        RetryExecution(it->second, reason);
        executions.erase(it);
      }
    } else if (cell.phase == CellPhase::kResetting) {
      try {
        store->CompleteReset(cell.trial_id, cell.attempt,
                             db::ResetReport{false,
                                             {0, 0, 0, 1, 0, 0, 0},
                                             0,
                                             0,
                                             0,
                                             reason,
                                             /*pose_observed=*/false});
        Count(&ServiceCounters::resets_failed);
        AfterReset(cell.trial_id);
      } catch (const db::StoreError& e) {
        if (StoreFailed(e)) throw;
        spdlog::error("trial {}: {}", cell.trial_id, e.what());
      }
    }
    if (count_against_cell && cell.phase != CellPhase::kIdle) CellResult(cell, false, reason);
    cell.phase = CellPhase::kIdle;
    cell.next_claim = Clock::now();
  }

  void RetryExecution(const Execution& ex, const std::string& reason) {
    const std::string tag = TrialTag(ex.campaign_id, ex.trial_id, ex.attempt);
    try {
      const db::TrialState next =
          store->RetryTrial(ex.trial_id, ex.attempt, reason, opt.max_attempts,
                            opt.retry_backoff_s * std::pow(2.0, ex.attempt - 1));
      if (next == db::TrialState::kFailed) {
        Count(&ServiceCounters::failed);
        spdlog::error("{}: failed, no attempts left: {}", tag, reason);
      } else {
        Count(&ServiceCounters::retried);
        spdlog::warn("{}: will be retried: {}", tag, reason);
      }
    } catch (const db::StoreError& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("{}: {}", tag, e.what());
    }
  }

  // ------------------------------------------------------------ dispatch
  void Dispatch() {
    if (stop_requested) return;
    const auto now = Clock::now();
    for (auto& [id, cell] : cells) {
      if (!cell.alive || cell.quarantined || cell.phase != CellPhase::kIdle ||
          now < cell.next_claim)
        continue;
      cell.next_claim = now + std::chrono::milliseconds(200);  // poll the store gently when idle
      const auto claim_started = Clock::now();
      std::optional<db::ClaimedTrial> claim;
      try {
        claim = store->ClaimNextTrial(id);
      } catch (const db::StoreError& e) {
        if (StoreFailed(e)) throw;
        spdlog::error("cell {}: claim failed: {}", id, e.what());
        continue;
      }
      if (!claim) continue;
      cell.claimed_at = claim_started;
      cell.campaign_id = claim->campaign_id;
      cell.execute_wall_s = -1;
      StartExecution(cell, *claim);
    }
  }

  void StartExecution(CellRun& cell, const db::ClaimedTrial& claim) {
    const std::string tag = TrialTag(claim.campaign_id, claim.trial_id, claim.attempt);
    Execution ex;
    ex.trial_id = claim.trial_id;
    ex.campaign_id = claim.campaign_id;
    ex.attempt = claim.attempt;
    ex.cell_id = cell.id;
    try {
      ex.scene = mechanics::ParseScene(claim.scene_json);
      ex.normals = ContactNormals(ex.scene);
      ex.ingest = store->BeginIngest(claim.trial_id, claim.attempt);
    } catch (const mechanics::SceneError& e) {
      store->FailTrial(claim.trial_id, claim.attempt, std::string("invalid scene: ") + e.what(),
                       "invalid_scene");
      Count(&ServiceCounters::failed);
      spdlog::error("{}: invalid scene: {}", tag, e.what());
      return;
    }
    const double budget =
        opt.execute_timeout_s + ex.scene.duration * std::max(cell.speed, 0.0) * 1.5;
    msg::TrialCommand cmd;
    cmd.cell_id(cell.id);
    cmd.trial_id(static_cast<std::uint64_t>(claim.trial_id));
    cmd.attempt(static_cast<std::uint32_t>(claim.attempt));
    cmd.phase(msg::PHASE_EXECUTE);
    cmd.scene_json(claim.scene_json);
    cmd.seed(claim.seed);
    cmd.deadline_s(budget);
    cmd.service_session(session);
    cell.phase = CellPhase::kExecuting;
    cell.trial_id = claim.trial_id;
    cell.attempt = claim.attempt;
    cell.deadline = After(budget + 2.0);
    executions.emplace(claim.trial_id, std::move(ex));
    Count(&ServiceCounters::dispatched);
    if (!commands.Write(cmd)) {
      AbortPhase(cell, "EXECUTE command could not be sent", true);
      return;
    }
    spdlog::info("{}: EXECUTE on cell {}", tag, cell.id);
  }

  // ------------------------------------------------------------ execute
  void OnGroundTruth(const msg::GroundTruth& batch) {
    auto it = executions.find(static_cast<std::int64_t>(batch.trial_id()));
    if (it == executions.end() || it->second.attempt != static_cast<int>(batch.attempt())) return;
    Execution& ex = it->second;
    const std::string problem = dds::CheckBatch(batch, ex.next_sample);
    if (!problem.empty()) {
      FailStream(ex, "malformed ground truth from cell " + batch.cell_id() + ": " + problem);
      return;
    }
    try {
      std::vector<db::Sample> samples;
      samples.reserve(batch.samples().size());
      for (const auto& s : batch.samples()) {
        mechanics::TrajectorySample truth;
        samples.push_back(ToStoreSample(s, ex.normals, &truth));
        ex.truth.push_back(std::move(truth));
      }
      ex.ingest->Add(samples);
      ex.next_sample += static_cast<std::uint32_t>(samples.size());
      Count(&ServiceCounters::samples, static_cast<std::int64_t>(samples.size()));
    } catch (const std::exception& e) {
      if (StoreFailed(e)) throw;
      FailStream(ex, std::string("ground truth refused: ") + e.what());
      return;
    }
    MaybeFinishExecution(ex.trial_id);
  }

  void FailStream(Execution& ex, const std::string& reason) {
    CellRun& cell = Cell(ex.cell_id);
    spdlog::error("{}: {}", TrialTag(ex.campaign_id, ex.trial_id, ex.attempt), reason);
    AbortPhase(cell, reason, true);
  }

  void MaybeFinishExecution(std::int64_t trial_id) {
    auto it = executions.find(trial_id);
    if (it == executions.end()) return;
    Execution& ex = it->second;
    if (ex.expected < 0 || ex.next_sample < ex.expected) return;
    const std::string tag = TrialTag(ex.campaign_id, ex.trial_id, ex.attempt);
    CellRun& cell = Cell(ex.cell_id);
    try {
      const std::int64_t n = ex.ingest->Finish("ok");
      Count(&ServiceCounters::executed);
      spdlog::info("{}: executed, {} samples stored", tag, n);
      CellResult(cell, true, "");
      PredictionJob job{ex.trial_id,         ex.attempt,
                        ex.campaign_id,      ScenesForPrediction(ex.scene, ex.campaign_id),
                        std::move(ex.truth), std::move(ex.commands)};
      predictor.Submit(std::move(job));
      // Aim the reset at the start of the trial this cell will most likely run next.
      std::optional<db::ClaimedTrial> next = store->PeekNextTrial(cell.id);
      store->BeginReset(ex.trial_id, ex.attempt);
      msg::TrialCommand cmd;
      cmd.cell_id(cell.id);
      cmd.trial_id(static_cast<std::uint64_t>(ex.trial_id));
      cmd.attempt(static_cast<std::uint32_t>(ex.attempt));
      cmd.phase(msg::PHASE_RESET);
      cmd.scene_json(next ? next->scene_json : std::string());
      cmd.seed(next ? next->seed : 0);
      cmd.deadline_s(opt.reset_timeout_s);
      cmd.service_session(session);
      executions.erase(it);
      cell.phase = CellPhase::kResetting;
      cell.deadline = After(opt.reset_timeout_s + 2.0);
      if (!commands.Write(cmd)) AbortPhase(cell, "RESET command could not be sent", true);
    } catch (const std::exception& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("{}: {}", tag, e.what());
      AbortPhase(cell, e.what(), true);
    }
  }

  // Closed loop (issue 19): the commands the cell applied and the
  // controller's outcome, stored with the attempt; the commands also go to
  // the prediction (replayed through the model).
  void RecordClosedLoop(Execution& ex, const msg::TrialStatus& st) {
    const std::string tag = TrialTag(ex.campaign_id, ex.trial_id, ex.attempt);
    try {
      auto run = ClosedLoopFromDetail(ex.trial_id, ex.attempt, st.reason(), st.detail_json());
      if (!run) return;
      store->RecordClosedLoop(*run);
      ex.commands = CommandsOf(*run);
    } catch (const db::StoreError& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("{}: closed-loop record: {}", tag, e.what());
    } catch (const std::exception& e) {
      spdlog::error("{}: closed-loop record: {}", tag, e.what());
    }
  }

  // ------------------------------------------------------------ statuses
  void OnStatus(const msg::TrialStatus& st) {
    const std::string id = st.cell_id();
    auto cit = cells.find(id);
    if (cit == cells.end()) return;
    CellRun& cell = cit->second;
    if (cell.phase == CellPhase::kIdle ||
        cell.trial_id != static_cast<std::int64_t>(st.trial_id()) ||
        cell.attempt != static_cast<int>(st.attempt())) {
      return;  // late or repeated status of a phase already settled
    }
    if (st.phase() == msg::PHASE_EXECUTE && cell.phase == CellPhase::kExecuting) {
      auto it = executions.find(cell.trial_id);
      if (it == executions.end()) return;
      Execution& ex = it->second;
      switch (st.state()) {
        case msg::STATE_ACCEPTED:
          break;
        case msg::STATE_EXECUTED:
          RecordClosedLoop(ex, st);
          cell.execute_wall_s = st.phase_wall_s();
          ex.expected = st.samples();
          ex.stream_deadline = After(opt.stream_grace_s);
          MaybeFinishExecution(ex.trial_id);
          break;
        case msg::STATE_REFUSED: {
          const std::string reason = "refused by cell " + id + ": " + st.reason();
          RetryExecution(ex, reason);
          executions.erase(it);
          cell.phase = CellPhase::kIdle;
          cell.next_claim = After(0.5);  // another cell may take it
          break;
        }
        default:
          RecordClosedLoop(ex, st);
          if (st.reason().rfind("simulation:", 0) == 0) {
            // A simulated cell's model could not run this scene. The cell is
            // fine and a re-run is bit-identical, so the trial fails at once.
            const std::string tag = TrialTag(ex.campaign_id, ex.trial_id, ex.attempt);
            try {
              store->FailTrial(ex.trial_id, ex.attempt, "cell " + id + ": " + st.reason(),
                               "solver_failure");
              Count(&ServiceCounters::failed);
              spdlog::error("{}: failed on cell {}: {}", tag, id, st.reason());
            } catch (const db::StoreError& e) {
              if (StoreFailed(e)) throw;
              spdlog::error("{}: {}", tag, e.what());
            }
            executions.erase(it);
            cell.phase = CellPhase::kIdle;
            cell.next_claim = Clock::now();
            break;
          }
          AbortPhase(cell, "cell " + id + " failed: " + st.reason(), true);
          break;
      }
    } else if (st.phase() == msg::PHASE_RESET && cell.phase == CellPhase::kResetting) {
      if (st.state() != msg::STATE_RESET_DONE && st.state() != msg::STATE_FAILED) return;
      const bool ok = st.state() == msg::STATE_RESET_DONE;
      db::ResetReport report;
      report.ok = ok;
      std::copy(st.observed_pose().begin(), st.observed_pose().end(), report.observed_pose.begin());
      report.position_error = st.reset_position_error();
      report.angle_error = st.reset_angle_error();
      report.reset_attempts = static_cast<int>(st.reset_attempts());
      report.reason = st.reason();
      try {
        store->CompleteReset(cell.trial_id, cell.attempt, report);
        if (!ok) {
          Count(&ServiceCounters::resets_failed);
          spdlog::warn("trial {} attempt {}: reset on cell {} failed: {}", cell.trial_id,
                       cell.attempt, id, st.reason());
        }
        CellResult(cell, ok, st.reason());
        if (ok) ReportTiming(cell, st.phase_wall_s());
        AfterReset(cell.trial_id);
      } catch (const db::StoreError& e) {
        if (StoreFailed(e)) throw;
        spdlog::error("trial {}: {}", cell.trial_id, e.what());
      }
      cell.phase = CellPhase::kIdle;
      cell.next_claim = Clock::now();
    }
  }

  // The split of a clean trial's time on its cell (TrialTiming). A cell's
  // reported phase times are its word: non-finite or negative ones give no figure.
  void ReportTiming(const CellRun& cell, double reset_wall_s) {
    const double busy = std::chrono::duration<double>(Clock::now() - cell.claimed_at).count();
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
    spdlog::debug(
        "trial {} attempt {} on cell {}: busy {:.3f} ms = execute {:.3f} + reset {:.3f} + arena "
        "{:.3f}",
        t.trial_id, t.attempt, t.cell_id, busy * 1e3, exec * 1e3, reset_wall_s * 1e3,
        t.overhead_s * 1e3);
    if (on_trial_timing) on_trial_timing(t);
  }

  // ------------------------------------------------------------ predictions
  void AfterReset(std::int64_t trial_id) {
    auto it = waiting_predictions.find(trial_id);
    if (it == waiting_predictions.end()) return;
    PredictionDone done = std::move(it->second);
    waiting_predictions.erase(it);
    RecordPrediction(std::move(done));
  }

  void OnPrediction(PredictionDone done) {
    db::Trial t;
    try {
      t = store->GetTrial(done.trial_id);
    } catch (const db::StoreError& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("trial {}: {}", done.trial_id, e.what());
      return;
    }
    if (t.attempt != done.attempt) return;  // the trial moved on (re-run): drop the old prediction
    if (t.state == db::TrialState::kResetting || t.state == db::TrialState::kExecuted) {
      waiting_predictions[done.trial_id] = std::move(done);
      return;
    }
    RecordPrediction(std::move(done));
  }

  void RecordPrediction(PredictionDone done) {
    const std::string tag = TrialTag(done.campaign_id, done.trial_id, done.attempt);
    try {
      store->RecordPrediction(done.trial_id, done.attempt, done.prediction);
      store->FinishTrial(done.trial_id, done.attempt);
      Count(&ServiceCounters::done);
      spdlog::info("{}: done (prediction {}, final position error {:.3g} m)", tag,
                   done.prediction.status, done.prediction.final_position_error.value_or(NAN));
    } catch (const db::StoreError& e) {
      if (StoreFailed(e)) throw;
      spdlog::error("{}: {}", tag, e.what());
    }
  }

  // ------------------------------------------------------------ deadlines
  void CheckDeadlines() {
    const auto now = Clock::now();
    for (auto& [id, cell] : cells) {
      if (cell.phase == CellPhase::kIdle) continue;
      if (cell.phase == CellPhase::kExecuting) {
        auto it = executions.find(cell.trial_id);
        if (it != executions.end() && it->second.expected >= 0 &&
            now > it->second.stream_deadline) {
          AbortPhase(cell,
                     "ground truth incomplete: " + std::to_string(it->second.next_sample) + " of " +
                         std::to_string(it->second.expected) + " samples",
                     true);
          continue;
        }
      }
      if (now > cell.deadline) {
        AbortPhase(cell,
                   std::string(cell.phase == CellPhase::kExecuting ? "EXECUTE" : "RESET") +
                       " missed its deadline on cell " + id,
                   true);
      }
    }
  }

  bool InFlight() const {
    for (const auto& [id, cell] : cells)
      if (cell.phase != CellPhase::kIdle) return true;
    return predictor.outstanding() > 0 || !waiting_predictions.empty();
  }

  bool CampaignsFinished() {
    store->CompleteFinishedCampaigns();
    for (const auto& c : store->ListCampaigns()) {
      if (opt.only_campaign > 0 && c.id != opt.only_campaign) continue;
      if (c.state == db::CampaignState::kActive || c.state == db::CampaignState::kPaused)
        return false;
    }
    return true;
  }

  int Run() {
    Resume();
    auto last_tick = Clock::now();
    std::optional<Clock::time_point> drain_deadline;
    for (;;) {
      if (stop_requested && !drain_deadline) {
        drain_deadline = After(opt.drain_timeout_s);
        spdlog::info("stopping: no new trials; waiting up to {} s for phases in flight",
                     opt.drain_timeout_s);
      }
      // Statuses are the latency-critical input: wait on them briefly.
      if (auto st = statuses.Take(std::chrono::milliseconds(1))) OnStatus(*st);
      for (auto& a : announces.TakeAll()) OnAnnounce(a);
      for (auto& b : truth_reader.TakeAll()) OnGroundTruth(b);
      for (auto& st : statuses.TakeAll()) OnStatus(st);
      while (auto e = participant.NextPeerEvent(std::chrono::milliseconds(0))) OnPeerEvent(*e);
      for (auto& p : predictor.TakeResults()) OnPrediction(std::move(p));
      CheckDeadlines();
      Dispatch();

      const auto now = Clock::now();
      if (now - last_tick > std::chrono::milliseconds(100)) {
        last_tick = now;
        for (auto& [id, ex] : executions) ex.ingest->Poll();
        if (on_tick) on_tick(Snapshot());
        if (opt.exit_when_done && !InFlight() && CampaignsFinished()) {
          spdlog::info("every campaign is finished");
          break;
        }
      }
      if (drain_deadline) {
        if (!InFlight()) break;
        if (now > *drain_deadline) {
          spdlog::warn("stopping with phases in flight; they are re-run after the next start");
          break;
        }
      }
    }
    if (on_tick) on_tick(Snapshot());
    return 0;
  }

  ServiceCounters Snapshot() {
    int known = 0, usable = 0;
    for (const auto& [id, cell] : cells) {
      ++known;
      usable += cell.alive && !cell.quarantined;
    }
    std::lock_guard lock(counters_mu);
    counters.cells_known = known;
    counters.cells_usable = usable;
    return counters;
  }
};

Service::Service(const ServiceOptions& options) {
  if (options.db_path.empty()) throw std::invalid_argument("--db: must name the store file");
  if (options.domain_id < 0 || options.domain_id > 232)
    throw std::invalid_argument("--domain: must be 0..232, got " +
                                std::to_string(options.domain_id));
  if (options.max_attempts < 1) throw std::invalid_argument("max_attempts: must be >= 1");
  if (options.quarantine_after < 1) throw std::invalid_argument("quarantine_after: must be >= 1");
  impl_ = std::make_unique<Impl>(options);
}

Service::~Service() = default;

int Service::Run() { return impl_->Run(); }
void Service::Stop() { impl_->stop_requested = true; }
ServiceCounters Service::counters() const {
  std::lock_guard lock(impl_->counters_mu);
  return impl_->counters;
}
void Service::OnTick(std::function<void(const ServiceCounters&)> callback) {
  impl_->on_tick = std::move(callback);
}
void Service::OnTrialTiming(std::function<void(const TrialTiming&)> callback) {
  impl_->on_trial_timing = std::move(callback);
}

}  // namespace arena::orchestrator
