// The TrialDriver alone: a fake clock, a fake command transport with a fake
// cell answering it, a fake store that keeps the trial state machine (and
// refuses illegal edges like the real one) and can fail any step with any
// store error. No DDS, no SQLite, no threads, no sleeping.
#include "arena/orchestrator/trial_driver.hpp"

#include <deque>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/db/outcomes.hpp"
#include "arena/db/retry_rule.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/trial_data.hpp"
#include "arena/schemas/ground_truth.hpp"

namespace arena::orchestrator {
namespace {

using K = db::StoreError::Kind;
using Clock = DriverClock;

std::string Scene() {
  return R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2,
              "pose": {"position": [0, 0, 0], "rpy": [0, 0, 0]}},
  "gravity": [0, 0, -9.81], "duration": 0.1, "grip_force": 10.0,
  "fingers": [
    {"name": "left",  "type": "point", "position": [-0.025, 0, 0], "normal": [1, 0, 0], "mu": 0.5},
    {"name": "right", "type": "point", "position": [0.025, 0, 0], "normal": [-1, 0, 0], "mu": 0.5}],
  "model": {"facets": 8, "points": 3, "dt": 0.004, "reduce": "auto"}})";
}

// Injected failures: step name -> kinds thrown by its next calls, in order.
struct Faults {
  std::map<std::string, std::deque<K>> next;
  std::map<std::string, int> calls;
  void Hit(const std::string& step) {
    ++calls[step];
    auto it = next.find(step);
    if (it == next.end() || it->second.empty()) return;
    const K kind = it->second.front();
    it->second.pop_front();
    throw db::StoreError(kind, step + ": injected");
  }
};

struct FakeSink : GroundTruthSink {
  Faults& faults;
  std::function<void(std::int64_t)> finish;
  std::int64_t n = 0;
  FakeSink(Faults& f, std::function<void(std::int64_t)> fin) : faults(f), finish(std::move(fin)) {}
  void Add(const std::vector<db::Sample>& s) override {
    faults.Hit("Ingest.Add");
    n += static_cast<std::int64_t>(s.size());
  }
  void Poll() override {}
  std::int64_t Finish() override {
    faults.Hit("Ingest.Finish");
    finish(n);
    return n;
  }
};

struct FakeStore : TrialStore {
  struct T {
    db::TrialState state = db::TrialState::kPlanned;
    int attempt = 1;
    std::int64_t samples = -1;
    db::TrialEnd outcome = db::TrialEnd::kNone;
    int service_restarts = 0;
    std::vector<std::string> rules;  // the audit rows' rules, in order
    int predictions = 0;             // RecordPrediction calls that stored one
  };
  Faults faults;
  std::map<std::int64_t, T> trials;
  std::map<std::string, std::string> serving;
  std::set<std::string> gone, quarantined;
  int beats = 0;
  bool file_gone = false;

  void Move(std::int64_t id, int attempt, db::TrialState to) {
    T& t = trials.at(id);
    if (t.attempt != attempt) throw db::StoreError(K::kStaleAttempt, "stale");
    if (!db::IsLegalTransition(t.state, to))
      throw db::StoreError(K::kIllegalTransition, std::string("illegal ") + db::ToString(t.state) +
                                                      " -> " + db::ToString(to));
    t.state = to;
  }
  db::RecoveryReport RecoverAfterRestart() override {
    faults.Hit("RecoverAfterRestart");
    db::RecoveryReport r;
    for (auto& [id, t] : trials) {
      if (t.state == db::TrialState::kDispatched) {
        t.state = db::TrialState::kPlanned;
        ++t.attempt;
        ++t.service_restarts;
        r.requeued.push_back(id);
      } else if (t.state == db::TrialState::kResetting) {
        t.state = db::TrialState::kResetFailed;
        r.reset_failed.push_back(id);
      }
    }
    return r;
  }
  std::vector<db::Trial> ListTrialsByState(const std::vector<db::TrialState>& states) override {
    faults.Hit("ListTrialsByState");
    std::vector<db::Trial> out;
    for (auto& [id, t] : trials)
      if (std::find(states.begin(), states.end(), t.state) != states.end()) out.push_back(Get(id));
    return out;
  }
  db::Trial Get(std::int64_t id) {
    db::Trial r;
    r.id = id;
    r.campaign_id = 1;
    r.state = trials.at(id).state;
    r.attempt = trials.at(id).attempt;
    r.scene_json = Scene();
    return r;
  }
  db::Trial GetTrial(std::int64_t id) override {
    faults.Hit("GetTrial");
    return Get(id);
  }
  std::optional<db::ClaimedTrial> Next() {
    for (auto& [id, t] : trials)
      if (t.state == db::TrialState::kPlanned)
        return db::ClaimedTrial{id, 1, t.attempt, 7, Scene(), "{}"};
    return std::nullopt;
  }
  std::optional<db::ClaimedTrial> ClaimNextTrial(const std::string&) override {
    faults.Hit("ClaimNextTrial");
    auto c = Next();
    if (c) Move(c->trial_id, c->attempt, db::TrialState::kDispatched);
    return c;
  }
  std::optional<db::ClaimedTrial> PeekNextTrial(const std::string&) override {
    faults.Hit("PeekNextTrial");
    return Next();
  }
  std::unique_ptr<GroundTruthSink> BeginIngest(std::int64_t id, int attempt,
                                               std::vector<db::ContactSite>) override {
    faults.Hit("BeginIngest");
    if (trials.at(id).attempt != attempt) throw db::StoreError(K::kStaleAttempt, "stale");
    return std::make_unique<FakeSink>(faults, [this, id, attempt](std::int64_t n) {
      Move(id, attempt, db::TrialState::kExecuted);
      trials.at(id).samples = n;
    });
  }
  // The same retry rule as the real store (db::DecideRetry), not a copy of it.
  db::TrialState RetryTrial(std::int64_t id, int attempt, const std::string&, int max_attempts,
                            double, const std::string& rule) override {
    faults.Hit("RetryTrial");
    T& t = trials.at(id);
    if (t.attempt != attempt) throw db::StoreError(K::kStaleAttempt, "stale");
    const db::RetryVerdict verdict = db::DecideRetry(attempt, t.service_restarts, max_attempts);
    if (verdict.give_up) {
      Move(id, attempt, db::TrialState::kFailed);
      t.outcome = db::TrialEnd::kFailed;
    } else {
      Move(id, attempt, db::TrialState::kPlanned);
      ++t.attempt;
    }
    t.rules.push_back(rule + " " + verdict.rule);
    return t.state;
  }
  // As the real store: not counted, no backoff.
  void ReleaseTrial(std::int64_t id, int attempt, const std::string&,
                    const std::string& rule) override {
    faults.Hit("ReleaseTrial");
    Move(id, attempt, db::TrialState::kPlanned);
    T& t = trials.at(id);
    ++t.attempt;
    ++t.service_restarts;
    t.rules.push_back(rule);
  }
  // The queued trial's claim (the aimed trial, while still planned).
  std::optional<db::ClaimedTrial> ClaimTrial(const std::string&, std::int64_t id,
                                             const std::string& rule) override {
    faults.Hit("ClaimTrial");
    auto it = trials.find(id);
    if (it == trials.end() || it->second.state != db::TrialState::kPlanned) return std::nullopt;
    Move(id, it->second.attempt, db::TrialState::kDispatched);
    claim_rules.push_back(rule);
    return db::ClaimedTrial{id, 1, it->second.attempt, 7, Scene(), "{}"};
  }
  std::vector<std::string> claim_rules;
  void FailTrial(std::int64_t id, int attempt, const std::string&, db::TrialEnd outcome,
                 const std::string& rule) override {
    faults.Hit("FailTrial");
    Move(id, attempt, db::TrialState::kFailed);
    trials.at(id).outcome = outcome;
    trials.at(id).rules.push_back(rule);
  }
  void BeginReset(std::int64_t id, int attempt, const std::string& rule) override {
    faults.Hit("BeginReset");
    Move(id, attempt, db::TrialState::kResetting);
    trials.at(id).rules.push_back(rule);
  }
  // As the real store's one transaction: each part's fault comes before any change.
  std::int64_t PublishExecuted(GroundTruthSink& sink, std::int64_t id, int attempt,
                               const db::FinishAlso& also) override {
    if (also.execution) faults.Hit("RecordExecution");
    if (!also.begin_reset_rule.empty()) faults.Hit("BeginReset");
    const std::int64_t n = sink.Finish();
    if (also.execution) ++executions_published;
    if (!also.begin_reset_rule.empty()) {
      Move(id, attempt, db::TrialState::kResetting);
      trials.at(id).rules.push_back(also.begin_reset_rule);
    }
    return n;
  }
  void CompleteReset(std::int64_t id, int attempt, const db::ResetReport& r,
                     const std::string& rule) override {
    faults.Hit("CompleteReset");
    Move(id, attempt, r.ok ? db::TrialState::kResetDone : db::TrialState::kResetFailed);
    trials.at(id).rules.push_back(rule);
  }
  void RecordPrediction(std::int64_t id, int attempt, const db::Prediction&) override {
    faults.Hit("RecordPrediction");
    if (trials.at(id).state != db::TrialState::kPredicted)
      Move(id, attempt, db::TrialState::kPredicted);
    ++trials.at(id).predictions;
  }
  void FinishTrial(std::int64_t id, int attempt) override {
    faults.Hit("FinishTrial");
    Move(id, attempt, db::TrialState::kDone);
  }
  void RecordExecution(std::int64_t, int, const std::string& backend, const std::string&,
                       const std::string&) override {
    faults.Hit("RecordExecution");
    last_backend = backend;
    ++executions_alone;
  }
  std::string last_backend;
  int executions_alone = 0;      // records written in a commit of their own
  int executions_published = 0;  // records that joined the publish (PublishExecuted)
  void RecordClosedLoop(const db::ClosedLoopRun& run) override {
    faults.Hit("RecordClosedLoop");
    closed_loops.push_back(run);
  }
  std::vector<db::ClosedLoopRun> closed_loops;
  void UpsertCell(const std::string& id, const std::vector<std::string>&, const std::string&,
                  const std::string&) override {
    faults.Hit("UpsertCell");
    gone.erase(id);
  }
  bool CellQuarantined(const std::string& id) override {
    faults.Hit("CellQuarantined");
    return quarantined.count(id) > 0;
  }
  int failures = 0;
  int RecordCellResult(const std::string&, bool ok) override {
    faults.Hit("RecordCellResult");
    failures = ok ? 0 : failures + 1;
    return failures;
  }
  void QuarantineCell(const std::string& id, const std::string&) override {
    faults.Hit("QuarantineCell");
    quarantined.insert(id);
  }
  void MarkCellGone(const std::string& id, const std::string&) override {
    faults.Hit("MarkCellGone");
    gone.insert(id);
  }
  void SetCellServing(const std::string& id, double, const std::string& s) override {
    faults.Hit("SetCellServing");
    serving[id] = s;
  }
  bool CompleteFinishedCampaigns(std::int64_t) override {
    faults.Hit("CompleteFinishedCampaigns");
    for (auto& [id, t] : trials)
      if (!db::IsTerminal(t.state)) return false;
    return true;
  }
  void ServiceBeat(const std::vector<std::string>&) override {
    faults.Hit("ServiceBeat");
    ++beats;
  }
  void CheckFileIdentity() override {
    if (file_gone) throw db::StoreError(K::kIo, "the store 'x.db' was deleted or renamed");
  }
};

struct FakeTransport : CommandTransport {
  std::vector<msg::TrialCommand> sent;
  std::function<void(const msg::TrialCommand&)> on_send;  // sees the store as at the send
  bool Send(msg::TrialCommand& c) override {
    sent.push_back(c);
    if (on_send) on_send(c);
    return true;
  }
};

struct FakePredictions : PredictionPort {
  std::deque<PredictionRequest> requests;
  std::size_t last_commands = 0;  // closed loop: commands the last request replays
  void Start(PredictionRequest r) override {
    last_commands = r.commands.size();
    requests.push_back(std::move(r));
  }
  int outstanding() const override { return static_cast<int>(requests.size()); }
};

// The driver logs every step; the tests read the fakes instead.
[[maybe_unused]] const bool kQuiet = [] {
  spdlog::set_level(spdlog::level::off);
  return true;
}();

constexpr std::uint64_t kSession = 0xabcdef;
constexpr std::uint64_t kOther = 0x123456;

// The driver with fakes around it, and a fake cell that answers commands.
struct Harness {
  FakeStore store;
  FakeTransport transport;
  FakePredictions predictions;
  Clock::time_point t = Clock::time_point{} + std::chrono::hours(1);
  std::unique_ptr<TrialDriver> driver;
  std::size_t answered = 0;  // commands the fake cell has handled
  int samples = 10;
  msg::TrialState execute_answer = msg::STATE_EXECUTED;
  msg::FailureKind execute_failure = msg::FAILURE_NONE;
  std::string execute_detail = "{}";  // the EXECUTE status's detail_json
  bool status_before_truth = false;   // the EXECUTED status overtakes the stream's batch
  int batches_lost = 0;               // this many EXECUTEs' batches never arrive

  bool predictor_holds = false;  // the predictor answers nothing (a slow or stopped one)
  bool queue_next = false;       // DriverOptions::queue_next_execute
  msg::TrialState reset_answer = msg::STATE_RESET_DONE;
  // The fake cell's ResetGate (executors): the last RESET it answered, and how.
  std::uint64_t last_reset_trial = 0;
  std::uint32_t last_reset_attempt = 0;
  bool last_was_reset = false, last_reset_done = false;

  explicit Harness(int trials = 1, int prediction_backlog = 64) {
    for (int i = 1; i <= trials; ++i) store.trials[i] = {};
    backlog = prediction_backlog;
    NewDriver();
  }
  int backlog = 64;
  // A new driver on the same store (a restarted service): what the old one
  // held in memory (its predictor's requests) is lost.
  void NewDriver() {
    driver.reset();
    predictions.requests.clear();
    DriverOptions o;
    o.service.max_attempts = 3;
    o.service.prediction_backlog = backlog;
    o.queue_next_execute = queue_next;
    driver = std::make_unique<TrialDriver>(o, ServiceIdentity{kSession, "lab1", 42, "store-a"},
                                           store, transport, predictions, [this] { return t; });
  }

  msg::CellAnnounce Announce(const std::string& id, std::uint64_t serving,
                             std::uint64_t incarnation = 1) {
    msg::CellAnnounce a;
    a.cell_id(id);
    a.contact_types({"point"});
    a.speed(0);
    a.defects_json("{}");
    a.started_unix_ns(incarnation);
    a.serving_session(serving);
    a.serving_host(serving == kSession ? "lab1" : "lab2");
    a.serving_pid(serving == kSession ? 42 : 77);
    return a;
  }

  msg::TrialStatus Status(const msg::TrialCommand& c, msg::TrialState state,
                          std::uint64_t session = kSession) {
    msg::TrialStatus s;
    s.trial_id(c.trial_id());
    s.attempt(c.attempt());
    s.cell_id(c.cell_id());
    s.phase(c.phase());
    s.state(state);
    s.service_session(session);
    s.samples(static_cast<std::uint32_t>(samples));
    s.phase_wall_s(0.01);
    s.observed_pose({0, 0, 0, 1, 0, 0, 0});
    return s;
  }

  msg::GroundTruth Batch(const msg::TrialCommand& c, std::uint64_t session = kSession) {
    msg::GroundTruth b;
    b.trial_id(c.trial_id());
    b.attempt(c.attempt());
    b.cell_id(c.cell_id());
    b.service_session(session);
    b.batch(0);
    b.first_sample(0);
    b.last(true);
    for (int i = 0; i < samples; ++i) {
      mechanics::TrajectorySample truth;
      truth.t = i * 0.004;
      truth.contacts.resize(2);
      dds::Observation obs;
      obs.valid = true;
      obs.t = truth.t;
      obs.finger_wrenches.resize(2, dds::Wrench::Zero());
      msg::GroundTruthSample s;
      dds::EncodeSample(truth, dds::PusherState{}, obs, &s);
      b.samples().push_back(s);
    }
    return b;
  }

  // The fake cell answers every command it has not answered yet; the
  // predictor answers every request.
  void Answer() {
    for (; answered < transport.sent.size(); ++answered) {
      const msg::TrialCommand c = transport.sent[answered];
      if (c.phase() == msg::PHASE_EXECUTE && c.after_reset_trial_id() != 0 &&
          !(last_was_reset && last_reset_done && last_reset_trial == c.after_reset_trial_id() &&
            last_reset_attempt == c.after_reset_attempt())) {
        last_was_reset = false;
        driver->OnStatus(Status(c, msg::STATE_REFUSED));  // as executors' ResetGate
      } else if (c.phase() == msg::PHASE_EXECUTE) {
        last_was_reset = false;
        driver->OnStatus(Status(c, msg::STATE_ACCEPTED));
        const bool batch = execute_answer == msg::STATE_EXECUTED && batches_lost-- <= 0;
        if (batch && !status_before_truth) driver->OnGroundTruth(Batch(c));
        auto st = Status(c, execute_answer);
        st.failure(execute_failure);
        st.detail_json(execute_detail);
        driver->OnStatus(st);
        if (batch && status_before_truth) driver->OnGroundTruth(Batch(c));
      } else if (c.phase() == msg::PHASE_RESET) {
        last_was_reset = true;
        last_reset_done = reset_answer == msg::STATE_RESET_DONE;
        last_reset_trial = c.trial_id();
        last_reset_attempt = c.attempt();
        auto st = Status(c, reset_answer);
        if (reset_answer == msg::STATE_FAILED) st.failure(msg::FAILURE_RESET);
        driver->OnStatus(st);
      }
    }
    while (!predictor_holds && !predictions.requests.empty()) {
      const PredictionRequest r = predictions.requests.front();
      predictions.requests.pop_front();
      db::Prediction p;
      p.model_key = "g8";
      driver->OnPrediction(PredictionDone{r.trial_id, r.attempt, r.campaign_id, p});
    }
  }

  // Ticks (100 ms apart) until every trial is terminal, or `limit` ticks.
  bool RunToEnd(int limit = 400) {
    for (int i = 0; i < limit; ++i) {
      t += std::chrono::milliseconds(100);
      driver->Tick(false);
      Answer();
      bool all = true;
      for (auto& [id, tr] : store.trials) all = all && db::IsTerminal(tr.state);
      if (all && !driver->InFlight()) return true;
    }
    return false;
  }

  void Start(std::uint64_t serving = kSession) {
    driver->Resume();
    driver->OnAnnounce(Announce("c1", serving));
  }

  int Sent(msg::Phase phase) const {
    int n = 0;
    for (const auto& c : transport.sent) n += c.phase() == phase;
    return n;
  }
};

// Trials 1 and 2 done on their first attempt, each predicted once, with the
// audit of a clean execute and a verified reset.
void ExpectTrialsOneAndTwoDoneFirstTime(Harness& h) {
  for (const std::int64_t id : {1, 2}) {
    EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone);
    EXPECT_EQ(h.store.trials[id].attempt, 1);
    EXPECT_EQ(h.store.trials[id].predictions, 1);
    EXPECT_EQ(h.store.trials[id].rules,
              (std::vector<std::string>{kResetAfterExecute, "reset.verified"}));
  }
}

TEST(TrialDriver, OneTrialGoesThroughEveryStepToDone) {
  Harness h;
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 1);
  EXPECT_EQ(h.store.trials[1].samples, 10);
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  EXPECT_EQ(h.Sent(msg::PHASE_RESET), 1);
  EXPECT_GE(h.Sent(msg::PHASE_CLAIM), 1);
  for (const auto& c : h.transport.sent) EXPECT_EQ(c.service_session(), kSession);
  EXPECT_EQ(h.driver->counters().done, 1);
  EXPECT_GE(h.store.beats, 1);
  EXPECT_GE(h.store.faults.calls["CompleteFinishedCampaigns"], 1);
}

// Closed loop (issue 19): the cell's record of the commands it applied is
// stored with the attempt (the same step again after a busy store) and its
// commands go to the prediction, which replays them.
TEST(TrialDriver, AClosedLoopTrialStoresItsCommandsAndPredictsByReplayingThem) {
  Harness h;
  h.execute_detail = R"({"closed_loop": {"controller": "pivot_to_angle", "lockstep": true,
      "context": {"target": 0.2, "gain": 1.0, "tolerance": 0.01, "hold_s": 0.5},
      "commands": [[0, 0.0, 0.01, 0, 0, 0.01, 0, 0, 0.4], [1, 0.004, 0.02, 0, 0, 0.02, 0, 0, 0.5]],
      "held": 0, "loop_ms": {"p50": 0.4, "p99": 0.5},
      "outcome": {"reached": false, "final_error": 0.1, "settle_time_s": null}}})";
  h.store.faults.next["RecordClosedLoop"] = {K::kBusy};
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.predictions.last_commands, 2u);
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.faults.calls["RecordClosedLoop"], 2);
  ASSERT_EQ(h.store.closed_loops.size(), 1u);
  EXPECT_EQ(h.store.closed_loops[0].controller, "pivot_to_angle");
  EXPECT_EQ(h.store.closed_loops[0].commands.size(), 2u);
  EXPECT_EQ(h.store.closed_loops[0].trial_id, 1);
}

TEST(TrialDriver, ACellServingAnotherServiceGetsNoTrialAndIsNamedInTheStore) {
  Harness h;
  h.Start(kOther);
  EXPECT_FALSE(h.RunToEnd(30));
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 0);
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kPlanned);
  EXPECT_EQ(h.store.serving["c1"], "serving service 0000000000123456 on host lab2 (pid 77)");
  EXPECT_GE(h.Sent(msg::PHASE_CLAIM), 1);  // it keeps asking: the other lease may run out
  // The cell frees up and serves us: the trial runs.
  h.driver->OnAnnounce(h.Announce("c1", kSession));
  EXPECT_EQ(h.store.serving["c1"], "");
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
}

TEST(TrialDriver, StatusesAndGroundTruthOfAnotherSessionAreDropped) {
  Harness h;
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);
  ASSERT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  msg::TrialCommand execute;
  for (const auto& c : h.transport.sent)
    if (c.phase() == msg::PHASE_EXECUTE) execute = c;
  // Another service's cell answers a trial with the same id and attempt.
  h.driver->OnGroundTruth(h.Batch(execute, kOther));
  h.driver->OnStatus(h.Status(execute, msg::STATE_EXECUTED, kOther));
  h.driver->OnStatus(h.Status(execute, msg::STATE_FAILED, kOther));
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDispatched);
  EXPECT_EQ(h.store.trials[1].attempt, 1);
  EXPECT_EQ(h.store.trials[1].samples, -1);
  h.answered = 0;  // now our own answers
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 1);
}

// Issue 27: a clean reset is written after the cell's next EXECUTE is sent
// (Tick's background), not between the cell's RESET_DONE and that EXECUTE;
// the reset's record and the prediction waiting for it are the same.
TEST(TrialDriver, AfterACleanResetTheNextExecuteGoesOutBeforeTheResetIsWritten) {
  Harness h(2);
  std::vector<db::TrialState> first_at_execute;  // trial 1's state at each EXECUTE
  std::vector<int> ingests_at_execute;           // BeginIngest calls before each EXECUTE
  h.transport.on_send = [&](const msg::TrialCommand& c) {
    if (c.phase() != msg::PHASE_EXECUTE) return;
    first_at_execute.push_back(h.store.trials[1].state);
    ingests_at_execute.push_back(h.store.faults.calls["BeginIngest"]);
  };
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  ASSERT_EQ(first_at_execute.size(), 2u);
  EXPECT_EQ(first_at_execute[1], db::TrialState::kResetting);
  EXPECT_EQ(ingests_at_execute, (std::vector<int>{0, 1}));  // the EXECUTE before its ingest
  ExpectTrialsOneAndTwoDoneFirstTime(h);
}

// Issue 27: the predictor yields to the trials' path (predictor_yield.hpp),
// which the driver marks: a cell is on it from the status that ended its
// phase until it is handed its next phase (or left idle), never left on it,
// and each command goes out with the cell off it (its hop is the grace's).
TEST(TrialDriver, ACellIsOnThePathFromEachPhasesEndUntilItsNextPhaseIsHanded) {
  Harness h(2);
  std::vector<std::string> events;  // "on", "off", "EXECUTE", "RESET", in order
  bool on_path = false;
  h.driver->OnPathChange([&](const std::string& cell, bool on) {
    EXPECT_EQ(cell, "c1");
    events.push_back(on ? "on" : "off");
    on_path = on;
  });
  h.transport.on_send = [&](const msg::TrialCommand& c) {
    if (c.phase() == msg::PHASE_EXECUTE) {
      events.push_back("EXECUTE");
      EXPECT_FALSE(on_path) << "an EXECUTE sent with its cell still on the path";
    }
    if (c.phase() == msg::PHASE_RESET) events.push_back("RESET");
  };
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  ExpectTrialsOneAndTwoDoneFirstTime(h);
  EXPECT_FALSE(on_path);
  // Each trial: the EXECUTED status puts the cell on the path, its RESET goes
  // out (ahead of the publish) and the publish's end hands it the reset; the
  // RESET_DONE puts it on again until its next EXECUTE or its idling.
  std::vector<std::string> compact;  // repeated "off"s folded
  for (const auto& e : events)
    if (compact.empty() || e != "off" || compact.back() != "off") compact.push_back(e);
  EXPECT_EQ(compact, (std::vector<std::string>{"off", "EXECUTE", "on", "RESET", "off", "on", "off",
                                               "EXECUTE", "on", "RESET", "off", "on", "off"}));
}

// Issue 27: a cell freed since the service's previous dispatch pass is busy
// from its freeing, not from the claim: the loop's work before the claim
// kept it waiting, and the overhead figure (TrialTiming) counts that too; a
// cell that waits for a pass for nothing of the service's (no trial yet)
// does not.
TEST(TrialDriver, ACellsWaitForTheNextDispatchPassCountsInItsNextTrialsBusyTime) {
  Harness h(2);
  std::map<std::int64_t, double> busy;
  h.driver->OnTrialTiming([&](const TrialTiming& t) { busy[t.trial_id] = t.cell_busy_s; });
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);  // claims trial 1
  ASSERT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  h.t += std::chrono::milliseconds(1);
  h.Answer();  // trial 1 runs and resets: the cell is free at +1 ms
  ASSERT_EQ(busy.count(1), 1u);
  h.t += std::chrono::milliseconds(5);
  h.driver->Tick(false);  // the next pass, 5 ms later, claims trial 2
  ASSERT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
  h.t += std::chrono::milliseconds(2);
  h.Answer();
  ASSERT_EQ(busy.count(2), 1u);
  EXPECT_NEAR(busy[2], 0.007, 1e-9);  // from the freeing, not 0.002 from the claim
  EXPECT_NEAR(busy[1], 0.001, 1e-9);  // a first claim counts from the claim
}

// Issue 27: the overhead figure in the four legs of the trial's path, each
// the interval it names, adding up to the overhead: claim -> EXECUTE sent,
// the EXECUTE's round trip beyond the cell's execute, stream complete ->
// RESET sent, the RESET's round trip beyond the cell's reset.
TEST(TrialDriver, TheOverheadIsTheSumOfTheFourLegsOfTheTrialsPath) {
  Harness h;
  std::optional<TrialTiming> timing;
  h.driver->OnTrialTiming([&](const TrialTiming& t) { timing = t; });
  // Sending a command takes the service 1 ms (EXECUTE) and 3 ms (RESET).
  h.transport.on_send = [&](const msg::TrialCommand& c) {
    if (c.phase() == msg::PHASE_EXECUTE) h.t += std::chrono::milliseconds(1);
    if (c.phase() == msg::PHASE_RESET) h.t += std::chrono::milliseconds(3);
  };
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);  // the claim at T, its EXECUTE sent at T + 1 ms
  msg::TrialCommand execute;
  for (const auto& c : h.transport.sent)
    if (c.phase() == msg::PHASE_EXECUTE) execute = c;
  h.t += std::chrono::milliseconds(20);  // the stream complete at T + 21 ms
  h.driver->OnGroundTruth(h.Batch(execute));
  auto executed = h.Status(execute, msg::STATE_EXECUTED);
  executed.phase_wall_s(0.012);  // of the 20 ms, the cell executed 12
  h.driver->OnStatus(executed);  // its RESET sent at T + 24 ms
  msg::TrialCommand reset;
  for (const auto& c : h.transport.sent)
    if (c.phase() == msg::PHASE_RESET) reset = c;
  ASSERT_EQ(reset.phase(), msg::PHASE_RESET);
  h.t += std::chrono::milliseconds(9);  // RESET_DONE taken at T + 33 ms
  auto done = h.Status(reset, msg::STATE_RESET_DONE);
  done.phase_wall_s(0.005);  // of the 9 ms, the cell reset 5
  h.driver->OnStatus(done);
  ASSERT_TRUE(timing);
  EXPECT_NEAR(timing->cell_busy_s, 0.033, 1e-9);
  EXPECT_NEAR(timing->overhead_s, 0.033 - 0.012 - 0.005, 1e-9);
  EXPECT_NEAR(timing->claim_to_execute_s, 0.001, 1e-9);
  EXPECT_NEAR(timing->execute_round_trip_s, 0.020 - 0.012, 1e-9);
  EXPECT_NEAR(timing->stream_to_reset_s, 0.003, 1e-9);
  EXPECT_NEAR(timing->reset_round_trip_s, 0.009 - 0.005, 1e-9);
  EXPECT_NEAR(timing->claim_to_execute_s + timing->execute_round_trip_s +
                  timing->stream_to_reset_s + timing->reset_round_trip_s,
              timing->overhead_s, 1e-12);
}

// Issue 27: what ran a trial (the EXECUTED status's detail) is stored in the
// publish's transaction, also when the status overtakes the stream's last
// batch: no commit of its own between the cell's status and its RESET.
TEST(TrialDriver, TheExecutionRecordJoinsThePublishWhenTheStatusOvertakesTheStream) {
  for (const bool overtakes : {false, true}) {
    SCOPED_TRACE(overtakes ? "status first" : "stream first");
    Harness h(2);
    h.execute_detail = R"({"backend": "model", "truth": "simulated", "defects_applied": {}})";
    h.status_before_truth = overtakes;
    h.Start();
    ASSERT_TRUE(h.RunToEnd());
    EXPECT_EQ(h.store.executions_published, 2);
    EXPECT_EQ(h.store.executions_alone, 0);
    for (const std::int64_t id : {1, 2}) {
      EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone);
      EXPECT_EQ(h.store.trials[id].attempt, 1);
    }
  }
}

// An attempt whose stream never completes is not published, and its record
// (what ran it) is written when its phase ends: nothing the cell said is lost.
TEST(TrialDriver, AnUnpublishedAttemptStillRecordsWhatRanIt) {
  Harness h;
  h.execute_detail = R"({"backend": "model", "truth": "simulated", "defects_applied": {}})";
  h.status_before_truth = true;
  h.batches_lost = 1;  // the first attempt's stream never comes: its grace runs out
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 2);
  EXPECT_EQ(h.store.executions_alone, 1);      // attempt 1's, when its phase ended
  EXPECT_EQ(h.store.executions_published, 1);  // attempt 2's, with its stream
  EXPECT_EQ(h.store.last_backend, "model");
}

// Issue 27: while an input waits (the service's doorbell rang), Tick runs one
// of the writes no cell waits on and leaves the rest for the next Tick, so a
// cell's status is answered first; every write still runs.
TEST(TrialDriver, WritesNoCellWaitsOnYieldOneAtATimeToAWaitingInput) {
  for (const bool waiting : {false, true}) {
    SCOPED_TRACE(waiting ? "an input waits" : "nothing waits");
    Harness h(2);
    h.driver->OnInputWaiting([waiting] { return waiting; });
    h.Start();
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);  // trial 1's EXECUTE
    h.Answer();             // its stream, its RESET, the cell's RESET_DONE
    ASSERT_EQ(h.Sent(msg::PHASE_RESET), 1);
    // Queued: trial 1's prediction, its reset's record, the cell's good result.
    auto& calls = h.store.faults.calls;
    const int results = calls["RecordCellResult"];  // the cell's first execute, written at once
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);  // trial 2's EXECUTE, then the queued writes
    ASSERT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
    EXPECT_EQ(h.predictions.requests.size(), 1u);
    EXPECT_EQ(calls["CompleteReset"], waiting ? 0 : 1);
    EXPECT_EQ(calls["RecordCellResult"], results + (waiting ? 0 : 1));
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
    EXPECT_EQ(calls["CompleteReset"], 1);
    EXPECT_EQ(calls["RecordCellResult"], results + (waiting ? 0 : 1));
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
    EXPECT_EQ(calls["RecordCellResult"], results + 1);
    ASSERT_TRUE(h.RunToEnd());
    for (const std::int64_t id : {1, 2}) EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone);
  }
}

// Issue 27: the cell's RESET goes out before the stream's publish commits
// (the cell resets while the commit runs), aimed at the cell's next trial as
// before; the store's records are those of the old order.
TEST(TrialDriver, TheResetGoesOutBeforeThePublishCommitsAimedAtTheNextTrial) {
  Harness h(2);
  std::vector<db::TrialState> at_reset;  // the reset trial's state when its RESET is sent
  std::vector<std::string> aims;         // the scene each RESET aims at
  h.transport.on_send = [&](const msg::TrialCommand& c) {
    if (c.phase() != msg::PHASE_RESET) return;
    at_reset.push_back(h.store.trials[static_cast<std::int64_t>(c.trial_id())].state);
    aims.push_back(c.scene_json());
  };
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(at_reset, (std::vector<db::TrialState>{db::TrialState::kDispatched,
                                                   db::TrialState::kDispatched}));
  EXPECT_EQ(aims, (std::vector<std::string>{Scene(), ""}));  // trial 2's start, then none left
  ExpectTrialsOneAndTwoDoneFirstTime(h);
  EXPECT_EQ(h.Sent(msg::PHASE_RESET), 2);
}

// The first EXECUTE's command, and the fake cell's answer to it (its stream
// and EXECUTED), by hand: the test then decides when the reset is answered.
msg::TrialCommand ExecuteAndAnswer(Harness& h) {
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);
  msg::TrialCommand execute;
  for (const auto& c : h.transport.sent)
    if (c.phase() == msg::PHASE_EXECUTE) execute = c;
  h.driver->OnGroundTruth(h.Batch(execute));
  h.driver->OnStatus(h.Status(execute, msg::STATE_EXECUTED));
  h.answered = h.transport.sent.size();
  return execute;
}
msg::TrialCommand LastReset(const Harness& h) {
  msg::TrialCommand reset;
  for (const auto& c : h.transport.sent)
    if (c.phase() == msg::PHASE_RESET) reset = c;
  return reset;
}

// ---- Issue 27: the next trial queued behind the cell's reset
// (The driver's clock points into its Harness: set up in place, never moved.)
void QueueNext(Harness& h) {
  h.queue_next = true;
  h.NewDriver();
}
std::vector<msg::TrialCommand> Executes(const Harness& h) {
  std::vector<msg::TrialCommand> out;
  for (const auto& c : h.transport.sent)
    if (c.phase() == msg::PHASE_EXECUTE) out.push_back(c);
  return out;
}

// Each trial after the first goes out right behind its cell's RESET, marked
// to run only after that reset ended done; the cell's reset status lets it
// run, and every trial is done on its first attempt, as without queuing.
TEST(TrialDriver, TheNextTrialGoesOutBehindTheResetAndRunsWhenItEndedDone) {
  Harness h(3);
  QueueNext(h);
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  for (const std::int64_t id : {1, 2, 3}) {
    EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone) << id;
    EXPECT_EQ(h.store.trials[id].attempt, 1) << id;
    EXPECT_EQ(h.store.trials[id].samples, 10) << id;
  }
  const auto executes = Executes(h);
  ASSERT_EQ(executes.size(), 3u);
  EXPECT_EQ(executes[0].after_reset_trial_id(), 0u) << "the first trial follows no reset";
  for (std::size_t k = 1; k < 3; ++k) {
    EXPECT_EQ(executes[k].after_reset_trial_id(), executes[k - 1].trial_id());
    EXPECT_EQ(executes[k].after_reset_attempt(), executes[k - 1].attempt());
  }
  // Sent right behind the RESET it waits for.
  for (std::size_t k = 0; k + 1 < h.transport.sent.size(); ++k) {
    if (h.transport.sent[k].phase() == msg::PHASE_RESET && h.transport.sent[k].trial_id() < 3) {
      EXPECT_EQ(h.transport.sent[k + 1].phase(), msg::PHASE_EXECUTE) << k;
    }
  }
  EXPECT_EQ(h.store.claim_rules, (std::vector<std::string>{kQueuedClaimRule, kQueuedClaimRule}));
  EXPECT_EQ(h.driver->counters().dispatched, 3);
  EXPECT_EQ(h.driver->counters().retried, 0);
}

// A reset that fails: the cell refuses the trial queued behind it (a robot
// never pushes from a failed reset). The service released it already, not
// counted and nobody blamed: it runs again as attempt 2 and is done.
TEST(TrialDriver, ATrialQueuedBehindAFailedResetIsReleasedUncountedAndRunsAgain) {
  Harness h(2);
  QueueNext(h);
  h.reset_answer = msg::STATE_FAILED;
  h.Start();
  for (int i = 0; i < 20 && h.store.trials[2].attempt == 1; ++i) {
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
    h.Answer();
  }
  ASSERT_EQ(h.store.trials[2].attempt, 2) << "the queued trial was not released";
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kPlanned);
  EXPECT_EQ(h.store.trials[2].rules, (std::vector<std::string>{"queued.behind_failed_reset"}));
  EXPECT_EQ(h.store.trials[2].service_restarts, 1) << "the released attempt is not counted";
  h.reset_answer = msg::STATE_RESET_DONE;
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);  // its truth is complete
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[2].attempt, 2);
  EXPECT_EQ(h.store.trials[2].samples, 10);
  // The cell's REFUSED of the released attempt failed nothing.
  EXPECT_EQ(h.store.trials[2].outcome, db::TrialEnd::kNone);
  EXPECT_EQ(h.driver->counters().failed, 0);
  EXPECT_EQ(h.driver->counters().resets_failed, 1);
}

// The cell is lost while it resets: its queued trial is released (not
// counted) with the reset closed as not observed; the cell back, both run.
TEST(TrialDriver, ATrialQueuedOnACellLostDuringItsResetIsReleased) {
  Harness h(2);
  QueueNext(h);
  h.Start();
  const msg::TrialCommand first = ExecuteAndAnswer(h);
  const auto executes = Executes(h);
  ASSERT_EQ(executes.size(), 2u) << "the next trial was not queued behind the reset";
  EXPECT_EQ(executes[1].after_reset_trial_id(), first.trial_id());
  h.driver->OnCellLost("c1", "participant left", false);
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kPlanned);
  EXPECT_EQ(h.store.trials[2].attempt, 2);
  EXPECT_EQ(h.store.trials[2].rules, (std::vector<std::string>{"queued.cell_phase_ended"}));
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kResetFailed);
  // Its statuses, from a process that comes back, are late: nothing moves.
  h.driver->OnStatus(h.Status(LastReset(h), msg::STATE_RESET_DONE));
  h.driver->OnStatus(h.Status(executes[1], msg::STATE_ACCEPTED));
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kPlanned);
  h.answered = h.transport.sent.size();  // the lost process's commands go unanswered
  h.driver->OnAnnounce(h.Announce("c1", kSession, 2));
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[2].attempt, 2);
}

// A busy store holds the publish before the queued trial: its reset's
// RESET_DONE is held, and so are the queued trial's own statuses, which come
// after it, as are its batches; once the publish commits, the reset is
// taken, then the queued trial's stream and statuses.
TEST(TrialDriver, AQueuedTrialsStatusesWaitForItsResetsStatus) {
  Harness h(2);
  QueueNext(h);
  h.store.faults.next["Ingest.Finish"] = {K::kBusy, K::kBusy};
  h.Start();
  ExecuteAndAnswer(h);
  const auto executes = Executes(h);
  ASSERT_EQ(executes.size(), 2u);
  h.driver->OnStatus(h.Status(LastReset(h), msg::STATE_RESET_DONE));
  h.driver->OnStatus(h.Status(executes[1], msg::STATE_ACCEPTED));
  h.driver->OnGroundTruth(h.Batch(executes[1]));
  h.driver->OnStatus(h.Status(executes[1], msg::STATE_EXECUTED));
  h.answered = h.transport.sent.size();
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDispatched);
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kDispatched);
  EXPECT_EQ(h.store.faults.calls["CompleteReset"], 0);
  ASSERT_TRUE(h.RunToEnd());
  for (const std::int64_t id : {1, 2}) {
    EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone) << id;
    EXPECT_EQ(h.store.trials[id].attempt, 1) << id;
    EXPECT_EQ(h.store.trials[id].samples, 10) << id;
    EXPECT_EQ(h.store.trials[id].rules,
              (std::vector<std::string>{kResetAfterExecute, "reset.verified"}))
        << id;
  }
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
  EXPECT_EQ(h.driver->counters().retried, 0);
}

// No trial is queued for a service that is stopping: the cell's last reset
// frees it, and the trial after it stays planned.
TEST(TrialDriver, NothingIsQueuedWhileTheServiceStops) {
  Harness h(2);
  QueueNext(h);
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);
  msg::TrialCommand execute = Executes(h).front();
  h.driver->Tick(true);  // stopping from now on
  h.driver->OnGroundTruth(h.Batch(execute));
  h.driver->OnStatus(h.Status(execute, msg::STATE_EXECUTED));
  EXPECT_EQ(h.Sent(msg::PHASE_RESET), 1);
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kPlanned);
}

// A RESET_DONE that comes while a busy store still holds the publish is held:
// nothing of the reset is written before the trial is executed (resetting
// only after executed), the cell gets no trial meanwhile, and once the
// publish commits the reset is recorded as any other and the cell goes on.
TEST(TrialDriver, AResetDoneWhileABusyStoreHoldsThePublishIsTakenOnlyAfterItCommits) {
  Harness h(2);
  h.store.faults.next["Ingest.Finish"] = {K::kBusy, K::kBusy};
  h.Start();
  ExecuteAndAnswer(h);
  ASSERT_EQ(h.Sent(msg::PHASE_RESET), 1) << "the RESET waited for the publish";
  h.driver->OnStatus(h.Status(LastReset(h), msg::STATE_RESET_DONE));
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDispatched);
  EXPECT_EQ(h.store.faults.calls["CompleteReset"], 0);
  EXPECT_EQ(h.driver->IdleCells(), 0);
  int ticks = 0;
  for (; ticks < 40 && h.store.trials[1].state == db::TrialState::kDispatched; ++ticks) {
    EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1) << "a trial sent to a cell its publish holds";
    EXPECT_EQ(h.store.faults.calls["CompleteReset"], 0);
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
  }
  ASSERT_LT(ticks, 40) << "the publish never committed";
  EXPECT_EQ(h.store.faults.calls["Ingest.Finish"], 3);
  // The held RESET_DONE was taken with the commit: the next trial went out in that Tick.
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.faults.calls["CompleteReset"], 2);  // once per trial, none refused
  for (const std::int64_t id : {1, 2}) {
    EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone);
    EXPECT_EQ(h.store.trials[id].attempt, 1);
    EXPECT_EQ(h.store.trials[id].rules,
              (std::vector<std::string>{kResetAfterExecute, "reset.verified"}));
  }
  EXPECT_EQ(h.Sent(msg::PHASE_RESET), 2);
  EXPECT_EQ(h.driver->counters().retried, 0);
  EXPECT_EQ(h.driver->counters().resets_failed, 0);
}

// A publish the store refuses after the cell was told to reset ends the
// attempt as a refused publish always did (execute.store_refused_truth:
// retried, the store's fault, the cell backs off); the cell is freed by its
// reset (its status, whether it came before or after the refusal, or its
// deadline), never sent a trial while it resets, and nothing of that reset
// is written for the trial. The trial then runs again on the same cell.
TEST(TrialDriver, ARefusedPublishWithTheCellResettingRetriesTheTrialAndTheResetFreesTheCell) {
  enum class Cell { kAnswersAfter, kAnsweredWhileHeld, kNeverAnswers };
  for (const Cell cell : {Cell::kAnswersAfter, Cell::kAnsweredWhileHeld, Cell::kNeverAnswers}) {
    SCOPED_TRACE(static_cast<int>(cell));
    Harness h;
    h.store.faults.next["Ingest.Finish"] = cell == Cell::kAnsweredWhileHeld
                                               ? std::deque<K>{K::kBusy, K::kStaleAttempt}
                                               : std::deque<K>{K::kStaleAttempt};
    h.Start();
    ExecuteAndAnswer(h);
    ASSERT_EQ(h.Sent(msg::PHASE_RESET), 1) << "the RESET waited for the publish";
    const msg::TrialCommand reset = LastReset(h);
    if (cell == Cell::kAnsweredWhileHeld) {
      h.driver->OnStatus(h.Status(reset, msg::STATE_RESET_DONE));  // held
      for (int i = 0; i < 40 && h.store.trials[1].attempt == 1; ++i) {
        h.t += std::chrono::milliseconds(100);
        h.driver->Tick(false);
      }
    }
    EXPECT_EQ(h.store.trials[1].state, db::TrialState::kPlanned);
    EXPECT_EQ(h.store.trials[1].attempt, 2);
    EXPECT_EQ(h.store.trials[1].rules,
              (std::vector<std::string>{"execute.store_refused_truth retry.attempts_left"}));
    EXPECT_EQ(h.driver->IdleCells(), cell == Cell::kAnsweredWhileHeld ? 1 : 0);
    if (cell == Cell::kAnswersAfter) {
      h.t += std::chrono::milliseconds(100);
      h.driver->Tick(false);
      EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1) << "a trial sent to a resetting cell";
      h.driver->OnStatus(h.Status(reset, msg::STATE_RESET_DONE));
      EXPECT_EQ(h.driver->IdleCells(), 1);
    } else if (cell == Cell::kNeverAnswers) {
      h.t += std::chrono::seconds(30);
      h.driver->Tick(false);
      EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1) << "a trial sent to a resetting cell";
      h.t += std::chrono::seconds(33);  // past the reset's deadline (60 s + 2)
      h.driver->Tick(false);
      EXPECT_EQ(h.driver->IdleCells(), 1);
      EXPECT_EQ(h.store.failures, 1) << "the missed reset is the cell's";
    }
    EXPECT_EQ(h.store.faults.calls["CompleteReset"], 0);
    EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);  // the refusal's backoff holds
    ASSERT_TRUE(h.RunToEnd());
    EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
    EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
    EXPECT_EQ(h.store.trials[1].attempt, 2);
    EXPECT_EQ(h.store.trials[1].rules,
              (std::vector<std::string>{"execute.store_refused_truth retry.attempts_left",
                                        kResetAfterExecute, "reset.verified"}));
    EXPECT_EQ(h.driver->counters().retried, 1);
    EXPECT_EQ(h.driver->counters().resets_failed, 0);
    EXPECT_FALSE(h.store.quarantined.count("c1"));
  }
}

// A service killed after the RESET went out and before the publish committed
// (here: held by a busy store) left the trial dispatched, its stream
// unpublished: the restart re-queues it, as any trial killed before its
// publish, and what the old session's cell says is not ours.
TEST(TrialDriver, AServiceKilledBetweenTheResetAndThePublishsCommitRequeuesTheTrial) {
  Harness h(2);
  h.store.faults.next["Ingest.Finish"] = {K::kBusy, K::kBusy, K::kBusy};
  h.Start();
  ExecuteAndAnswer(h);
  ASSERT_EQ(h.Sent(msg::PHASE_RESET), 1);
  const msg::TrialCommand reset = LastReset(h);
  ASSERT_EQ(h.store.trials[1].state, db::TrialState::kDispatched);
  h.store.faults.next["Ingest.Finish"].clear();
  h.NewDriver();
  h.Start();
  h.driver->OnStatus(h.Status(reset, msg::STATE_RESET_DONE));  // late: the cell is idle
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kPlanned);
  EXPECT_EQ(h.store.trials[1].attempt, 2);
  h.answered = h.transport.sent.size();  // the old session's commands are not answered
  ASSERT_TRUE(h.RunToEnd());
  for (const std::int64_t id : {1, 2}) EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 2);
  EXPECT_EQ(h.store.trials[1].rules,
            (std::vector<std::string>{kResetAfterExecute, "reset.verified"}));
  EXPECT_EQ(h.store.faults.calls["CompleteReset"], 2);
}

// The cell lost while a busy store holds the publish its RESET went ahead of:
// the attempt is retried as before, the reset's held status is dropped.
TEST(TrialDriver, ACellLostWhileItsPublishIsHeldDropsItsHeldResetStatus) {
  Harness h;
  h.store.faults.next["Ingest.Finish"] = {K::kBusy};
  h.Start();
  ExecuteAndAnswer(h);
  h.driver->OnStatus(h.Status(LastReset(h), msg::STATE_RESET_DONE));  // held
  h.driver->OnCellLost("c1", "participant left", false);
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kPlanned);
  EXPECT_EQ(h.store.trials[1].attempt, 2);
  h.driver->OnAnnounce(h.Announce("c1", kSession, 2));
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 2);
  EXPECT_EQ(h.store.faults.calls["CompleteReset"], 1);  // attempt 2's only
  EXPECT_EQ(h.store.trials[1].rules,
            (std::vector<std::string>{"execute.cell_lost retry.attempts_left", kResetAfterExecute,
                                      "reset.verified"}));
}

// The written-later reset on a busy store: taken again while the cell runs
// its next trial, whose deadlines it does not hold; nothing costs an attempt.
TEST(TrialDriver, ABusyStoreAtTheWrittenLaterResetDoesNotHoldTheCellsNextTrial) {
  Harness h(2);
  h.store.faults.next["CompleteReset"] = {K::kBusy};
  std::vector<db::TrialState> first_at_execute;
  h.transport.on_send = [&](const msg::TrialCommand& c) {
    if (c.phase() == msg::PHASE_EXECUTE) first_at_execute.push_back(h.store.trials[1].state);
  };
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  ASSERT_EQ(first_at_execute.size(), 2u);
  EXPECT_EQ(first_at_execute[1], db::TrialState::kResetting);
  EXPECT_EQ(h.store.faults.calls["CompleteReset"], 3);  // trial 1 twice, trial 2 once
  for (const std::int64_t id : {1, 2}) {
    EXPECT_EQ(h.store.trials[id].state, db::TrialState::kDone);
    EXPECT_EQ(h.store.trials[id].attempt, 1);
    EXPECT_EQ(h.store.trials[id].predictions, 1);
  }
  EXPECT_EQ(h.driver->counters().retried, 0);
}

// The EXECUTE goes out before the ingest begins: a store that then refuses
// the ingest ends the attempt (the store's fault, retried), and what the cell
// still sends for it is dropped as late.
TEST(TrialDriver, AnIngestRefusedAfterItsExecuteWentOutRetriesTheTrial) {
  Harness h;
  h.store.faults.next["BeginIngest"] = {K::kStaleAttempt};
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 2);
  EXPECT_EQ(h.store.trials[1].samples, 10);
  ASSERT_FALSE(h.store.trials[1].rules.empty());
  EXPECT_EQ(h.store.trials[1].rules.front().rfind("execute.store_refused_truth", 0), 0u)
      << h.store.trials[1].rules.front();
}

// The service stops with a clean reset not yet written (here: held by a busy
// store) and the cell's next trial sent: the restart closes the reset as not
// observed (reset_failed; the trial is predicted and done) and re-queues the
// sent trial, as for any trial in flight at a restart.
TEST(TrialDriver, AResetNotYetWrittenAtARestartIsClosedAsNotObserved) {
  Harness h(2);
  h.store.faults.next["CompleteReset"] = {K::kBusy, K::kBusy, K::kBusy, K::kBusy};
  h.Start();
  for (int i = 0; i < 40 && h.Sent(msg::PHASE_EXECUTE) < 2; ++i) {
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
    if (h.Sent(msg::PHASE_EXECUTE) == 2) break;  // trial 2 sent, not yet answered
    h.Answer();
  }
  ASSERT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
  ASSERT_EQ(h.store.trials[1].state, db::TrialState::kResetting);
  h.store.faults.next["CompleteReset"].clear();
  h.NewDriver();
  h.answered = h.transport.sent.size();  // the old session's commands are not answered
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 1);
  EXPECT_EQ(h.store.trials[1].predictions, 1);
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[2].attempt, 2);  // sent before the restart: a restart's re-queue
}

// Busy at any step: the same step is taken again; the trial is never
// abandoned, never retried as if the cell had failed, and ends done.
class BusyAtEveryStep : public ::testing::TestWithParam<std::string> {};

TEST_P(BusyAtEveryStep, TheSameStepIsRetriedAndTheTrialEndsDone) {
  Harness h;
  h.store.faults.next[GetParam()] = {K::kBusy, K::kBusy, K::kBusy};
  h.Start();
  ASSERT_TRUE(h.RunToEnd()) << "trial stuck in " << db::ToString(h.store.trials[1].state);
  EXPECT_GT(h.store.faults.calls[GetParam()], 3) << GetParam() << " was not retried";
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 1) << "a busy store cost the trial an attempt";
  EXPECT_EQ(h.store.trials[1].samples, 10);
  EXPECT_EQ(h.driver->pending_store_steps(), 0u);
  EXPECT_EQ(h.driver->counters().retried, 0);
}

// Every store step a trial (or its cell) goes through.
const std::vector<std::string> kSteps = {
    "RecoverAfterRestart", "ListTrialsByState", "UpsertCell",       "CellQuarantined",
    "SetCellServing",      "ClaimNextTrial",    "BeginIngest",      "Ingest.Add",
    "Ingest.Finish",       "RecordCellResult",  "PeekNextTrial",    "BeginReset",
    "CompleteReset",       "GetTrial",          "RecordPrediction", "FinishTrial"};
// ... and the periodic ones (a busy one is simply taken at its next period).
std::vector<std::string> AllSteps() {
  auto all = kSteps;
  all.push_back("ServiceBeat");
  all.push_back("CompleteFinishedCampaigns");
  return all;
}

INSTANTIATE_TEST_SUITE_P(Steps, BusyAtEveryStep, ::testing::ValuesIn(kSteps), [](const auto& info) {
  std::string n = info.param;
  std::erase(n, '.');
  return n;
});

// A store that cannot take writes: the driver stops (throws) at that step.
class FatalAtEveryStep : public ::testing::TestWithParam<std::tuple<std::string, K>> {};

TEST_P(FatalAtEveryStep, TheDriverStopsWithTheStoreError) {
  const auto& [step, kind] = GetParam();
  Harness h;
  h.store.faults.next[step] = {kind};
  bool thrown = false;
  try {
    h.Start();
    h.RunToEnd();
  } catch (const db::StoreError& e) {
    thrown = true;
    EXPECT_EQ(e.kind(), kind);
  }
  EXPECT_TRUE(thrown) << step << ": a fatal store error did not stop the driver";
}

std::string FatalName(const ::testing::TestParamInfo<std::tuple<std::string, K>>& info) {
  std::string n = std::get<0>(info.param);
  std::erase(n, '.');
  static const char* const kKinds[] = {"BadInput", "NotFound", "Illegal", "Stale", "ReadOnly",
                                       "Busy",     "TooNew",   "Corrupt", "Full",  "Io"};
  return n + "_" + kKinds[static_cast<int>(std::get<1>(info.param))];
}

INSTANTIATE_TEST_SUITE_P(Steps, FatalAtEveryStep,
                         ::testing::Combine(::testing::ValuesIn(AllSteps()),
                                            ::testing::Values(K::kFull, K::kReadOnly, K::kCorrupt,
                                                              K::kIo)),
                         FatalName);

// A step the store calls moot (a stale attempt, an illegal edge: a late
// message, someone else moved the trial) is dropped, and nothing in the driver
// waits for it for ever: the cell goes on with the next trial.
class MootAtEveryStep : public ::testing::TestWithParam<std::string> {};

TEST_P(MootAtEveryStep, TheDriverIsNeverStuckAndTheCellGoesOn) {
  Harness h(2);
  h.store.faults.next[GetParam()] = {K::kStaleAttempt};
  h.Start();
  h.RunToEnd(300);
  EXPECT_FALSE(h.driver->InFlight()) << GetParam() << ": the driver waits for ever";
  EXPECT_EQ(h.driver->pending_store_steps(), 0u);
  EXPECT_EQ(h.store.trials[2].state, db::TrialState::kDone) << GetParam();
}

INSTANTIATE_TEST_SUITE_P(Steps, MootAtEveryStep, ::testing::ValuesIn(kSteps), [](const auto& info) {
  std::string n = info.param;
  std::erase(n, '.');
  return n;
});

TEST(TrialDriver, AStoreFileThatVanishesStopsTheNextTick) {
  Harness h;
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);
  h.store.file_gone = true;
  h.t += std::chrono::milliseconds(200);
  EXPECT_THROW(h.driver->Tick(false), db::StoreError);
}

TEST(TrialDriver, ASimulationFailureFailsTheTrialAtOnceWithoutBlamingTheCell) {
  Harness h;
  h.execute_answer = msg::STATE_FAILED;
  h.execute_failure = msg::FAILURE_SIMULATION;
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kFailed);
  EXPECT_EQ(h.store.trials[1].outcome, db::TrialEnd::kSolverFailure);
  EXPECT_EQ(h.store.trials[1].attempt, 1);
  EXPECT_EQ(h.store.faults.calls["RecordCellResult"], 0);
}

TEST(TrialDriver, AFailedExecuteIsRetriedUpToMaxAttemptsThenTheCellIsQuarantined) {
  Harness h;
  h.execute_answer = msg::STATE_FAILED;
  h.Start();
  ASSERT_TRUE(h.RunToEnd(2000));
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kFailed);
  EXPECT_EQ(h.store.trials[1].attempt, 3);
  EXPECT_TRUE(h.store.quarantined.count("c1"));
}

TEST(TrialDriver, AMissedDeadlineRetriesTheTrial) {
  Harness h;
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);
  ASSERT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  h.answered = h.transport.sent.size();  // the cell never answers
  h.t += std::chrono::seconds(40);
  h.driver->Tick(false);
  EXPECT_EQ(h.store.trials[1].attempt, 2);  // retried
  EXPECT_EQ(h.driver->counters().retried, 1);
  EXPECT_EQ(h.store.trials[1].rules.back(), "execute.deadline_missed retry.attempts_left");
  // The cell backs off (issue 28): not dispatched again at once ...
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  h.t += std::chrono::milliseconds(300);
  h.driver->Tick(false);
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  // ... but after its backoff (0.5 s for a first failure).
  h.t += std::chrono::milliseconds(300);
  h.driver->Tick(false);
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 2);
}

TEST(TrialDriver, ACellRestartedWithinItsLeaseStaysAliveAndItsOldPhaseIsAborted) {
  Harness h;
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);
  ASSERT_EQ(h.Sent(msg::PHASE_EXECUTE), 1);
  h.answered = h.transport.sent.size();  // the old process died mid-trial
  // The new process announces first (not yet serving anyone) ...
  h.driver->OnAnnounce(h.Announce("c1", 0, /*incarnation=*/2));
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kPlanned) << "old phase not aborted";
  // ... then the old one's loss arrives while the new one is there.
  h.driver->OnCellLost("c1", "liveliness lost", /*another_process=*/true);
  EXPECT_FALSE(h.store.gone.count("c1"));
  EXPECT_EQ(h.driver->counters().cells_usable, 1);
  h.driver->OnAnnounce(h.Announce("c1", kSession, 2));
  ASSERT_TRUE(h.RunToEnd());
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kDone);
  EXPECT_EQ(h.store.trials[1].attempt, 2);
}

TEST(TrialDriver, ALostCellIsGoneAndItsTrialRequeued) {
  Harness h;
  h.Start();
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);
  h.answered = h.transport.sent.size();
  h.driver->OnCellLost("c1", "participant left", false);
  EXPECT_TRUE(h.store.gone.count("c1"));
  EXPECT_EQ(h.store.trials[1].state, db::TrialState::kPlanned);
  EXPECT_EQ(h.driver->counters().cells_usable, 0);
}

// Issue 27: the prediction is off the trial's path. A service stopped with
// predictions pending (its trials executed, reset, not predicted) leaves
// them in the store; the next one predicts each, once, and finishes it.
TEST(TrialDriver, PredictionsPendingAtAStopArePredictedOnceByTheNextService) {
  Harness h(4);
  h.predictor_holds = true;
  h.Start();
  for (int i = 0; i < 100 && h.Sent(msg::PHASE_RESET) < 4; ++i) {
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
    h.Answer();
  }
  ASSERT_EQ(h.Sent(msg::PHASE_RESET), 4) << "the cell waited for the predictor";
  h.t += std::chrono::milliseconds(100);
  h.driver->Tick(false);  // the last prediction is started after its reset is sent
  for (int i = 1; i <= 4; ++i) {
    EXPECT_EQ(h.store.trials[i].state, db::TrialState::kResetDone) << "trial " << i;
    EXPECT_EQ(h.store.trials[i].predictions, 0);
  }
  EXPECT_EQ(h.predictions.outstanding(), 4);
  EXPECT_TRUE(h.driver->InFlight()) << "pending predictions must keep a draining service";

  h.NewDriver();  // the service stops (or is killed); its predictor's queue is gone
  h.predictor_holds = false;
  h.driver->Resume();
  EXPECT_EQ(h.predictions.outstanding(), 4) << "the restart did not ask for the predictions";
  ASSERT_TRUE(h.RunToEnd());
  for (int i = 1; i <= 4; ++i) {
    EXPECT_EQ(h.store.trials[i].state, db::TrialState::kDone) << "trial " << i;
    EXPECT_EQ(h.store.trials[i].predictions, 1) << "trial " << i;
  }
}

// A predictor behind by a full backlog holds new claims (memory bounded, the
// predictor never left behind for good); dispatch resumes when it catches up.
TEST(TrialDriver, AFullPredictionBacklogHoldsNewClaimsUntilThePredictorCatchesUp) {
  Harness h(5, /*prediction_backlog=*/2);
  h.predictor_holds = true;
  h.Start();
  for (int i = 0; i < 50; ++i) {
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
    h.Answer();
  }
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 2) << "claims went on past the prediction backlog";
  EXPECT_EQ(h.store.trials[3].state, db::TrialState::kPlanned);
  h.predictor_holds = false;
  ASSERT_TRUE(h.RunToEnd());
  for (int i = 1; i <= 5; ++i) {
    EXPECT_EQ(h.store.trials[i].state, db::TrialState::kDone) << "trial " << i;
    EXPECT_EQ(h.store.trials[i].predictions, 1) << "trial " << i;
  }
}

TEST(TrialDriver, ResumeFinishesWhatARestartLeftThroughTheSameSteps) {
  Harness h(5);
  h.store.trials[1].state = db::TrialState::kExecuted;
  h.store.trials[2].state = db::TrialState::kResetDone;
  h.store.trials[3].state = db::TrialState::kPredicted;
  h.store.trials[4].state = db::TrialState::kDispatched;  // -> planned, attempt 2
  h.store.trials[5].state = db::TrialState::kResetting;   // -> reset_failed
  h.store.faults.next["BeginReset"] = {K::kBusy};
  h.store.faults.next["RecordPrediction"] = {K::kBusy};
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  for (int i = 1; i <= 5; ++i)
    EXPECT_EQ(h.store.trials[i].state, db::TrialState::kDone) << "trial " << i;
  EXPECT_EQ(h.store.trials[4].attempt, 2);
  EXPECT_EQ(h.driver->counters().recovered, 2);
}

// Issue 28: a controller paused past its hold time fails trial after trial;
// none counts against the cell, which is never quarantined, backs off
// between them, and runs the trials once the controller is back.
TEST(TrialDriver, ControllerFaultsNeverQuarantineTheCellAndTheCellBacksOff) {
  Harness h(4);
  h.execute_answer = msg::STATE_FAILED;
  h.execute_failure = msg::FAILURE_CONTROLLER;
  h.Start();
  for (int i = 0; i < 60; ++i) {  // 6 s of a controller that answers nothing
    h.t += std::chrono::milliseconds(100);
    h.driver->Tick(false);
    h.Answer();
  }
  EXPECT_EQ(h.store.faults.calls["RecordCellResult"], 0) << "a controller fault blamed the cell";
  EXPECT_FALSE(h.store.quarantined.count("c1"));
  // Backed off: 0.5 + 1 + 2 + 4 s between the failures, so at most 4 or 5 in 6 s.
  EXPECT_LE(h.Sent(msg::PHASE_EXECUTE), 5);
  EXPECT_GE(h.Sent(msg::PHASE_EXECUTE), 3);
  bool named = false;
  for (const auto& [id, t] : h.store.trials)
    for (const auto& r : t.rules) named = named || r.rfind("execute.controller_fault", 0) == 0;
  EXPECT_TRUE(named);
  h.execute_answer = msg::STATE_EXECUTED;  // the controller is back
  ASSERT_TRUE(h.RunToEnd(2000));
  EXPECT_FALSE(h.store.quarantined.count("c1"));
}

TEST(TrialDriver, EveryResetItBeginsNamesItsRule) {
  Harness h;
  h.Start();
  ASSERT_TRUE(h.RunToEnd());
  const auto& rules = h.store.trials[1].rules;
  ASSERT_EQ(rules.size(), 2u);
  EXPECT_EQ(rules[0], kResetAfterExecute);
  EXPECT_EQ(rules[1], "reset.verified");
}

TEST(TrialDriver, NoTrialIsDispatchedBeforeRecoveryRan) {
  Harness h;
  h.store.faults.next["RecoverAfterRestart"] = {K::kBusy, K::kBusy};
  h.driver->Resume();
  h.driver->OnAnnounce(h.Announce("c1", kSession));
  h.driver->Tick(false);  // the backoff has not passed: recovery waits, so does dispatch
  EXPECT_EQ(h.Sent(msg::PHASE_EXECUTE), 0);
  ASSERT_TRUE(h.RunToEnd());
}

// The EXECUTED status's truth is read without parsing the detail whole
// (issue 27): only the top-level "truth" string of an object counts, and a
// malformed detail states none, as when it was parsed whole.
std::string StatedTruth(std::string_view detail_json) {
  const auto d = ReadExecutionDetail(detail_json);
  return d ? d->truth : std::string();
}

TEST(StatedTruth, IsTheTopLevelTruthStringOfAWellFormedObjectOnly) {
  EXPECT_EQ(StatedTruth(R"({"backend":"model","truth":"simulated","x":[1,{"truth":"no"}]})"),
            "simulated");
  EXPECT_EQ(StatedTruth(R"({"a":{"truth":"nested"},"truth":"measured_no_forces"})"),
            "measured_no_forces");
  EXPECT_EQ(StatedTruth(R"({"a":{"truth":"nested only"}})"), "");
  EXPECT_EQ(StatedTruth(R"({"truth":{"kind":"simulated"}})"), "");
  EXPECT_EQ(StatedTruth(R"({"truth":3,"b":"simulated"})"), "");
  EXPECT_EQ(StatedTruth(R"({"truth":"simulated","b":)"), "");  // malformed after it
  EXPECT_EQ(StatedTruth(R"([{"truth":"simulated"}])"), "");
  EXPECT_EQ(StatedTruth(R"("simulated")"), "");
  EXPECT_EQ(StatedTruth(""), "");
}

// What ran a trial is read from the EXECUTED status's detail without a
// document (issue 27): for every detail the cell writes (a compact dump), the
// same record as parsing it whole and dumping "defects_applied" back.
TEST(ReadExecutionDetail, GivesWhatAParseAndDumpGaveForEveryCompactDetail) {
  std::mt19937 rng(27);
  const std::vector<std::string> keys = {"backend", "truth", "defects_applied", "a",
                                         "x\"y",    "b\\",   "\u00e9t\u00e9",   "defects"};
  const std::vector<std::string> words = {"model",   "simulated",   "",
                                          "q\"uote", "back\\slash", "{not json}",
                                          "[1,2]",   "tab\there",   "\u00e9"};
  std::function<nlohmann::json(int)> value = [&](int depth) -> nlohmann::json {
    switch (std::uniform_int_distribution<int>(0, depth > 2 ? 4 : 6)(rng)) {
      case 0:
        return nullptr;
      case 1:
        return std::uniform_int_distribution<int>(0, 1)(rng) == 1;
      case 2:
        return std::uniform_real_distribution<double>(-1e6, 1e6)(rng);
      case 3:
        return std::uniform_int_distribution<int>(-5, 5)(rng);
      case 4:
        return words[std::uniform_int_distribution<std::size_t>(0, words.size() - 1)(rng)];
      case 5: {
        nlohmann::json a = nlohmann::json::array();
        for (int i = std::uniform_int_distribution<int>(0, 3)(rng); i > 0; --i)
          a.push_back(value(depth + 1));
        return a;
      }
      default: {
        nlohmann::json o = nlohmann::json::object();
        for (int i = std::uniform_int_distribution<int>(0, 4)(rng); i > 0; --i)
          o[keys[std::uniform_int_distribution<std::size_t>(0, keys.size() - 1)(rng)]] =
              value(depth + 1);
        return o;
      }
    }
  };
  for (int n = 0; n < 500; ++n) {
    nlohmann::json detail = nlohmann::json::object();
    for (int i = std::uniform_int_distribution<int>(0, 6)(rng); i > 0; --i)
      detail[keys[std::uniform_int_distribution<std::size_t>(0, keys.size() - 1)(rng)]] = value(1);
    const std::string text = detail.dump();
    SCOPED_TRACE(text);
    const auto got = ReadExecutionDetail(text);
    ASSERT_TRUE(got.has_value());
    auto string_of = [&](const char* key) {
      return detail.contains(key) && detail[key].is_string() ? detail[key].get<std::string>()
                                                             : std::string();
    };
    EXPECT_EQ(got->backend, string_of("backend"));
    EXPECT_EQ(got->truth, string_of("truth"));
    if (detail.contains("defects_applied")) {
      ASSERT_TRUE(got->defects_applied.has_value());
      EXPECT_EQ(*got->defects_applied, detail["defects_applied"].dump());
    } else {
      EXPECT_FALSE(got->defects_applied.has_value());
    }
  }
}

TEST(ReadExecutionDetail, KeepsTheCellsTextAndRefusesWhatIsNotAWellFormedObject) {
  // Spaced out: the value's text as written (the same value), escapes in keys decoded.
  const auto spaced = ReadExecutionDetail(
      "{ \"backend\" : \"model\",\n \"defects\\u005fapplied\" : { \"mu\" : [1, 2.5] } ,"
      " \"truth\":\"simulated\" }");
  ASSERT_TRUE(spaced.has_value());
  EXPECT_EQ(spaced->backend, "model");
  EXPECT_EQ(spaced->truth, "simulated");
  ASSERT_TRUE(spaced->defects_applied.has_value());
  EXPECT_EQ(*spaced->defects_applied, "{ \"mu\" : [1, 2.5] }");
  // The last of a repeated key counts, as in a parsed document.
  const auto repeated = ReadExecutionDetail(
      R"({"backend":"a","defects_applied":1,"backend":2,"defects_applied":[3]})");
  ASSERT_TRUE(repeated.has_value());
  EXPECT_EQ(repeated->backend, "");
  EXPECT_EQ(repeated->defects_applied, std::optional<std::string>("[3]"));
  for (const char* bad : {"", "[]", "\"x\"", R"({"backend":"model","defects_applied":{)",
                          R"({"backend":"model"} trailing)", "{\"a\":1,}"})
    EXPECT_FALSE(ReadExecutionDetail(bad).has_value()) << bad;
}

}  // namespace
}  // namespace arena::orchestrator
