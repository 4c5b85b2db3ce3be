// The store on real SQLite files: migrations, the trial state machine, cells,
// ingest, recovery, status (db/include/arena/db/store.hpp).
#include <sqlite3.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <thread>

#include <sched.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeSample;
using testing::MakeTrials;
using testing::RunTrialToDone;
using testing::SceneJson;
using testing::TempDir;

#define EXPECT_STORE_ERROR(stmt, kind_)                                           \
  do {                                                                            \
    try {                                                                         \
      stmt;                                                                       \
      ADD_FAILURE() << "expected StoreError from " #stmt;                         \
    } catch (const StoreError& e) {                                               \
      EXPECT_EQ(static_cast<int>(e.kind()), static_cast<int>(kind_)) << e.what(); \
    }                                                                             \
  } while (0)

using K = StoreError::Kind;

std::string RawScalar(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
  sqlite3_stmt* s = nullptr;
  sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr);
  std::string out;
  if (sqlite3_step(s) == SQLITE_ROW && sqlite3_column_text(s, 0)) {
    out = reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
  }
  sqlite3_finalize(s);
  sqlite3_close(db);
  return out;
}

void ExpectHealthy(const Store& store) {
  EXPECT_EQ(store.IntegrityCheck(), "ok");
  const auto v = store.CheckInvariants();
  EXPECT_TRUE(v.empty()) << v.front();
}

TEST(StoreOpen, MigratesEmptyFileAndReopens) {
  TempDir dir;
  const auto path = dir.File("a.db");
  {
    auto store = Store::Open(path);
    EXPECT_EQ(store->FileSchemaVersion(), Store::SchemaVersion());
    store->CreateCampaign(MakeCampaign(), MakeTrials(2));
  }
  EXPECT_EQ(RawScalar(path, "PRAGMA journal_mode"), "wal");
  // Versions may have gaps (each branch owns its numbers): the last one is the schema's.
  EXPECT_EQ(RawScalar(path, "SELECT MAX(version) FROM schema_migrations"),
            std::to_string(Store::SchemaVersion()));
  auto again = Store::Open(path);
  EXPECT_EQ(again->FileSchemaVersion(), Store::SchemaVersion());
  EXPECT_EQ(again->ListTrials(1).size(), 2u);
  ExpectHealthy(*again);
}

// A file at schema 1 (as the first merged arena wrote it) is migrated on a
// read-write open, its data kept; a read-only open of it asks for that first.
TEST(StoreOpen, MigratesVersionOneFile) {
  TempDir dir;
  const auto path = dir.File("v1.db");
  Store::Open(path)->CreateCampaign(MakeCampaign("old"), MakeTrials(2));
  {
    sqlite3* db = nullptr;
    sqlite3_open(path.c_str(), &db);
    ASSERT_EQ(
        sqlite3_exec(db,
                     (std::string("BEGIN;") + testing::kUndoMigration6 + testing::kUndoMigration7 +
                      " ALTER TABLE campaigns DROP COLUMN state_reason;"
                      " DROP TABLE evaluation_results; DROP TABLE evaluations;" +
                      testing::kUndoMigration10 + testing::kUndoMigration14 +
                      testing::kUndoMigration15 + testing::kUndoMigration5 +
                      " DELETE FROM schema_migrations WHERE version > 1; PRAGMA user_version = 1;"
                      " COMMIT;")
                         .c_str(),
                     nullptr, nullptr, nullptr),
        SQLITE_OK)
        << sqlite3_errmsg(db);
    sqlite3_close(db);
  }
  StoreOptions ro;
  ro.read_only = true;
  EXPECT_STORE_ERROR(Store::Open(path, ro), K::kIo);
  auto store = Store::Open(path);
  EXPECT_EQ(store->FileSchemaVersion(), Store::SchemaVersion());
  EXPECT_EQ(store->GetCampaign(1).name, "old");
  store->PauseCampaign(1, "why not");
  EXPECT_EQ(store->GetCampaign(1).state_reason, "why not");
  EXPECT_EQ(store->ListTrials(1).size(), 2u);
  ExpectHealthy(*store);
}

TEST(StoreOpen, RefusesStoreNewerThanBinary) {
  TempDir dir;
  const auto path = dir.File("new.db");
  Store::Open(path).reset();
  sqlite3* db = nullptr;
  sqlite3_open(path.c_str(), &db);
  sqlite3_exec(db, "PRAGMA user_version = 999", nullptr, nullptr, nullptr);
  sqlite3_close(db);
  EXPECT_STORE_ERROR(Store::Open(path), K::kTooNew);
  StoreOptions ro;
  ro.read_only = true;
  EXPECT_STORE_ERROR(Store::Open(path, ro), K::kTooNew);
}

TEST(StoreOpen, ReadOnlyRefusesEveryWriteAndMissingFile) {
  TempDir dir;
  const auto path = dir.File("ro.db");
  StoreOptions ro;
  ro.read_only = true;
  EXPECT_STORE_ERROR(Store::Open(path, ro), K::kIo);
  Store::Open(path)->CreateCampaign(MakeCampaign(), MakeTrials(1));
  auto store = Store::Open(path, ro);
  EXPECT_TRUE(store->read_only());
  EXPECT_STORE_ERROR(store->CreateCampaign(MakeCampaign(), MakeTrials(1)), K::kReadOnly);
  EXPECT_STORE_ERROR(store->PauseCampaign(1), K::kReadOnly);
  EXPECT_STORE_ERROR(store->UpsertCell("c1", {"point"}), K::kReadOnly);
  EXPECT_EQ(store->ListCampaigns().size(), 1u);
  EXPECT_EQ(store->Status().campaigns.at(0).planned, 1);
}

// Issue 26: the README's `arena run ... --db out/smoke.db`, typed before
// `out/` existed, said only "cannot open 'out/smoke.db': unable to open
// database file". Pins: a store whose folder is missing is refused (I/O,
// nothing created) naming the folder that does not exist.
TEST(StoreOpen, MissingFolderIsNamed) {
  TempDir dir;
  const auto path = dir.File("out/smoke.db");
  try {
    Store::Open(path);
    ADD_FAILURE() << "opened a store in a missing folder";
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), K::kIo);
    const std::string what = e.what();
    EXPECT_NE(what.find("folder '" + dir.File("out") + "' does not exist"), std::string::npos)
        << what;
    EXPECT_NE(what.find("mkdir -p"), std::string::npos) << what;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.File("out")));
}

TEST(StoreOpen, NotADatabaseIsCorrupt) {
  TempDir dir;
  const auto path = dir.File("junk.db");
  {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    std::string junk(8192, 'x');
    std::fwrite(junk.data(), 1, junk.size(), f);
    std::fclose(f);
  }
  EXPECT_STORE_ERROR(Store::Open(path), K::kCorrupt);
}

TEST(StoreCampaign, StoresTrialsWithParameterColumns) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  const auto id = store->CreateCampaign(MakeCampaign("grip"), MakeTrials(4, "line"));
  const auto trials = store->ListTrials(id);
  ASSERT_EQ(trials.size(), 4u);
  EXPECT_EQ(trials[3].index, 3);
  EXPECT_EQ(trials[3].condition, 1);
  EXPECT_EQ(trials[3].replicate, 1);
  EXPECT_EQ(trials[3].seed, 1003u);
  EXPECT_EQ(trials[0].state, TrialState::kPlanned);
  EXPECT_EQ(trials[0].attempt, 1);
  EXPECT_EQ(RawScalar(store->path(), "SELECT grip_force FROM trials WHERE idx = 2"), "7.0");
  EXPECT_EQ(
      RawScalar(store->path(), "SELECT finger_type || '/' || pusher_type FROM trials LIMIT 1"),
      "line/point");
  EXPECT_EQ(RawScalar(store->path(), "SELECT contact_mask FROM trials LIMIT 1"), "3");
  EXPECT_EQ(RawScalar(store->path(), "SELECT round(pusher_speed, 6) FROM trials LIMIT 1"), "0.01");
  // Append more (budget sampler) continues the index and stores the sampler position.
  store->AppendPlannedTrials(id, MakeTrials(2), R"({"position": 6})");
  EXPECT_EQ(store->ListTrials(id).back().index, 5);
  EXPECT_EQ(store->GetCampaign(id).sampler_state_json, R"({"position": 6})");
  // Big seeds survive the int64 column bit for bit.
  auto big = MakeTrials(1);
  big[0].seed = std::numeric_limits<std::uint64_t>::max() - 5;
  const auto id2 = store->CreateCampaign(MakeCampaign("big"), big);
  EXPECT_EQ(store->ListTrials(id2)[0].seed, std::numeric_limits<std::uint64_t>::max() - 5);
  ExpectHealthy(*store);
}

TEST(StoreCampaign, BadInputRefusedAndNothingStored) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  auto trials = MakeTrials(3);
  trials[2].scene_json = R"({"grip_force": 1e999, "fingers": [{"type": "point"}]})";
  EXPECT_STORE_ERROR(store->CreateCampaign(MakeCampaign(), trials), K::kBadInput);
  try {  // 1e999 is JSON; what is wrong is the number's size (issue 28)
    store->CreateCampaign(MakeCampaign(), trials);
  } catch (const StoreError& e) {
    EXPECT_NE(std::string(e.what()).find("out of range"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("not valid JSON"), std::string::npos) << e.what();
  }
  trials = MakeTrials(3);  // the caller's facts of the scene are checked, each by name
  const auto refused = [&](const char* field) {
    try {
      store->CreateCampaign(MakeCampaign(), trials);
      ADD_FAILURE() << field;
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), K::kBadInput);
      EXPECT_NE(std::string(e.what()).find("trial 2"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
    trials = MakeTrials(3);
  };
  trials[2].facts.finger_type = "blob";
  refused("finger_type");
  trials[2].facts.pusher_type = "blob";
  refused("pusher_type");
  trials[2].facts.grip_force = std::nan("");
  refused("grip_force is NaN");
  trials[2].facts.pusher_speed = std::numeric_limits<double>::infinity();
  refused("pusher_speed is infinite");
  trials[2].facts.nominal[3] = std::nan("");
  refused("nominal[3]");
  trials[2].facts.contact_mask = 0;
  refused("no fingers or pusher");
  trials[2].facts.contact_mask = 8;
  refused("contact_mask");
  trials[2].scene_json = "not json";
  EXPECT_STORE_ERROR(store->CreateCampaign(MakeCampaign(), trials), K::kBadInput);
  EXPECT_STORE_ERROR(store->CreateCampaign(MakeCampaign(""), MakeTrials(1)), K::kBadInput);
  EXPECT_TRUE(store->ListCampaigns().empty());
  EXPECT_EQ(RawScalar(store->path(), "SELECT COUNT(*) FROM trials"), "0");
}

TEST(StoreTrial, FullLifecycleWritesAuditRows) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("cell-1", {"point", "line", "patch"});
  const auto cid = store->CreateCampaign(MakeCampaign(), MakeTrials(1));
  auto claimed = store->ClaimNextTrial("cell-1");
  ASSERT_TRUE(claimed);
  EXPECT_EQ(claimed->campaign_id, cid);
  EXPECT_EQ(store->GetTrial(claimed->trial_id).state, TrialState::kDispatched);
  EXPECT_EQ(store->GetTrial(claimed->trial_id).cell_id, "cell-1");
  RunTrialToDone(*store, *claimed, 300);
  const auto t = store->GetTrial(claimed->trial_id);
  EXPECT_EQ(t.state, TrialState::kDone);
  EXPECT_EQ(t.outcome, TrialEnd::kOk);
  const auto log = store->ListTransitions(t.id);
  const std::vector<std::string> expected = {"planned",    "dispatched", "executed", "resetting",
                                             "reset_done", "predicted",  "done"};
  ASSERT_EQ(log.size(), expected.size());
  for (std::size_t i = 0; i < log.size(); ++i) {
    EXPECT_EQ(log[i].to_state, expected[i]);
    if (i > 0) {
      EXPECT_EQ(log[i].from_state, expected[i - 1]);
    }
  }
  const auto gt = store->ReadGroundTruth(t.id);
  ASSERT_EQ(gt.samples.size(), 300u);
  EXPECT_EQ(gt.samples[123].object_pose[0], MakeSample(123).object_pose[0]);
  EXPECT_EQ(gt.samples[123].contacts[2].mode, MakeSample(123).contacts[2].mode);
  EXPECT_EQ(gt.samples[3].observed_valid, false);
  EXPECT_EQ(store->ListPredictions(t.id).size(), 1u);
  EXPECT_EQ(RawScalar(store->path(), "SELECT samples || '/' || observed_samples FROM gt_summary"),
            "300/257");
  store->CompleteFinishedCampaigns();
  EXPECT_EQ(store->GetCampaign(cid).state, CampaignState::kDone);
  ExpectHealthy(*store);
}

TEST(StoreTrial, StateMachineMatchesTable) {
  using S = TrialState;
  const std::set<std::pair<S, S>> edges = {
      {S::kPlanned, S::kDispatched},  {S::kPlanned, S::kCancelled},
      {S::kDispatched, S::kExecuted}, {S::kDispatched, S::kPlanned},
      {S::kExecuted, S::kResetting},  {S::kResetFailed, S::kResetting},
      {S::kResetting, S::kResetDone}, {S::kResetting, S::kResetFailed},
      {S::kResetDone, S::kPredicted}, {S::kResetFailed, S::kPredicted},
      {S::kPredicted, S::kDone}};
  for (int a = 0; a <= static_cast<int>(S::kCancelled); ++a) {
    for (int b = 0; b <= static_cast<int>(S::kCancelled); ++b) {
      const auto from = static_cast<S>(a), to = static_cast<S>(b);
      const bool expected = edges.count({from, to}) > 0 || (to == S::kFailed && !IsTerminal(from));
      EXPECT_EQ(IsLegalTransition(from, to), expected) << ToString(from) << " -> " << ToString(to);
    }
    EXPECT_EQ(ParseTrialState(ToString(static_cast<S>(a))), static_cast<S>(a));
  }
}

TEST(StoreTrial, IllegalTransitionsRejectedAndNothingWritten) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(2));
  // planned: no reset, no prediction, no finish, no ingest.
  EXPECT_STORE_ERROR(store->BeginReset(1, 1), K::kIllegalTransition);
  EXPECT_STORE_ERROR(store->FinishTrial(1, 1), K::kIllegalTransition);
  EXPECT_STORE_ERROR(store->BeginIngest(1, 1, testing::SceneSites()), K::kIllegalTransition);
  Prediction p;
  p.model_key = "m";
  EXPECT_STORE_ERROR(store->RecordPrediction(1, 1, p), K::kIllegalTransition);
  EXPECT_STORE_ERROR(store->RetryTrial(1, 1, "x", 3, 0), K::kIllegalTransition);
  auto t = store->ClaimNextTrial("c");
  ASSERT_TRUE(t);
  // dispatched: no reset before the ground truth, no finish.
  EXPECT_STORE_ERROR(store->BeginReset(t->trial_id, 1), K::kIllegalTransition);
  EXPECT_STORE_ERROR(store->CompleteReset(t->trial_id, 1, ResetReport{}), K::kIllegalTransition);
  EXPECT_STORE_ERROR(store->FinishTrial(t->trial_id, 1), K::kIllegalTransition);
  // A stale attempt cannot move it.
  EXPECT_STORE_ERROR(store->FailTrial(t->trial_id, 2, "late"), K::kStaleAttempt);
  EXPECT_STORE_ERROR(store->FailTrial(99, 1, "x"), K::kNotFound);
  EXPECT_EQ(store->ListTransitions(t->trial_id).size(), 2u);
  store->FailTrial(t->trial_id, 1, "scene refused", arena::db::TrialEnd::kRefused);
  // failed is terminal.
  EXPECT_STORE_ERROR(store->FailTrial(t->trial_id, 1, "again"), K::kIllegalTransition);
  EXPECT_EQ(store->GetTrial(t->trial_id).outcome, arena::db::TrialEnd::kRefused);
  ExpectHealthy(*store);
}

TEST(StoreTrial, ClaimFollowsPriorityCapabilityAndHealth) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("points-only", {"point"});
  store->UpsertCell("all", {"point", "line", "patch"});
  const auto low = store->CreateCampaign(MakeCampaign("low", 0), MakeTrials(2));
  const auto high = store->CreateCampaign(MakeCampaign("high", 5), MakeTrials(2, "patch"));
  // The high-priority campaign needs patches: the point-only cell takes the low one.
  auto a = store->ClaimNextTrial("points-only");
  ASSERT_TRUE(a);
  EXPECT_EQ(a->campaign_id, low);
  auto peek = store->PeekNextTrial("all");
  auto b = store->ClaimNextTrial("all");
  ASSERT_TRUE(b && peek);
  EXPECT_EQ(b->campaign_id, high);
  EXPECT_EQ(peek->trial_id, b->trial_id);
  // Paused campaigns and quarantined cells get nothing.
  store->PauseCampaign(high);
  auto c = store->ClaimNextTrial("all");
  ASSERT_TRUE(c);
  EXPECT_EQ(c->campaign_id, low);
  store->QuarantineCell("all", "reset failed 3 times");
  store->ResumeCampaign(high);
  EXPECT_FALSE(store->ClaimNextTrial("all"));
  EXPECT_STORE_ERROR(store->ClaimNextTrial("nobody"), K::kNotFound);
  store->ReleaseCell("all");
  auto d = store->ClaimNextTrial("all");
  ASSERT_TRUE(d);
  EXPECT_EQ(d->campaign_id, high);
  EXPECT_FALSE(store->ClaimNextTrial("all"));
  ExpectHealthy(*store);
}

TEST(StoreTrial, RetryKeepsLineageBacksOffAndCaps) {
  TempDir dir;
  double now = 1000;
  StoreOptions o;
  o.clock = [&] { return now; };
  auto store = Store::Open(dir.File("s.db"), o);
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(1));
  auto t = store->ClaimNextTrial("c");
  EXPECT_EQ(store->RetryTrial(t->trial_id, 1, "deadline", 2, 10.0), TrialState::kPlanned);
  EXPECT_EQ(store->GetTrial(t->trial_id).attempt, 2);
  EXPECT_FALSE(store->ClaimNextTrial("c"));  // backing off
  now += 11;
  auto again = store->ClaimNextTrial("c");
  ASSERT_TRUE(again);
  EXPECT_EQ(again->attempt, 2);
  EXPECT_EQ(store->RetryTrial(t->trial_id, 2, "deadline", 2, 10.0), TrialState::kFailed);
  const auto log = store->ListTransitions(t->trial_id);
  ASSERT_EQ(log.size(), 5u);
  EXPECT_EQ(log[2].attempt, 1);
  EXPECT_EQ(log[2].to_state, "planned");
  EXPECT_EQ(log[3].attempt, 2);
  EXPECT_EQ(log[4].to_state, "failed");
  ExpectHealthy(*store);
}

// Issue 27: an attempt released before its cell ran it (an EXECUTE queued
// behind a reset that failed) runs again at once (no backoff), and the audit
// row names the rule.
TEST(StoreTrial, AReleasedAttemptIsNotCountedWaitsForNothingAndNamesItsRule) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(2));
  auto t = store->ClaimNextTrial("c");
  ASSERT_TRUE(t);
  EXPECT_STORE_ERROR(store->ReleaseTrial(t->trial_id, 2, "x", "queued.r"), K::kStaleAttempt);
  EXPECT_STORE_ERROR(store->ReleaseTrial(t->trial_id, 1, "x", ""), K::kBadInput);
  store->ReleaseTrial(t->trial_id, 1, "queued behind a failed reset", "queued.reset_failed");
  EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kPlanned);
  const auto log = store->ListTransitions(t->trial_id);
  ASSERT_EQ(log.size(), 3u);
  EXPECT_EQ(log[2].to_state, "planned");
  EXPECT_EQ(log[2].rule, "queued.reset_failed");
  EXPECT_NE(log[2].reason.find("not counted"), std::string::npos);
  auto again = store->ClaimNextTrial("c");  // at once: no backoff
  ASSERT_TRUE(again);
  EXPECT_EQ(again->trial_id, t->trial_id);
  EXPECT_EQ(again->attempt, 2);
  // Not counted: with max_attempts 2, attempts 2 and 3 are the two counted ones.
  EXPECT_EQ(store->RetryTrial(t->trial_id, 2, "deadline", 2, 0), TrialState::kPlanned);
  auto third = store->ClaimNextTrial("c");
  ASSERT_TRUE(third);
  EXPECT_EQ(third->attempt, 3);
  EXPECT_EQ(store->RetryTrial(t->trial_id, 3, "deadline", 2, 0), TrialState::kFailed);
  // Only a dispatched trial is released.
  auto other = store->ClaimNextTrial("c");
  ASSERT_TRUE(other);
  auto in = store->BeginIngest(other->trial_id, 1, testing::SceneSites());
  in->Add(MakeSample(0));
  in->Finish();
  EXPECT_STORE_ERROR(store->ReleaseTrial(other->trial_id, 1, "x", "queued.r"),
                     K::kIllegalTransition);
  ExpectHealthy(*store);
}

// Issue 27: the service's clean trial stores its prediction and `done` in one
// commit: both edges and both audit rows, or (refused) nothing at all.
TEST(StoreTrial, RecordPredictionAndFinishIsBothStepsOrNothing) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(2));
  auto t = store->ClaimNextTrial("c");
  auto ingest = store->BeginIngest(t->trial_id, 1, testing::SceneSites());
  ingest->Add(MakeSample(0));
  ingest->Finish();
  Prediction p;
  p.model_key = "k";
  // Executed, not reset: refused, nothing written.
  EXPECT_STORE_ERROR(store->RecordPredictionAndFinish(t->trial_id, 1, p), K::kIllegalTransition);
  EXPECT_TRUE(store->ListPredictions(t->trial_id).empty());
  EXPECT_EQ(store->Status().campaigns.at(0).awaiting_prediction, 1);
  store->BeginReset(t->trial_id, 1);
  ResetReport ok;
  ok.ok = true;
  ok.observed_pose = {0, 0, 0, 1, 0, 0, 0};
  store->CompleteReset(t->trial_id, 1, ok);
  EXPECT_EQ(store->Status().campaigns.at(0).awaiting_prediction, 1);
  // A stale attempt: refused, nothing written.
  EXPECT_STORE_ERROR(store->RecordPredictionAndFinish(t->trial_id, 2, p), K::kStaleAttempt);
  EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kResetDone);
  EXPECT_TRUE(store->ListPredictions(t->trial_id).empty());
  // A NaN in the prediction: refused before any write.
  Prediction nan = p;
  nan.final_position_error = std::nan("");
  EXPECT_STORE_ERROR(store->RecordPredictionAndFinish(t->trial_id, 1, nan), K::kBadInput);
  EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kResetDone);

  store->RecordPredictionAndFinish(t->trial_id, 1, p);
  EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kDone);
  EXPECT_EQ(store->ListPredictions(t->trial_id).size(), 1u);
  EXPECT_EQ(store->Status().campaigns.at(0).awaiting_prediction, 0);
  const auto log = store->ListTransitions(t->trial_id);
  ASSERT_GE(log.size(), 2u);
  EXPECT_EQ(log[log.size() - 2].to_state, "predicted");
  EXPECT_EQ(log[log.size() - 2].rule, "predict.recorded");
  EXPECT_EQ(log.back().to_state, "done");
  EXPECT_EQ(log.back().rule, "finish.predicted");
  // Done is terminal: a second one is refused.
  EXPECT_STORE_ERROR(store->RecordPredictionAndFinish(t->trial_id, 1, p), K::kIllegalTransition);
  EXPECT_EQ(store->ListPredictions(t->trial_id).size(), 1u);
  ExpectHealthy(*store);
}

TEST(StoreTrial, ResetFailureStillLetsTrialFinishAndRecordsStartState) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(4));
  auto t = store->ClaimNextTrial("c");
  auto ingest = store->BeginIngest(t->trial_id, 1, testing::SceneSites());
  ingest->Add(MakeSample(0));
  ingest->Finish();
  store->BeginReset(t->trial_id, 1);
  ResetReport bad;
  bad.ok = false;
  bad.reason = "object dropped";
  bad.observed_pose = {0.004, 0.003, 0, 1, 0, 0, 0};
  store->CompleteReset(t->trial_id, 1, bad);
  store->BeginReset(t->trial_id, 1);  // retry the reset
  ResetReport good;
  good.ok = true;
  good.observed_pose = {0.003, 0.004, 0, std::cos(0.05), 0, 0, std::sin(0.05)};
  store->CompleteReset(t->trial_id, 1, good);
  Prediction p;
  p.model_key = "k";
  store->RecordPrediction(t->trial_id, 1, p);
  store->FinishTrial(t->trial_id, 1);
  // The next trial on this cell starts where the reset left the object (until
  // its own stream says where its cell measured it); the first trial's start
  // is its stream's first sample, observed 0.5 mm off.
  auto next = store->ClaimNextTrial("c");
  ASSERT_TRUE(next);
  const auto drift = store->Drift();
  ASSERT_EQ(drift.size(), 1u);
  EXPECT_EQ(drift[0].cell_id, "c");
  EXPECT_EQ(drift[0].trials, 2);
  EXPECT_NEAR(drift[0].max_position_error, 0.005, 1e-12);
  EXPECT_NEAR(drift[0].mean_dx, (0.0005 + 0.003) / 2, 1e-12);
  EXPECT_NEAR(drift[0].max_angle_error, 0.1, 1e-9);
  const auto only_streams = [&] {
    const auto d = store->Drift();
    ASSERT_EQ(d.size(), 1u);
    EXPECT_NEAR(d[0].max_position_error, 0.0005, 1e-12);
    EXPECT_NEAR(d[0].max_angle_error, 0.0, 1e-12);
  };
  // The claim consumed the start state: a trial claimed without a reset in
  // between has none, and a reset that observed nothing leaves none.
  store->RetryTrial(next->trial_id, next->attempt, "cell lost", 3, 0);
  auto unknown = store->ClaimNextTrial("c");
  ASSERT_TRUE(unknown);
  // The retried attempt started from an unknown state: the first attempt's
  // observation (and its error) no longer describe the trial (issue 16, item 10).
  EXPECT_EQ(store->Drift()[0].trials, 1);
  only_streams();
  auto in = store->BeginIngest(unknown->trial_id, unknown->attempt, testing::SceneSites());
  in->Add(MakeSample(0));
  in->Finish();
  store->BeginReset(unknown->trial_id, unknown->attempt);
  ResetReport blind;
  blind.ok = false;
  blind.pose_observed = false;
  blind.observed_pose = {9, 9, 9, 1, 0, 0, 0};  // ignored
  blind.reason = "service restarted before the reset";
  store->CompleteReset(unknown->trial_id, unknown->attempt, blind);
  store->RecordPrediction(unknown->trial_id, unknown->attempt, p);
  store->FinishTrial(unknown->trial_id, unknown->attempt);
  ASSERT_TRUE(store->ClaimNextTrial("c"));
  // A blind reset observed nothing either; the retried attempt's stream did.
  EXPECT_EQ(store->Drift()[0].trials, 2);
  only_streams();
  ExpectHealthy(*store);
}

// Pins issue 26 item 4 in the store: a trial's start state was only the
// reset's observation copied at the claim, so a cell's first trial (and one
// whose cell's reset was aimed at another trial) had none though it ran.
// Publishing the stream now stores the start its cell measured: the first
// sample's observed pose, or the sample's own pose when the sensors dropped
// it (as a prediction starts), with its errors against the nominal start.
TEST(StoreTrial, PublishedStreamStoresTheStartItsCellMeasured) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(2));
  const auto column = [&](const char* name, std::int64_t id) {
    return RawScalar(dir.File("s.db"), std::string("SELECT ") + name +
                                           " FROM trials WHERE id = " + std::to_string(id));
  };
  const auto number = [&](const char* name, std::int64_t id) {
    return std::stod(column(name, id));
  };
  auto first = store->ClaimNextTrial("c");  // no reset before it
  ASSERT_TRUE(first);
  EXPECT_EQ(column("start_x", first->trial_id), "");
  auto ingest = store->BeginIngest(first->trial_id, first->attempt, testing::SceneSites());
  Sample seen = MakeSample(1);
  seen.observed_object_pose = {0.003, 0.004, 0, std::cos(0.05), 0, 0, std::sin(0.05)};
  ingest->Add(seen);
  ingest->Add(MakeSample(2));
  EXPECT_EQ(column("start_x", first->trial_id), "");  // not before the stream is published
  ingest->Finish();
  EXPECT_NEAR(number("start_x", first->trial_id), 0.003, 1e-15);
  EXPECT_NEAR(number("start_qz", first->trial_id), std::sin(0.05), 1e-15);
  EXPECT_NEAR(number("start_position_error", first->trial_id), 0.005, 1e-12);
  EXPECT_NEAR(number("start_angle_error", first->trial_id), 0.1, 1e-9);
  // The sensors dropped the first sample: the sample's own pose.
  auto second = store->ClaimNextTrial("c");
  ASSERT_TRUE(second);
  auto in = store->BeginIngest(second->trial_id, second->attempt, testing::SceneSites());
  Sample dropped = MakeSample(3);  // MakeSample(3) is a dropped observation
  ASSERT_FALSE(dropped.observed_valid);
  dropped.object_pose = {-0.002, 0, 0, 1, 0, 0, 0};
  in->Add(dropped);
  in->Finish();
  EXPECT_NEAR(number("start_x", second->trial_id), -0.002, 1e-15);
  EXPECT_NEAR(number("start_position_error", second->trial_id), 0.002, 1e-12);
  EXPECT_NEAR(number("start_angle_error", second->trial_id), 0.0, 1e-12);
  ExpectHealthy(*store);
}

TEST(StoreTrial, CancelPauseResume) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  const auto id = store->CreateCampaign(MakeCampaign(), MakeTrials(3));
  auto running = store->ClaimNextTrial("c");
  store->PauseCampaign(id);
  store->PauseCampaign(id);  // idempotent
  EXPECT_EQ(store->GetCampaign(id).state, CampaignState::kPaused);
  EXPECT_STORE_ERROR(store->PauseCampaign(42), K::kNotFound);
  store->CancelCampaign(id);
  EXPECT_STORE_ERROR(store->ResumeCampaign(id), K::kIllegalTransition);
  const auto trials = store->ListTrials(id);
  EXPECT_EQ(trials[0].state, TrialState::kDispatched);  // in flight: runs out
  EXPECT_EQ(trials[1].state, TrialState::kCancelled);
  EXPECT_EQ(trials[2].outcome, TrialEnd::kCancelled);
  RunTrialToDone(*store, *running, 10);
  ExpectHealthy(*store);
}

TEST(StoreTrial, RecoverAfterRestartRequeuesWithNextAttempt) {
  TempDir dir;
  const auto path = dir.File("s.db");
  std::int64_t dispatched = 0, resetting = 0, executed = 0;
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    store->CreateCampaign(MakeCampaign(), MakeTrials(4));
    auto a = store->ClaimNextTrial("c");
    auto b = store->ClaimNextTrial("c");
    auto c = store->ClaimNextTrial("c");
    dispatched = a->trial_id;
    resetting = b->trial_id;
    executed = c->trial_id;
    auto partial = store->BeginIngest(a->trial_id, 1, testing::SceneSites());  // dies half-way
    for (int i = 0; i < 600; ++i) partial->Add(MakeSample(i));
    partial->Flush();
    for (auto* t : {&*b, &*c}) {
      auto in = store->BeginIngest(t->trial_id, 1, testing::SceneSites());
      in->Add(MakeSample(0));
      in->Finish();
    }
    store->BeginReset(b->trial_id, 1);
    // "SIGKILL": the store goes away with the ingest unfinished (~Ingest writes
    // nothing, so destroying it is the same as a crash for the file).
  }
  auto store = Store::Open(path);
  EXPECT_EQ(RawScalar(path, "SELECT COUNT(*) FROM gt_streams WHERE complete = 0"), "1");
  const auto report = store->RecoverAfterRestart();
  EXPECT_EQ(report.requeued, std::vector<std::int64_t>{dispatched});
  EXPECT_EQ(report.reset_failed, std::vector<std::int64_t>{resetting});
  EXPECT_EQ(report.orphan_streams_deleted, 1);
  EXPECT_EQ(store->GetTrial(dispatched).state, TrialState::kPlanned);
  EXPECT_EQ(store->GetTrial(dispatched).attempt, 2);
  EXPECT_EQ(store->GetTrial(resetting).state, TrialState::kResetFailed);
  EXPECT_EQ(store->GetTrial(executed).state, TrialState::kExecuted);
  EXPECT_EQ(RawScalar(path, "SELECT COUNT(*) FROM gt_chunks"), "2");
  // Idempotent: a second recovery changes nothing.
  const auto second = store->RecoverAfterRestart();
  EXPECT_TRUE(second.requeued.empty());
  EXPECT_TRUE(second.reset_failed.empty());
  // The requeued trial runs again as attempt 2 and finishes once.
  auto again = store->ClaimNextTrial("c");
  ASSERT_TRUE(again);
  EXPECT_EQ(again->trial_id, dispatched);
  EXPECT_EQ(again->attempt, 2);
  RunTrialToDone(*store, *again, 50);
  EXPECT_EQ(store->ReadGroundTruth(dispatched).attempt, 2);
  EXPECT_EQ(store->ReadGroundTruth(dispatched).samples.size(), 50u);
  ExpectHealthy(*store);
}

TEST(StoreIngest, ReingestSameAttemptReplacesNeverDuplicates) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(1));
  auto t = store->ClaimNextTrial("c");
  {
    auto in = store->BeginIngest(t->trial_id, 1, testing::SceneSites(), IngestOptions{10, 25, 1.0});
    for (int i = 0; i < 100; ++i) in->Add(MakeSample(i));
    EXPECT_EQ(in->Finish(), 100);
  }
  {
    auto in = store->BeginIngest(t->trial_id, 1, testing::SceneSites(), IngestOptions{10, 25, 1.0});
    for (int i = 0; i < 80; ++i) in->Add(MakeSample(i + 1000));
    EXPECT_EQ(in->Finish(), 80);
  }
  EXPECT_EQ(RawScalar(store->path(), "SELECT COUNT(*) FROM gt_streams"), "1");
  EXPECT_EQ(RawScalar(store->path(), "SELECT COUNT(*) FROM gt_summary"), "1");
  EXPECT_EQ(RawScalar(store->path(), "SELECT SUM(samples) FROM gt_chunks"), "80");
  const auto gt = store->ReadGroundTruth(t->trial_id);
  ASSERT_EQ(gt.samples.size(), 80u);
  EXPECT_EQ(gt.samples[0].t, MakeSample(1000).t);
  // Still one executed transition only.
  EXPECT_EQ(store->ListTransitions(t->trial_id).size(), 3u);
  ExpectHealthy(*store);
}

// Finish with `also`: the execution record, the publish and the move to
// resetting in one transaction, each with its checks and audit row; a refusal
// of the last part leaves nothing of the others.
TEST(StoreIngest, FinishWithAlsoIsOneStepOfThreeAndAllOrNothing) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(1));
  auto t = store->ClaimNextTrial("c");
  FinishAlso also;
  also.execution = ExecutionRecord{"model", "simulator", "{}"};
  also.begin_reset_rule = "reset.after_execute";
  {
    auto in = store->BeginIngest(t->trial_id, 1, testing::SceneSites());
    for (int i = 0; i < 20; ++i) in->Add(MakeSample(i));
    EXPECT_EQ(in->Finish(TrialEnd::kOk, also), 20);
  }
  EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kResetting);
  EXPECT_EQ(RawScalar(store->path(), "SELECT backend || '/' || truth FROM trials"),
            "model/simulator");
  auto log = store->ListTransitions(t->trial_id);
  ASSERT_EQ(log.size(), 4u);
  EXPECT_EQ(log[2].to_state, "executed");
  EXPECT_EQ(log[3].to_state, "resetting");
  EXPECT_EQ(log[3].rule, "reset.after_execute");
  EXPECT_EQ(log[3].reason, "reset sent");
  // A re-ingest now in resetting: resetting -> resetting is no edge, so the
  // whole Finish is refused: the old stream stays, the record is not rewritten.
  also.execution = ExecutionRecord{"mujoco", "robot", "{}"};
  {
    auto in = store->BeginIngest(t->trial_id, 1, testing::SceneSites());
    for (int i = 0; i < 5; ++i) in->Add(MakeSample(i + 100));
    EXPECT_STORE_ERROR(in->Finish(TrialEnd::kOk, also), K::kIllegalTransition);
  }
  EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kResetting);
  EXPECT_EQ(RawScalar(store->path(), "SELECT backend FROM trials"), "model");
  EXPECT_EQ(store->ReadGroundTruth(t->trial_id).samples.size(), 20u);
  EXPECT_EQ(store->ListTransitions(t->trial_id).size(), 4u);
  ExpectHealthy(*store);
}

TEST(StoreIngest, NanInfAndOutOfOrderRefused) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(1));
  auto t = store->ClaimNextTrial("c");
  auto in = store->BeginIngest(t->trial_id, 1, testing::SceneSites());
  in->Add(MakeSample(0));
  auto nan = MakeSample(1);
  nan.object_pose[3] = std::numeric_limits<double>::quiet_NaN();
  try {
    in->Add(nan);
    ADD_FAILURE();
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), K::kBadInput);
    EXPECT_NE(std::string(e.what()).find("object_pose[3] is NaN"), std::string::npos) << e.what();
  }
  auto inf = MakeSample(1);
  inf.contacts[1].force[2] = std::numeric_limits<double>::infinity();
  EXPECT_STORE_ERROR(in->Add(inf), K::kBadInput);
  auto fw = MakeSample(1);
  fw.observed_finger_wrenches[5] = -std::numeric_limits<double>::infinity();
  EXPECT_STORE_ERROR(in->Add(fw), K::kBadInput);
  in->Add(MakeSample(5));
  EXPECT_STORE_ERROR(in->Add(MakeSample(4)), K::kBadInput);  // out of order
  EXPECT_EQ(in->Finish(), 2);
  Prediction p;
  p.model_key = "m";
  p.force_error = std::numeric_limits<double>::quiet_NaN();
  store->BeginReset(t->trial_id, 1);
  ResetReport r;
  r.ok = true;
  r.observed_pose[0] = std::numeric_limits<double>::infinity();
  EXPECT_STORE_ERROR(store->CompleteReset(t->trial_id, 1, r), K::kBadInput);
  r.observed_pose[0] = 0;
  store->CompleteReset(t->trial_id, 1, r);
  EXPECT_STORE_ERROR(store->RecordPrediction(t->trial_id, 1, p), K::kBadInput);
  EXPECT_EQ(RawScalar(store->path(), "SELECT COUNT(*) FROM predictions"), "0");
  EXPECT_EQ(RawScalar(store->path(), "SELECT SUM(samples) FROM gt_chunks"), "2");
  ExpectHealthy(*store);
}

TEST(StoreIngest, StaleAttemptStreamRefused) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(1));
  auto t = store->ClaimNextTrial("c");
  auto in = store->BeginIngest(t->trial_id, 1, testing::SceneSites());
  in->Add(MakeSample(0));
  store->RetryTrial(t->trial_id, 1, "cell lost", 3, 0);  // attempt 1 abandoned meanwhile
  EXPECT_STORE_ERROR(in->Finish(), K::kStaleAttempt);
  EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kPlanned);
  EXPECT_FALSE(store->GetTrial(t->trial_id).gt_stream_id.has_value());
  ExpectHealthy(*store);
}

TEST(StoreCells, HealthCounters) {
  TempDir dir;
  double now = 50;
  StoreOptions o;
  o.clock = [&] { return now; };
  auto store = Store::Open(dir.File("s.db"), o);
  store->UpsertCell("c", {"point", "line"}, R"({"max_pusher_speed": 0.1})");
  EXPECT_EQ(store->RecordCellResult("c", false), 1);
  EXPECT_EQ(store->RecordCellResult("c", false), 2);
  EXPECT_EQ(store->RecordCellResult("c", true), 0);
  EXPECT_EQ(store->RecordCellResult("c", false), 1);
  EXPECT_EQ(store->GetCell("c").total_failures, 3);
  now = 60;
  store->TouchCell("c");
  EXPECT_EQ(store->GetCell("c").last_seen, 60);
  store->MarkCellGone("c", "liveliness lost");
  EXPECT_EQ(store->GetCell("c").state, CellState::kGone);
  store->UpsertCell("c", {"point"});  // it came back
  EXPECT_EQ(store->GetCell("c").state, CellState::kHealthy);
  store->QuarantineCell("c", "3 failures");
  store->UpsertCell("c", {"point"});  // quarantine survives a re-announce
  EXPECT_EQ(store->GetCell("c").state, CellState::kQuarantined);
  EXPECT_EQ(store->GetCell("c").quarantine_reason, "3 failures");
  EXPECT_STORE_ERROR(store->UpsertCell("d", {"wheel"}), K::kBadInput);
  EXPECT_STORE_ERROR(store->TouchCell("nobody"), K::kNotFound);
}

TEST(StoreStatus, CountsRateAndEta) {
  TempDir dir;
  double now = 10000;
  StoreOptions o;
  o.clock = [&] { return now; };
  auto store = Store::Open(dir.File("s.db"), o);
  store->UpsertCell("c", {"point"});
  const auto id = store->CreateCampaign(MakeCampaign(), MakeTrials(6));
  for (int i = 0; i < 3; ++i) {
    auto t = store->ClaimNextTrial("c");
    now += 10;
    RunTrialToDone(*store, *t, 5);
  }
  auto t = store->ClaimNextTrial("c");
  store->FailTrial(t->trial_id, 1, "refused", arena::db::TrialEnd::kRefused);
  auto running = store->ClaimNextTrial("c");
  const auto s = store->Status();
  ASSERT_EQ(s.campaigns.size(), 1u);
  const auto& c = s.campaigns[0];
  EXPECT_EQ(c.id, id);
  EXPECT_EQ(c.planned, 6);
  EXPECT_EQ(c.done, 3);
  EXPECT_EQ(c.failed, 1);
  EXPECT_EQ(c.running, 1);
  EXPECT_EQ(c.pending, 1);
  // 4 finished in the 30 s since the first dispatch: 480 per hour; 2 left: 15 s.
  EXPECT_NEAR(c.rate_per_hour, 480, 1e-9);
  ASSERT_TRUE(c.eta_s);
  EXPECT_NEAR(*c.eta_s, 15, 1e-9);
  ASSERT_EQ(s.cells.size(), 1u);
  EXPECT_EQ(s.cells[0].id, "c");
  EXPECT_EQ(s.drift.size(), 1u);
}

TEST(StoreFaults, FullStoreRefusesWriteAndKeepsEarlierTrials) {
  TempDir dir;
  StoreOptions small;
  small.max_pages = 400;  // 1.6 MB: room for a couple of trials of raw ground truth
  IngestOptions raw;
  raw.pack_chunks = false;  // MakeSample's regular values would pack ~35x and never fill it
  auto store = Store::Open(dir.File("full.db"), small);
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(20));
  int done = 0;
  bool full = false;
  while (!full) {
    auto t = store->ClaimNextTrial("c");
    ASSERT_TRUE(t) << "the store never filled up";
    try {
      RunTrialToDone(*store, *t, 1000, raw);
      ++done;
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), K::kFull) << e.what();
      EXPECT_NE(std::string(e.what()).find("free disk space"), std::string::npos) << e.what();
      full = true;
      // The trial that hit the limit is still dispatched, without ground truth.
      EXPECT_EQ(store->GetTrial(t->trial_id).state, TrialState::kDispatched);
      EXPECT_FALSE(store->GetTrial(t->trial_id).gt_stream_id.has_value());
    }
  }
  EXPECT_GE(done, 1);
  // Every finished trial is intact; the file is consistent; a restart recovers.
  for (const auto& t : store->ListTrials(1)) {
    if (t.state == TrialState::kDone) {
      EXPECT_EQ(store->ReadGroundTruth(t.id).samples.size(), 1000u);
    }
  }
  store.reset();
  auto again = Store::Open(dir.File("full.db"));  // no limit now: the disk "was freed"
  const auto report = again->RecoverAfterRestart();
  EXPECT_EQ(report.requeued.size(), 1u);
  ExpectHealthy(*again);
}

// What a write-protected store must do: refuse a writing open with
// kReadOnly, and still be read. @returns "" or what went wrong.
std::string CheckWriteProtected(const std::string& path) {
  try {
    Store::Open(path);
    return "a writing open succeeded";
  } catch (const StoreError& e) {
    if (e.kind() != K::kReadOnly) return std::string("wrong kind: ") + e.what();
  }
  StoreOptions ro;
  ro.read_only = true;
  if (Store::Open(path, ro)->ListCampaigns().size() != 1u) return "reading failed";
  return "";
}

// A file without write permission. Root ignores file permissions, so as
// root (how CI runs) the file is not write-protected: that case is the
// read-only file system below.
TEST(StoreFaults, WriteProtectedFileIsRefusedClearly) {
  TempDir dir;
  const auto path = dir.File("ro.db");
  Store::Open(path)->CreateCampaign(MakeCampaign(), MakeTrials(1));
  std::filesystem::permissions(
      path, std::filesystem::perms::owner_read | std::filesystem::perms::group_read);
  if (::geteuid() == 0) GTEST_SKIP() << "root ignores file permissions (see ReadOnlyFileSystem)";
  EXPECT_EQ(CheckWriteProtected(path), "");
}

// The store's directory bind-mounted read-only, in a mount namespace of a
// child process's own (nothing outside it sees the mount): the path of
// schema.cpp that refuses a write-protected store runs as root too. Skips,
// saying why, only where the process may not mount (no CAP_SYS_ADMIN).
TEST(StoreFaults, StoreOnAReadOnlyFileSystemIsRefusedClearly) {
  TempDir dir;
  const std::string sub = dir.File("mnt");
  std::filesystem::create_directories(sub);
  const std::string path = sub + "/ro.db";
  Store::Open(path)->CreateCampaign(MakeCampaign(), MakeTrials(1));
  int pipe_fd[2];
  ASSERT_EQ(::pipe(pipe_fd), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(pipe_fd[0]);
    auto reply = [&](int code, const std::string& text) {
      [[maybe_unused]] auto n = ::write(pipe_fd[1], text.data(), text.size());
      ::_exit(code);
    };
    if (::unshare(CLONE_NEWNS) != 0) reply(77, std::string("unshare: ") + std::strerror(errno));
    if (::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0)
      reply(77, std::string("make / private: ") + std::strerror(errno));
    if (::mount(sub.c_str(), sub.c_str(), nullptr, MS_BIND, nullptr) != 0)
      reply(77, std::string("bind mount: ") + std::strerror(errno));
    if (::mount(nullptr, sub.c_str(), nullptr, MS_REMOUNT | MS_BIND | MS_RDONLY, nullptr) != 0)
      reply(77, std::string("remount read-only: ") + std::strerror(errno));
    const std::string problem = CheckWriteProtected(path);
    reply(problem.empty() ? 0 : 1, problem);
  }
  ::close(pipe_fd[1]);
  std::string text;
  char buf[512];
  for (ssize_t n; (n = ::read(pipe_fd[0], buf, sizeof buf)) > 0;) text.append(buf, n);
  ::close(pipe_fd[0]);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status)) << "the child died: " << text;
  if (WEXITSTATUS(status) == 77) GTEST_SKIP() << "cannot make a read-only mount here: " << text;
  EXPECT_EQ(WEXITSTATUS(status), 0) << text;
  // The mount was the child's alone: the store is writable again out here.
  EXPECT_NO_THROW(Store::Open(path)->ListCampaigns());
}

TEST(StoreCampaign, PauseReasonAndTrialsByState) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  const auto id = store->CreateCampaign(MakeCampaign(), MakeTrials(3));
  store->PauseCampaign(id, "suspended: 3 reset failures in a row");
  EXPECT_EQ(store->GetCampaign(id).state_reason, "suspended: 3 reset failures in a row");
  store->ResumeCampaign(id);
  EXPECT_EQ(store->GetCampaign(id).state_reason, "");
  auto t = store->ClaimNextTrial("c");
  const auto running = store->ListTrialsByState({TrialState::kDispatched, TrialState::kResetting});
  ASSERT_EQ(running.size(), 1u);
  EXPECT_EQ(running[0].id, t->trial_id);
  EXPECT_TRUE(running[0].dispatched_at.has_value());
  EXPECT_FALSE(running[0].finished_at.has_value());
  EXPECT_EQ(store->ListTrialsByState({TrialState::kPlanned}).size(), 2u);
}

TEST(StoreEvaluation, RunStoredWithResultsOnlyForDoneTrialsAndStatesUntouched) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("cell-1", {"point", "line", "patch"});
  const auto cid = store->CreateCampaign(MakeCampaign(), MakeTrials(2));
  const auto other = store->CreateCampaign(MakeCampaign("other"), MakeTrials(1));
  auto first = store->ClaimNextTrial("cell-1");
  ASSERT_TRUE(first);
  RunTrialToDone(*store, *first, 50);
  auto second = store->ClaimNextTrial("cell-1");  // stays dispatched
  ASSERT_TRUE(second);
  ASSERT_EQ(second->campaign_id, cid);
  const auto transitions_before = store->ListTransitions(first->trial_id).size();

  auto result = [](std::int64_t trial, const std::string& key, double err) {
    EvaluationResult r;
    r.trial_id = trial;
    r.attempt = 1;
    r.prediction.model_key = key;
    r.prediction.final_position_error = err;
    r.prediction.wall_s = 0.01;
    return r;
  };
  const auto id = store->RecordEvaluation(
      cid, R"({"facets":[4,8]})", R"({"recommended":"g8"})",
      {result(first->trial_id, "g4", 0.002), result(first->trial_id, "g8", 0.001)});
  const auto runs = store->ListEvaluations(cid);
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].id, id);
  EXPECT_EQ(runs[0].report_json, R"({"recommended":"g8"})");
  EXPECT_EQ(store->GetEvaluation(id).settings_json, R"({"facets":[4,8]})");
  const auto rows = store->ListEvaluationResults(id);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].prediction.model_key, "g4");
  EXPECT_EQ(*rows[1].prediction.final_position_error, 0.001);
  // The trial's own prediction and state machine are untouched.
  EXPECT_EQ(store->ListPredictions(first->trial_id).size(), 1u);
  EXPECT_EQ(store->ListTransitions(first->trial_id).size(), transitions_before);

  // Refused, and nothing written: a trial not done, of another campaign, a
  // stale attempt, a duplicate key, a NaN, an unknown campaign.
  const auto other_trial = store->ListTrials(other).at(0).id;
  EXPECT_STORE_ERROR(store->RecordEvaluation(cid, "{}", "{}", {result(second->trial_id, "g4", 0)}),
                     K::kIllegalTransition);
  EXPECT_STORE_ERROR(store->RecordEvaluation(cid, "{}", "{}", {result(other_trial, "g4", 0)}),
                     K::kBadInput);
  auto stale = result(first->trial_id, "g4", 0);
  stale.attempt = 2;
  EXPECT_STORE_ERROR(store->RecordEvaluation(cid, "{}", "{}", {stale}), K::kStaleAttempt);
  EXPECT_STORE_ERROR(
      store->RecordEvaluation(cid, "{}", "{}",
                              {result(first->trial_id, "g4", 0), result(first->trial_id, "g4", 1)}),
      K::kBadInput);
  EXPECT_STORE_ERROR(
      store->RecordEvaluation(cid, "{}", "{}", {result(first->trial_id, "g4", std::nan(""))}),
      K::kBadInput);
  EXPECT_STORE_ERROR(store->RecordEvaluation(999, "{}", "{}", {}), K::kNotFound);
  EXPECT_STORE_ERROR(store->RecordEvaluation(cid, "[1]", "{}", {}), K::kBadInput);
  EXPECT_STORE_ERROR(store->GetEvaluation(999), K::kNotFound);
  EXPECT_EQ(store->ListEvaluations(cid).size(), 1u);
  EXPECT_EQ(RawScalar(store->path(), "SELECT COUNT(*) FROM evaluation_results"), "2");
  ExpectHealthy(*store);
}

}  // namespace
}  // namespace arena::db

namespace arena::db {
namespace {

// Issue 16: one transaction for the whole campaign; a throw leaves nothing.
TEST(StoreCampaign, StreamedCreateIsOneTransaction) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  int chunks = 0;
  EXPECT_THROW(store->CreateCampaign(MakeCampaign("half"),
                                     [&]() -> std::vector<PlannedTrial> {
                                       if (++chunks == 3) throw std::runtime_error("interrupted");
                                       return testing::MakeTrials(4);
                                     }),
               std::runtime_error);
  EXPECT_TRUE(store->ListCampaigns().empty());
  chunks = 0;
  const auto id = store->CreateCampaign(MakeCampaign("whole"), [&]() -> std::vector<PlannedTrial> {
    return ++chunks <= 3 ? testing::MakeTrials(4) : std::vector<PlannedTrial>{};
  });
  const auto trials = store->ListTrials(id);
  ASSERT_EQ(trials.size(), 12u);
  EXPECT_EQ(trials.back().index, 11);
  ExpectHealthy(*store);
}

// Issue 16 item 4: attempts a service restart cut short do not count.
TEST(StoreTrial, RestartsDoNotCountAgainstMaxAttempts) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(1));
  for (int k = 0; k < 3; ++k) {
    ASSERT_TRUE(store->ClaimNextTrial("c"));
    store->RecoverAfterRestart();
  }
  auto t = store->ClaimNextTrial("c");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->attempt, 4);
  EXPECT_EQ(store->RetryTrial(t->trial_id, 4, "deadline", 3, 0), TrialState::kPlanned);
  t = store->ClaimNextTrial("c");
  EXPECT_EQ(store->RetryTrial(t->trial_id, 5, "deadline", 3, 0), TrialState::kPlanned);
  t = store->ClaimNextTrial("c");
  EXPECT_EQ(store->RetryTrial(t->trial_id, 6, "deadline", 3, 0), TrialState::kFailed);
  ExpectHealthy(*store);
}

// Issue 16 item 10: a retried attempt without an observed start has no start error.
TEST(StoreTrial, RetriedAttemptDropsThePreviousStartError) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(2));
  RunTrialToDone(*store, *store->ClaimNextTrial("c"), 10);  // its reset leaves a start
  auto t = store->ClaimNextTrial("c");
  ASSERT_TRUE(t);
  const std::string q =
      "SELECT start_position_error FROM trials WHERE id = " + std::to_string(t->trial_id);
  EXPECT_NE(RawScalar(dir.File("s.db"), q), "");
  store->RetryTrial(t->trial_id, t->attempt, "deadline", 3, 0);
  ASSERT_TRUE(store->ClaimNextTrial("c"));  // no reset since: nothing observed
  EXPECT_EQ(RawScalar(dir.File("s.db"), q), "");
}

// Two cells that expect the same next trial: one takes it, and the other's
// observed start (prepared for that trial) is not charged to the trial it
// claims instead; a reset aimed at the trial claimed is.
TEST(StoreTrial, AnObservedStartGoesOnlyToTheTrialItsResetWasAimedAt) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("a", {"point"});
  store->UpsertCell("b", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(4));
  const auto reset_aimed_at = [&](const ClaimedTrial& t, std::int64_t aim) {
    auto ingest = store->BeginIngest(t.trial_id, t.attempt, testing::SceneSites());
    for (int i = 0; i < 10; ++i) ingest->Add(MakeSample(i));
    ingest->Finish();
    store->BeginReset(t.trial_id, t.attempt);
    ResetReport r;
    r.ok = true;
    r.observed_pose = {0.002, -0.001, 0, 1, 0, 0, 0};
    r.aimed_at_trial = aim;
    store->CompleteReset(t.trial_id, t.attempt, r);
  };
  const auto start_x = [&](std::int64_t id) {
    return RawScalar(dir.File("s.db"),
                     "SELECT start_x FROM trials WHERE id = " + std::to_string(id)) +
           "|" +
           RawScalar(dir.File("s.db"),
                     "SELECT start_position_error FROM trials WHERE id = " + std::to_string(id));
  };
  const auto first = store->ClaimNextTrial("a");
  ASSERT_TRUE(first);
  const auto expected_next = store->PeekNextTrial("a");
  ASSERT_TRUE(expected_next);
  reset_aimed_at(*first, expected_next->trial_id);
  const auto taken_by_b = store->ClaimNextTrial("b");  // b takes the trial a's reset prepared
  ASSERT_TRUE(taken_by_b);
  EXPECT_EQ(taken_by_b->trial_id, expected_next->trial_id);
  const auto other = store->ClaimNextTrial("a");
  ASSERT_TRUE(other);
  EXPECT_EQ(start_x(other->trial_id), "|");  // a's start was prepared for another trial
  // Aimed at the trial it then claims: charged, error against that trial's nominal pose.
  reset_aimed_at(*other, other->trial_id + 1);
  const auto aimed = store->ClaimNextTrial("a");
  ASSERT_TRUE(aimed);
  ASSERT_EQ(aimed->trial_id, other->trial_id + 1);
  EXPECT_NE(start_x(aimed->trial_id), "|");
  EXPECT_EQ(RawScalar(dir.File("s.db"), "SELECT start_for_trial FROM cells WHERE id = 'a'"), "");
}

TEST(StoreServices, OneServicePerStoreHeartbeatAndStop) {
  TempDir dir;
  double now = 100;
  StoreOptions o;
  o.clock = [&] { return now; };
  auto store = Store::Open(dir.File("s.db"), o);
  EXPECT_EQ(store->StoreId().size(), 16u);
  EXPECT_FALSE(store->LatestService());
  const ServiceRecord a{"aaaa", 11, "lab1", 42, 0, 0, {}};
  const ServiceRecord b{"bbbb", 22, "lab1", 42, 0, 0, {}};
  const auto alive = [](const ServiceRecord&) { return true; };
  EXPECT_FALSE(store->RegisterService(a, 15, alive));
  const auto holder = store->RegisterService(b, 15, alive);
  ASSERT_TRUE(holder);
  EXPECT_EQ(holder->pid, 11);
  EXPECT_EQ(holder->host, "lab1");
  // A dead holder (its pid gone on this host) does not hold the store.
  EXPECT_FALSE(store->RegisterService(b, 15, [](const ServiceRecord&) { return false; }));
  now = 200;  // a's beat is old anyway; b beats
  store->UpsertCell("c", {"point"});
  store->ServiceBeat("bbbb", {"c"});
  EXPECT_EQ(store->LatestService()->last_beat, 200);
  EXPECT_EQ(store->GetCell("c").last_seen, 200);
  store->ServiceStopped("bbbb");
  EXPECT_TRUE(store->LatestService()->stopped_at);
  EXPECT_FALSE(store->RegisterService(ServiceRecord{"cccc", 33, "lab2", 1, 0, 0, {}}, 15, alive));
}

TEST(StoreCells, ReleaseIsAuditedAndStatusShowsSilentCellsGone) {
  TempDir dir;
  double now = 100;
  StoreOptions o;
  o.clock = [&] { return now; };
  auto store = Store::Open(dir.File("s.db"), o);
  store->UpsertCell("c", {"point"});
  store->SetCellServing("c", 10, "");
  store->QuarantineCell("c", "3 failures");
  store->ReleaseCell("c", "pads replaced", "ana@lab1");
  EXPECT_EQ(store->GetCell("c").state, CellState::kHealthy);
  const auto events = store->ListCellEvents("c");
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1].event, "released");
  EXPECT_EQ(events[1].by_whom, "ana@lab1");
  EXPECT_EQ(events[1].reason, "pads replaced");
  EXPECT_EQ(store->Status().cells[0].state, CellState::kHealthy);
  now = 111;  // no sign for longer than its 10 s lease
  EXPECT_EQ(store->Status().cells[0].state, CellState::kGone);
  store->SetCellServing("c", 10, "serving service ab on host h (pid 1)");
  EXPECT_EQ(store->GetCell("c").serving, "serving service ab on host h (pid 1)");
}

TEST(StoreFaults, AStoreFileDeletedRenamedOrReplacedIsNoticed) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->CheckFileIdentity();
  std::filesystem::rename(dir.File("s.db"), dir.File("t.db"));
  EXPECT_STORE_ERROR(store->CheckFileIdentity(), K::kIo);
  { std::ofstream(dir.File("s.db")) << "x"; }  // another file under the name
  EXPECT_STORE_ERROR(store->CheckFileIdentity(), K::kIo);
}

// Issue 27: a store whose checkpoints another thread runs. Its commits past
// the due size ask for one (and copy nothing into the database file
// themselves); CheckpointWal() on a second connection copies the frames,
// after which the writer starts the WAL over; a checkpointer that never
// comes leaves the WAL bounded by the writer's own backstop (4 x due).
std::uintmax_t WalBytes(const std::string& db_path) {
  std::error_code ec;
  const auto n = std::filesystem::file_size(db_path + "-wal", ec);
  return ec ? 0 : n;
}

TEST(StoreWal, CommitsPastTheDueSizeAskForACheckpointThatAnotherConnectionRuns) {
  TempDir dir;
  const auto path = dir.File("a.db");
  int asked = 0;
  StoreOptions o;
  o.wal_autocheckpoint_bytes = 65536;  // 8 frames of 8 KiB pages
  o.wal_checkpoint_due = [&asked] { ++asked; };
  auto writer = Store::Open(path, o);
  RawScalar(path, "PRAGMA wal_checkpoint(TRUNCATE)");  // the schema's frames out of the way
  const auto db_bytes_before = std::filesystem::file_size(path);
  for (int i = 0; i < 200 && asked == 0; ++i)
    writer->UpsertCell(std::string("c").append(std::to_string(i)), {"point"}, "{}", "{}");
  ASSERT_GT(asked, 0) << "no commit asked for a checkpoint";
  EXPECT_GE(WalBytes(path), 65536u);
  // Nothing was copied into the database file by the writer's commits.
  EXPECT_EQ(std::filesystem::file_size(path), db_bytes_before);

  StoreOptions reader_options;
  reader_options.create = false;
  auto checkpointer = Store::Open(path, reader_options);
  EXPECT_GT(checkpointer->CheckpointWal(), 0);
  // The WAL starts over: more commits of the same size keep the file's size.
  const auto wal_after = WalBytes(path);
  for (int i = 0; i < 3; ++i) writer->UpsertCell("c0", {"point"}, "{}", "{}");
  EXPECT_EQ(WalBytes(path), wal_after);
  EXPECT_EQ(checkpointer->ListCells().size(), writer->ListCells().size());
  ExpectHealthy(*checkpointer);
}

TEST(StoreWal, WithNoCheckpointerTheWritersBackstopBoundsTheWal) {
  TempDir dir;
  const auto path = dir.File("a.db");
  int asked = 0;
  StoreOptions o;
  o.wal_autocheckpoint_bytes = 65536;
  o.wal_checkpoint_due = [&asked] {
    ++asked;
    throw std::runtime_error("a callback that throws fails no commit");
  };
  auto writer = Store::Open(path, o);
  RawScalar(path, "PRAGMA wal_checkpoint(TRUNCATE)");  // the schema's frames out of the way
  std::uintmax_t largest = 0;
  for (int i = 0; i < 2000; ++i) {
    writer->UpsertCell(std::string("c").append(std::to_string(i % 50)), {"point"},
                       std::string(R"({"k": )").append(std::to_string(i)).append("}"), "{}");
    largest = std::max(largest, WalBytes(path));
  }
  EXPECT_GT(asked, 0);
  // 4 x 64 KiB, plus one commit's frames and the WAL header.
  EXPECT_LE(largest, 4u * 65536u + 8u * (8192u + 24u) + 32u);
  EXPECT_EQ(writer->ListCells().size(), 50u);
  ExpectHealthy(*writer);
}

}  // namespace
}  // namespace arena::db
