// SIGKILL a process that is writing the store, at seeded random moments, and
// check what the store promises (db/README.md "What survives which crash"):
// the file is intact, every published trial is complete, recovery re-queues
// exactly the interrupted trials, and no trial is ever done twice.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <random>
#include <thread>

#include "arena/db/query.hpp"
#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeSample;
using testing::MakeTrials;
using testing::RunTrialToDone;
using testing::TempDir;

// The child: a tiny "service" that runs trials until it is killed.
[[noreturn]] void WriteForever(const std::string& path) {
  try {
    auto store = Store::Open(path);
    store->RecoverAfterRestart();
    while (auto t = store->ClaimNextTrial("c")) {
      auto in = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites(),
                                   IngestOptions{50, 200, 10.0});
      for (int i = 0; i < 1500; ++i) in->Add(MakeSample(i));
      in->Finish();
      store->BeginReset(t->trial_id, t->attempt);
      ResetReport r;
      r.ok = true;
      store->CompleteReset(t->trial_id, t->attempt, r);
      Prediction p;
      p.model_key = "m";
      store->RecordPrediction(t->trial_id, t->attempt, p);
      store->FinishTrial(t->trial_id, t->attempt);
    }
  } catch (...) {
    ::_exit(3);
  }
  ::_exit(0);
}

std::int64_t Scalar(const Store& ro, const std::string& sql) {
  return std::get<std::int64_t>(RunQuery(ro, sql).rows.at(0).at(0));
}

TEST(StoreCrash, SigkillWhileWritingLosesNothingCommitted) {
  TempDir dir;
  const auto path = dir.File("crash.db");
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    // Enough trials that the writer never runs out within the 12 rounds (packed
    // chunks made ingest fast enough to finish 400 before the kills came).
    store->CreateCampaign(MakeCampaign(), MakeTrials(6000));
  }
  std::mt19937 rng(2026);
  int kills = 0, finished_early = 0;
  for (int round = 0; round < 12; ++round) {
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) WriteForever(path);
    std::this_thread::sleep_for(std::chrono::milliseconds(30 + rng() % 250));
    int status = 0;
    if (::waitpid(pid, &status, WNOHANG) == 0) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      ++kills;
    } else {
      ++finished_early;
    }
    // What a restarted service would see.
    StoreOptions ro;
    ro.read_only = true;
    auto reader = Store::Open(path, ro);
    ASSERT_EQ(reader->IntegrityCheck(), "ok") << "round " << round;
    EXPECT_EQ(Scalar(*reader,
                     "SELECT COUNT(*) FROM trials WHERE state IN ('executed','resetting',"
                     "'reset_done','reset_failed','predicted','done') AND gt_stream_id IS NULL"),
              0);
    for (const auto& t : reader->ListTrialsByState({TrialState::kDone})) {
      ASSERT_EQ(reader->ReadGroundTruth(t.id).samples.size(), 1500u) << "trial " << t.id;
    }
    auto writer = Store::Open(path);
    const auto dispatched_before = writer->ListTrialsByState({TrialState::kDispatched}).size();
    const auto report = writer->RecoverAfterRestart();
    EXPECT_EQ(report.requeued.size(), dispatched_before);
    const auto v = writer->CheckInvariants();
    EXPECT_TRUE(v.empty()) << v.front();
    // No trial finished twice, no attempt published twice.
    EXPECT_EQ(Scalar(*reader,
                     "SELECT COUNT(*) FROM (SELECT trial_id FROM trial_transitions"
                     " WHERE to_state = 'done' GROUP BY trial_id HAVING COUNT(*) > 1)"),
              0);
    EXPECT_EQ(Scalar(*reader,
                     "SELECT COUNT(*) FROM (SELECT trial_id, attempt FROM gt_streams"
                     " WHERE complete = 1 GROUP BY trial_id, attempt HAVING COUNT(*) > 1)"),
              0);
  }
  EXPECT_GT(kills, 6);
  StoreOptions ro;
  ro.read_only = true;
  auto reader = Store::Open(path, ro);
  const auto done = reader->ListTrialsByState({TrialState::kDone}).size();
  EXPECT_GT(done, 0u);
  std::printf("[ crash ] %d SIGKILLs, %d clean exits, %zu trials done, store consistent\n", kills,
              finished_early, done);
}

}  // namespace
}  // namespace arena::db
