// The campaign service's shell: DDS endpoints, the SQLite store and the
// predictor threads around the TrialDriver (trial_driver.hpp), which makes
// every decision. The contract and a trial's path are in service.hpp.
#include "arena/orchestrator/service.hpp"
#include "arena/orchestrator/scene_facts.hpp"

#include <signal.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/assessment/truth.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/adaptive.hpp"
#include "arena/orchestrator/logging.hpp"
#include "arena/orchestrator/notifier.hpp"
#include "arena/orchestrator/suspenders.hpp"
#include "arena/orchestrator/trial_data.hpp"
#include "arena/orchestrator/trial_driver.hpp"
#include "arena/schemas/arena.h"
#include "predictor_yield.hpp"
#include "service_watch.hpp"

namespace arena::orchestrator {

namespace {

using assessment::ApplyModelSettings;
using assessment::ContactNormals;
using assessment::PredictionFailure;
using assessment::PredictTrial;
using assessment::ToTrajectorySample;
using Clock = std::chrono::steady_clock;
using Seconds = std::chrono::duration<double>;

constexpr char kCellPrefix[] = "arena.cell.";
// A service whose last beat is younger than this holds the store (unless its
// pid is known dead on this host).
constexpr double kServiceFresh_s = 15.0;
// A service on this host is asked (its pid) if it beat within this long.
constexpr double kServiceRemembered_s = 600.0;

std::string CellOfParticipant(const std::string& participant) {
  const std::string prefix = kCellPrefix;
  return participant.rfind(prefix, 0) == 0 ? participant.substr(prefix.size()) : "";
}

Clock::time_point After(double seconds) {
  return Clock::now() + std::chrono::duration_cast<Clock::duration>(Seconds(seconds));
}

std::string HostName() {
  char buf[256] = {};
  if (gethostname(buf, sizeof buf - 1) != 0) return "unknown-host";
  return buf;
}

bool ProcessAlive(std::int64_t pid) {
  if (pid <= 0) return false;
  return kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM;
}

// ------------------------------------------------------------ store port
class SqliteSink : public GroundTruthSink {
 public:
  explicit SqliteSink(std::unique_ptr<db::Ingest> ingest) : ingest_(std::move(ingest)) {}
  void Add(const std::vector<db::Sample>& samples) override { ingest_->Add(samples); }
  void Poll() override { ingest_->Poll(); }
  std::int64_t Finish() override { return ingest_->Finish(); }
  std::int64_t Finish(const db::FinishAlso& also) {
    return ingest_->Finish(db::TrialEnd::kOk, also);
  }

 private:
  std::unique_ptr<db::Ingest> ingest_;
};

// The store's quick check at a cadence, on its own read-only connection in
// its own thread (a check of a large store takes seconds; the service loop
// must not wait for it). WAL lets it read beside the service's writes.
class IntegrityMonitor {
 public:
  IntegrityMonitor(const std::string& path, double period_s, bool open_check_complete)
      : path_(path), period_(period_s) {
    thread_ = std::thread([this, open_check_complete] { Run(!open_check_complete); });
  }
  ~IntegrityMonitor() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
      if (reader_) reader_->Interrupt();
    }
    cv_.notify_all();
    thread_.join();
  }
  void ThrowIfDamaged() const {
    std::lock_guard lock(mu_);
    if (!damage_.empty()) throw db::StoreError(db::StoreError::Kind::kCorrupt, damage_);
  }

 private:
  void Run(bool check_now) {
    std::unique_lock lock(mu_);
    for (;;) {
      if (!check_now)
        cv_.wait_for(lock, std::chrono::duration<double>(period_), [&] { return stop_; });
      check_now = false;
      if (stop_) return;
      lock.unlock();
      std::string damage;
      double seconds = 0;
      try {
        db::StoreOptions ro;
        ro.read_only = true;
        auto reader = db::Store::Open(path_, ro);
        {
          std::lock_guard l(mu_);
          if (stop_) return;
          reader_ = reader.get();
        }
        const auto r = reader->QuickCheck(0);
        {
          std::lock_guard l(mu_);
          reader_ = nullptr;
        }
        seconds = r.seconds;
        if (r.complete && !r.problems.empty()) damage = r.problems.substr(0, 400);
      } catch (const db::StoreError& e) {
        if (e.kind() == db::StoreError::Kind::kCorrupt)
          damage = e.what();
        else
          spdlog::warn("store quick check could not run: {}", e.what());
      }
      lock.lock();
      if (!damage.empty()) {
        damage_ = "the store '" + path_ + "' is corrupt (PRAGMA quick_check: " + damage +
                  "); stopped before writing more into it";
        return;
      }
      if (!stop_) spdlog::debug("store quick check: ok ({:.1f} s)", seconds);
    }
  }

  std::string path_;
  double period_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  const db::Store* reader_ = nullptr;
  std::string damage_;
  std::thread thread_;
};

class SqliteTrialStore : public TrialStore {
 public:
  SqliteTrialStore(db::Store& store, std::string session)
      : s_(store), session_(std::move(session)) {}
  db::RecoveryReport RecoverAfterRestart() override { return s_.RecoverAfterRestart(); }
  std::vector<db::Trial> ListTrialsByState(const std::vector<db::TrialState>& states) override {
    return s_.ListTrialsByState(states);
  }
  db::Trial GetTrial(std::int64_t id) override { return s_.GetTrial(id); }
  std::optional<db::ClaimedTrial> ClaimNextTrial(const std::string& cell) override {
    return s_.ClaimNextTrial(cell);
  }
  std::vector<db::ClaimedTrial> ClaimWindow(const std::string& cell, int limit) override {
    return s_.ClaimWindow(cell, limit);
  }
  std::optional<db::ClaimedTrial> ClaimTrial(const std::string& cell, std::int64_t trial_id,
                                             const std::string& rule) override {
    return s_.ClaimTrial(cell, trial_id, rule);
  }
  db::Campaign GetCampaign(std::int64_t campaign_id) override {
    return s_.GetCampaign(campaign_id);
  }
  void RecordFixtureChanges(const std::vector<db::FixtureChangeRecord>& changes) override {
    s_.RecordFixtureChanges(changes);
  }
  // The claim gate (issue 26).
  std::vector<db::PlannedNeed> PlannedNeeds() override { return s_.PlannedNeeds(); }
  void SetCampaignWait(std::int64_t campaign_id, const std::string& kind, const std::string& reason,
                       const std::string& rule) override {
    s_.SetCampaignWait(campaign_id, kind, reason, rule);
  }
  void ClearCampaignWait(std::int64_t campaign_id) override { s_.ClearCampaignWait(campaign_id); }
  std::vector<db::CampaignWait> ListCampaignWaits() override { return s_.ListCampaignWaits(); }
  void RestrictClaimsTo(std::optional<std::vector<std::int64_t>> campaigns) override {
    s_.RestrictClaimsTo(std::move(campaigns));
  }
  std::vector<std::int64_t> ActiveCampaignIds() override { return s_.ActiveCampaignIds(); }
  std::optional<db::ClaimedTrial> PeekNextTrial(const std::string& cell) override {
    return s_.PeekNextTrial(cell);
  }
  std::unique_ptr<GroundTruthSink> BeginIngest(std::int64_t trial_id, int attempt,
                                               std::vector<db::ContactSite> sites) override {
    return std::make_unique<SqliteSink>(
        s_.BeginIngest(trial_id, attempt, std::move(sites), db::IngestOptions{}));
  }
  db::TrialState RetryTrial(std::int64_t id, int attempt, const std::string& reason,
                            int max_attempts, double backoff_s, const std::string& rule) override {
    return s_.RetryTrial(id, attempt, reason, max_attempts, backoff_s, rule);
  }
  void ReleaseTrial(std::int64_t id, int attempt, const std::string& reason,
                    const std::string& rule) override {
    s_.ReleaseTrial(id, attempt, reason, rule);
  }
  void FailTrial(std::int64_t id, int attempt, const std::string& reason, db::TrialEnd outcome,
                 const std::string& rule) override {
    s_.FailTrial(id, attempt, reason, outcome, rule);
  }
  void BeginReset(std::int64_t id, int attempt, const std::string& rule) override {
    s_.BeginReset(id, attempt, rule);
  }
  // One transaction (Ingest::Finish with `also`): every sink here is a SqliteSink.
  std::int64_t PublishExecuted(GroundTruthSink& sink, std::int64_t, int,
                               const db::FinishAlso& also) override {
    return static_cast<SqliteSink&>(sink).Finish(also);
  }
  void CompleteReset(std::int64_t id, int attempt, const db::ResetReport& r,
                     const std::string& rule) override {
    s_.CompleteReset(id, attempt, r, rule);
  }
  void RecordPrediction(std::int64_t id, int attempt, const db::Prediction& p) override {
    s_.RecordPrediction(id, attempt, p);
  }
  void FinishTrial(std::int64_t id, int attempt) override { s_.FinishTrial(id, attempt); }
  void RecordPredictionAndFinish(std::int64_t id, int attempt, const db::Prediction& p) override {
    s_.RecordPredictionAndFinish(id, attempt, p);
  }
  void RecordExecution(std::int64_t id, int attempt, const std::string& backend,
                       const std::string& truth, const std::string& defects_applied) override {
    s_.RecordExecution(id, attempt, backend, truth, defects_applied);
  }
  void RecordClosedLoop(const db::ClosedLoopRun& run) override { s_.RecordClosedLoop(run); }
  void UpsertCell(const std::string& id, const std::vector<std::string>& types,
                  const std::string& caps, const std::string& defects) override {
    s_.UpsertCell(id, types, caps, defects);
  }
  bool CellQuarantined(const std::string& id) override {
    return s_.GetCell(id).state == db::CellState::kQuarantined;
  }
  int RecordCellResult(const std::string& id, bool ok) override {
    return s_.RecordCellResult(id, ok);
  }
  void QuarantineCell(const std::string& id, const std::string& reason) override {
    s_.QuarantineCell(id, reason);
  }
  void MarkCellGone(const std::string& id, const std::string& reason) override {
    s_.MarkCellGone(id, reason);
  }
  void SetCellServing(const std::string& id, double lease_s, const std::string& serving) override {
    s_.SetCellServing(id, lease_s, serving);
  }
  bool CompleteFinishedCampaigns(std::int64_t only) override {
    s_.CompleteFinishedCampaigns();
    for (const auto& c : s_.ListCampaigns()) {
      if (only > 0 && c.id != only) continue;
      if (c.state == db::CampaignState::kActive || c.state == db::CampaignState::kPaused)
        return false;
    }
    return true;
  }
  void ServiceBeat(const std::vector<std::string>& cells) override {
    s_.ServiceBeat(session_, cells);
  }
  // The tick's look at the file: still the one opened, and no damage found
  // by the background quick check (both throw: the service stops, exit 3).
  void CheckFileIdentity() override {
    s_.CheckFileIdentity();
    if (integrity_) integrity_->ThrowIfDamaged();
  }
  void WatchIntegrity(const class IntegrityMonitor* m) { integrity_ = m; }

 private:
  db::Store& s_;
  std::string session_;
  const IntegrityMonitor* integrity_ = nullptr;
};

// Checkpoints the store's WAL on its own thread and connection when a
// commit says one is due (db::StoreOptions::wal_checkpoint_due), so no
// trial's commit stalls 14-18 ms every ~40 trials copying the WAL into the
// database file (issue 27). Nothing is opened until the first checkpoint is
// due; a checkpoint that fails is logged and left to the writer's backstop.
class WalCheckpointer {
 public:
  explicit WalCheckpointer(std::string path) : path_(std::move(path)) {
    thread_ = std::thread([this] { Run(); });
  }
  ~WalCheckpointer() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  WalCheckpointer(const WalCheckpointer&) = delete;
  WalCheckpointer& operator=(const WalCheckpointer&) = delete;
  // From the writer's commit: never waits for the checkpoint.
  void Due() {
    {
      std::lock_guard lock(mu_);
      due_ = true;
    }
    cv_.notify_one();
  }

 private:
  void Run() {
    std::unique_ptr<db::Store> store;
    std::unique_lock lock(mu_);
    for (;;) {
      cv_.wait(lock, [&] { return stop_ || due_; });
      if (stop_) return;
      due_ = false;
      lock.unlock();
      try {
        if (!store) {
          db::StoreOptions so;
          so.create = false;
          so.open_check_budget_s = 0;  // the service's own open checked the file
          store = db::Store::Open(path_, so);
        }
        const std::int64_t frames = store->CheckpointWal();
        spdlog::debug("store: WAL checkpointed in the background ({} frames)", frames);
      } catch (const std::exception& e) {
        spdlog::warn(
            "store: background WAL checkpoint failed ({}); commits checkpoint past 4x "
            "the WAL's size",
            e.what());
        store.reset();
      }
      lock.lock();
    }
  }

  const std::string path_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool due_ = false, stop_ = false;
  std::thread thread_;  // last: starts once the rest is built
};

class DdsTransport : public CommandTransport {
 public:
  explicit DdsTransport(dds::Participant& p) : writer_(p) {}
  bool Send(msg::TrialCommand& c) override { return writer_.Write(c); }

 private:
  dds::Writer<msg::TrialCommand> writer_;
};

// ------------------------------------------------------------ predictor
struct PredictionJob {
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::int64_t campaign_id = 0;
  mechanics::Scene scene;  // with the campaign's model settings applied
  std::vector<mechanics::TrajectorySample> truth;
  nlohmann::json prediction;  // the campaign's `prediction` (names the predictor)
  // Closed loop: the applied commands, replayed through the model; empty otherwise.
  assessment::RecordedCommands commands;
  assessment::PredictionStart start;  // where `scene`'s object starts (noted in the prediction)
};

// Worker threads that run the predictor; jobs in, results out. Start()
// runs on the service thread (it reads the store for a resumed trial).
class PredictorPool : public PredictionPort {
 public:
  PredictorPool(int threads, int nice, int backlog_bound) : backlog_bound_(backlog_bound) {
    for (int i = 0; i < std::max(1, threads); ++i)
      workers_.emplace_back([this, nice] {
        LowerPriority(nice);
        Work();
      });
  }
  ~PredictorPool() override {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    path_.Stop();
    cv_.notify_all();
    for (auto& w : workers_) w.join();
  }
  void SetStore(db::Store* store) { store_ = store; }
  // The trials' path, written by the service's loop (TrialDriver::OnPathChange).
  PathWatch& path() { return path_; }

  void Start(PredictionRequest r) override {
    PredictionJob job{r.trial_id,         r.attempt, r.campaign_id,         {},
                      std::move(r.truth), {},        std::move(r.commands), {}};
    std::optional<db::Sample> first = std::move(r.first_sample);
    try {
      mechanics::Scene scene = r.scene_json.empty() || !job.truth.empty()
                                   ? std::move(r.scene)
                                   : mechanics::ParseScene(r.scene_json);
      if (job.truth.empty()) {  // a resumed trial: its ground truth is in the store
        const db::GroundTruth gt = store_->ReadGroundTruth(r.trial_id);
        if (!gt.samples.empty()) first = gt.samples.front();
        const auto normals = ContactNormals(scene);
        for (const auto& s : gt.samples)
          job.truth.push_back(
              ToTrajectorySample(s, normals, scene.pusher.has_value(), gt.forces_measured()));
        // Closed loop: the commands it applied, replayed (issue 19).
        if (job.commands.empty() && scene.pusher && scene.pusher->controller) {
          if (auto run = store_->GetClosedLoop(r.trial_id))
            job.commands = assessment::CommandsOf(*run);
        }
      }
      job.prediction = CampaignModel(r.campaign_id);
      // From the start pose the cell measured (issue 26), unless the campaign
      // asks for the planned one (prediction.start).
      job.start = assessment::StartOf(scene, first ? &*first : nullptr,
                                      assessment::StartFromOf(job.prediction));
      job.scene = ApplyModelSettings(assessment::StartedAt(scene, job.start), job.prediction);
    } catch (const db::StoreError& e) {
      using K = db::StoreError::Kind;
      // A store that cannot be written stops the service; anything else
      // (busy reading, a missing stream) costs this prediction only.
      if (e.kind() == K::kFull || e.kind() == K::kIo || e.kind() == K::kReadOnly ||
          e.kind() == K::kTooNew)
        throw;
      Fail(job, e.what());
      return;
    } catch (const std::exception& e) {
      Fail(job, e.what());
      return;
    }
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
  int outstanding() const override {
    std::lock_guard lock(mu_);
    return outstanding_;
  }

 private:
  void Fail(const PredictionJob& job, const std::string& why) {
    spdlog::error("{}: cannot predict: {}", TrialTag(job.campaign_id, job.trial_id, job.attempt),
                  why);
    std::lock_guard lock(mu_);
    ++outstanding_;
    results_.push_back(PredictionDone{job.trial_id, job.attempt, job.campaign_id,
                                      PredictionFailure(db::PredictionStatus::kError, why)});
  }

  // The campaign's model settings (spec "prediction", or null), cached.
  const nlohmann::json& CampaignModel(std::int64_t campaign_id) {
    auto it = models_.find(campaign_id);
    if (it != models_.end()) return it->second;
    nlohmann::json model;
    try {
      const auto spec = nlohmann::json::parse(store_->GetCampaign(campaign_id).spec_json);
      if (spec.is_object() && spec.contains("prediction")) model = spec["prediction"];
    } catch (const nlohmann::json::exception& e) {
      spdlog::warn("campaign {}: spec unreadable ({}), predicting with the scene's model",
                   campaign_id, e.what());
    }
    return models_.emplace(campaign_id, model).first->second;
  }

  // This thread only (Linux: a thread's nice value is its own). A refusal
  // (a container without the right) costs the priority, not the predictions.
  static void LowerPriority(int nice) {
    if (nice <= 0) return;
    const auto tid = static_cast<id_t>(syscall(SYS_gettid));
    errno = 0;
    const int current = getpriority(PRIO_PROCESS, tid);
    if (errno != 0 || setpriority(PRIO_PROCESS, tid, std::min(19, current + nice)) != 0)
      spdlog::warn("predictor thread: cannot lower its priority: {}", std::strerror(errno));
  }

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
      // The model waits for the cells' path to be quiet (predictor_yield.hpp).
      const char* rule = path_.WaitToStart(backlog_bound_, [this] {
        std::lock_guard lock(mu_);
        return outstanding_;
      });
      if (*rule == '\0') return;  // stopping
      PredictionDone done{job.trial_id, job.attempt, job.campaign_id,
                          assessment::PredictTrial(job.scene, job.truth, job.prediction,
                                                   job.commands.empty() ? nullptr : &job.commands)};
      assessment::NoteStart(&done.prediction, job.start);
      std::lock_guard lock(mu_);
      results_.push_back(std::move(done));
    }
  }

  db::Store* store_ = nullptr;
  const int backlog_bound_;
  PathWatch path_;
  std::map<std::int64_t, nlohmann::json> models_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<PredictionJob> jobs_;
  std::vector<PredictionDone> results_;
  int outstanding_ = 0;
  bool stop_ = false;
  std::vector<std::thread> workers_;
};

std::uint64_t NewSession() {
  std::random_device rd;
  std::uint64_t s = 0;
  while (s == 0) s = (static_cast<std::uint64_t>(rd()) << 32) ^ rd();  // 0 means "no session"
  return s;
}

}  // namespace

struct Service::Impl {
  ServiceOptions opt;
  const std::uint64_t session = NewSession();
  dds::Participant participant;
  DdsTransport transport;
  // Rung by each input reader: the loop wakes on whichever input comes.
  std::shared_ptr<dds::Doorbell> input = std::make_shared<dds::Doorbell>();
  dds::Reader<msg::CellAnnounce> announces;
  dds::Reader<msg::TrialStatus> statuses;
  dds::Reader<msg::GroundTruth> truth_reader;
  PredictorPool predictor;
  // After the participant: a bad network or security setting fails before
  // the store file is created or touched (bad input changes nothing stored).
  std::unique_ptr<db::Store> store;
  std::unique_ptr<SqliteTrialStore> trial_store;
  std::unique_ptr<IntegrityMonitor> integrity;  // trial_store points at it: ends before it
  std::unique_ptr<TrialDriver> driver;
  // Adaptive campaigns' next rounds (adaptive.hpp): one call per scheduling pass.
  std::unique_ptr<AdaptivePlanner> adaptive;
  // Issue 29: suspenders (fed by the driver, gate its claims), the events'
  // command and the watch that ties them to the store.
  std::unique_ptr<Suspenders> suspenders;
  std::unique_ptr<Notifier> notifier;
  std::unique_ptr<ServiceWatch> watch;
  bool registered = false;

  std::atomic<bool> stop_requested{false};
  std::function<void(const ServiceCounters&)> on_tick;

  static dds::ReaderOptions RungBy(std::shared_ptr<dds::Doorbell> doorbell) {
    dds::ReaderOptions o;
    o.doorbell = std::move(doorbell);
    return o;
  }

  static db::StoreOptions StoreOptionsFor(const ServiceOptions& o,
                                          std::shared_ptr<WalCheckpointer> checkpointer) {
    db::StoreOptions so;
    so.wal_checkpoint_due = [checkpointer] { checkpointer->Due(); };
    so.scene_facts = SceneFactsOfJson;  // an older store's migration reads scenes
    so.max_pages = o.store_max_pages;
    return so;
  }

  Impl(const ServiceOptions& o)
      : opt(o),
        participant(dds::ParticipantOptions{o.domain_id, "arena.service", o.network, 2.5}),
        transport(participant),
        announces(participant, RungBy(input)),
        statuses(participant, RungBy(input)),
        truth_reader(participant, RungBy(input)),
        predictor(o.predictor_threads, o.predictor_nice, o.prediction_backlog),
        store(db::Store::Open(o.db_path,
                              StoreOptionsFor(o, std::make_shared<WalCheckpointer>(o.db_path)))) {
    predictor.SetStore(store.get());
    ServiceIdentity me{session, HostName(), static_cast<std::uint32_t>(getpid()), store->StoreId()};
    // One service per store: a second one refuses to start, naming the first.
    db::ServiceRecord record{SessionHex(session), getpid(), me.host, o.domain_id, 0, 0, {}};
    // On this host the pid says whether it lives (even if a long foreign
    // write lock kept it from beating); elsewhere its beat must be fresh.
    const double now = store->Now();
    const auto holder =
        store->RegisterService(record, kServiceRemembered_s, [&](const db::ServiceRecord& other) {
          return other.host == me.host ? ProcessAlive(other.pid)
                                       : now - other.last_beat < kServiceFresh_s;
        });
    if (holder) {
      throw db::StoreError(db::StoreError::Kind::kBusy,
                           "another service is serving '" + o.db_path + "': pid " +
                               std::to_string(holder->pid) + " on host " + holder->host +
                               " (DDS domain " + std::to_string(holder->domain) +
                               ", last heartbeat " +
                               std::to_string(static_cast<int>(store->Now() - holder->last_beat)) +
                               " s ago); stop it first, or use another store");
    }
    registered = true;
    store->SetBusyTimeout(o.store_busy_timeout_ms);
    trial_store = std::make_unique<SqliteTrialStore>(*store, SessionHex(session));
    const auto& checked = store->open_check();
    if (!checked.complete)
      spdlog::warn(
          "store quick check incomplete after {:.1f} s (a large store); finishing it in "
          "the background",
          checked.seconds);
    integrity =
        std::make_unique<IntegrityMonitor>(o.db_path, o.integrity_check_period_s, checked.complete);
    trial_store->WatchIntegrity(integrity.get());
    adaptive = std::make_unique<AdaptivePlanner>(*store);
    DriverOptions d;
    d.service = o;
    d.queue_next_execute = o.queue_next_execute;
    driver = std::make_unique<TrialDriver>(d, me, *trial_store, transport, predictor);
    driver->OnInputWaiting([doorbell = input] { return doorbell->Rung(); });
    driver->OnPathChange([&path = predictor.path()](const std::string& cell, bool on_path) {
      const auto t = PathWatch::Clock::now();
      on_path ? path.OnPath(cell, t) : path.OffPath(cell, t);
    });
    const auto t0 = Clock::now();
    suspenders = std::make_unique<Suspenders>(o.suspenders,
                                              [t0] { return Seconds(Clock::now() - t0).count(); });
    driver->SetObserver(suspenders.get());
    if (!o.notify_command.empty())
      notifier = std::make_unique<Notifier>(o.notify_command, o.notify_timeout_s,
                                            static_cast<std::size_t>(o.notify_queue));
    watch = std::make_unique<ServiceWatch>(*store, opt, *suspenders, notifier.get());
    spdlog::info("service session {} (pid {} on {})", SessionHex(session), me.pid, me.host);
  }

  ~Impl() {
    if (!registered) return;
    try {
      store->ServiceStopped(SessionHex(session));
    } catch (const std::exception& e) {
      spdlog::warn("cannot record the service's stop: {}", e.what());
    }
  }

  // How many participants carry this cell's name now (a restart within the
  // lease: the new process is there while the old one's loss arrives).
  int ProcessesNamed(const std::string& cell_id) const {
    const std::string name = dds::CellParticipantName(cell_id);
    int n = 0;
    for (const auto& p : participant.Peers()) n += p == name;
    return n;
  }

  void OnPeerEvent(const dds::PeerEvent& e) {
    const std::string id = CellOfParticipant(e.participant);
    if (id.empty()) return;
    using Kind = dds::PeerEvent::Kind;
    if (e.kind == Kind::kParticipantLeft || e.kind == Kind::kWriterLost) {
      // Left: the gone one is no longer listed. Writer lost: it still is.
      const int others = ProcessesNamed(id) - (e.kind == Kind::kWriterLost ? 1 : 0);
      driver->OnCellLost(id, std::string("liveliness lost (") + dds::ToString(e.kind) + ")",
                         others > 0);
    } else if (e.kind == Kind::kWriterAlive) {
      driver->OnCellAlive(id);
    }
  }

  // On a clean stop: cells we serve are released at once (the next service
  // need not wait for the lease).
  void ReleaseCells() {
    for (const auto& p : participant.Peers()) {
      const std::string id = CellOfParticipant(p);
      if (id.empty()) continue;
      msg::TrialCommand cmd;
      cmd.cell_id(id);
      cmd.phase(msg::PHASE_CLAIM);
      cmd.service_session(session);
      cmd.lease_s(0);
      transport.Send(cmd);
    }
  }

  int Run() {
    driver->Resume();
    auto last_tick = Clock::now();
    auto next_watch = Clock::now();
    std::optional<Clock::time_point> drain_deadline;
    for (;;) {
      if (stop_requested && !drain_deadline) {
        drain_deadline = After(opt.drain_timeout_s);
        spdlog::info("stopping: no new trials; waiting up to {} s for phases in flight",
                     opt.drain_timeout_s);
      }
      // Wait briefly for any input: a trial's ground truth is stored as it
      // arrives, so its status finds the stream complete.
      input->Wait(std::chrono::milliseconds(1));
      for (auto& a : announces.TakeAll()) driver->OnAnnounce(a);
      for (auto& b : truth_reader.TakeAll()) driver->OnGroundTruth(b);
      for (auto& st : statuses.TakeAll()) driver->OnStatus(st);
      while (auto e = participant.NextPeerEvent(std::chrono::milliseconds(0))) OnPeerEvent(*e);
      for (auto& p : predictor.TakeResults()) driver->OnPrediction(std::move(p));
      if (!stop_requested) {
        const ServiceCounters c = driver->counters();
        adaptive->Advance(driver->IdleCells(), c.done + c.failed);
      }
      driver->Tick(stop_requested || drain_deadline.has_value());

      const auto now = Clock::now();
      if (now >= next_watch) {
        next_watch = now + std::chrono::duration_cast<Clock::duration>(Seconds(opt.watch_period_s));
        watch->Poll();
      }
      if (now - last_tick > std::chrono::milliseconds(100)) {
        last_tick = now;
        if (on_tick) on_tick(driver->counters());
        if (opt.exit_when_done && !driver->InFlight() && driver->CampaignsFinished()) {
          spdlog::info("every campaign is finished");
          break;
        }
      }
      if (drain_deadline) {
        if (!driver->InFlight()) break;
        if (now > *drain_deadline) {
          spdlog::warn("stopping with phases in flight; they are re-run after the next start");
          break;
        }
      }
    }
    ReleaseCells();
    watch->Poll();  // the last events (a campaign done) before the command is drained
    if (notifier && !notifier->Drain(opt.notify_timeout_s + 2))
      spdlog::warn("notify: events still queued at stop (they are in the store's service_events)");
    if (on_tick) on_tick(driver->counters());
    return 0;
  }
};

Service::Service(const ServiceOptions& options) {
  if (options.db_path.empty()) throw std::invalid_argument("--db: must name the store file");
  ValidateServiceOptions(options);
  impl_ = std::make_unique<Impl>(options);
}

Service::~Service() = default;

int Service::Run() { return impl_->Run(); }
void Service::Stop() { impl_->stop_requested = true; }
ServiceCounters Service::counters() const { return impl_->driver->counters(); }
void Service::OnTick(std::function<void(const ServiceCounters&)> callback) {
  impl_->on_tick = std::move(callback);
}
void Service::OnTrialTiming(std::function<void(const TrialTiming&)> callback) {
  impl_->driver->OnTrialTiming(std::move(callback));
}

namespace {
void RequireSeconds(double v, const char* field, double min, double max) {
  if (!std::isfinite(v) || v < min || v > max) {
    throw std::invalid_argument(std::string(field) + ": must be a number of seconds in [" +
                                std::to_string(min) + ", " + std::to_string(max) + "], got " +
                                std::to_string(v));
  }
}
}  // namespace

void ValidateServiceOptions(const ServiceOptions& o) {
  if (o.db_path.empty()) throw std::invalid_argument("--db: must name the store file");
  if (o.domain_id < 0 || o.domain_id > dds::kMaxDomainId)
    throw std::invalid_argument("--domain: must be 0.." + std::to_string(dds::kMaxDomainId) +
                                ", got " + std::to_string(o.domain_id));
  if (o.max_attempts < 1 || o.max_attempts > 1000)
    throw std::invalid_argument("--max-attempts: must be 1..1000, got " +
                                std::to_string(o.max_attempts));
  if (o.quarantine_after < 1 || o.quarantine_after > 1000000)
    throw std::invalid_argument("--quarantine-after: must be >= 1, got " +
                                std::to_string(o.quarantine_after));
  RequireSeconds(o.execute_timeout_s, "--execute-timeout", 0.1, 86400);
  RequireSeconds(o.reset_timeout_s, "--reset-timeout", 0.1, 86400);
  RequireSeconds(o.drain_timeout_s, "--drain", 0, 86400);
  RequireSeconds(o.retry_backoff_s, "retry_backoff_s", 0, 86400);
  RequireSeconds(o.stream_grace_s, "stream_grace_s", 0, 3600);
  RequireSeconds(o.integrity_check_period_s, "--integrity-check-period", 0.1, 7 * 86400);
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int max_predictors = std::max(64, 4 * cores);
  if (o.predictor_threads < 1 || o.predictor_threads > max_predictors)
    throw std::invalid_argument("--predictors: must be 1.." + std::to_string(max_predictors) +
                                " threads, got " + std::to_string(o.predictor_threads));
  if (o.predictor_nice < 0 || o.predictor_nice > 19)
    throw std::invalid_argument("predictor_nice: must be 0..19, got " +
                                std::to_string(o.predictor_nice));
  if (o.prediction_backlog < 1 || o.prediction_backlog > 100000)
    throw std::invalid_argument("prediction_backlog: must be 1..100000 trials, got " +
                                std::to_string(o.prediction_backlog));
  if (o.store_max_pages < 0) throw std::invalid_argument("--store-max-pages: must be >= 0");
  RequireSeconds(o.cell_backoff_s, "cell_backoff_s", 0, 3600);
  RequireSeconds(o.cell_backoff_max_s, "--cell-backoff-max", 0, 3600);
  RequireSeconds(o.notify_timeout_s, "--notify-timeout", 0.01, 3600);
  RequireSeconds(o.watch_period_s, "watch_period_s", 0.01, 3600);
  if (o.notify_queue < 1 || o.notify_queue > 100000)
    throw std::invalid_argument("--notify-queue: must be 1..100000 events, got " +
                                std::to_string(o.notify_queue));
  if (!std::isfinite(o.notify_failure_rate) || o.notify_failure_rate < 0 ||
      o.notify_failure_rate > 1)
    throw std::invalid_argument("--notify-failure-rate: must be a fraction in [0, 1], got " +
                                std::to_string(o.notify_failure_rate));
}

}  // namespace arena::orchestrator
