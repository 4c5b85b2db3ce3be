// Several connections on one file: claims are atomic, readers never see a
// half-written trial, a WAL reader never blocks the writer. Every wait is bounded.
#include <sqlite3.h>

#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <thread>

#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeSample;
using testing::MakeTrials;
using testing::RunTrialToDone;
using testing::TempDir;

// Two threads, each with its own connection, claim from the same campaign
// until it is empty: every trial is claimed exactly once.
TEST(StoreConcurrency, ClaimIsAtomicAcrossConnections) {
  TempDir dir;
  const auto path = dir.File("claim.db");
  constexpr int kTrials = 200;
  {
    auto store = Store::Open(path);
    store->UpsertCell("a", {"point"});
    store->UpsertCell("b", {"point"});
    store->CreateCampaign(MakeCampaign(), MakeTrials(kTrials));
  }
  std::mutex mu;
  std::multiset<std::int64_t> claimed;
  auto worker = [&](const std::string& cell) {
    auto store = Store::Open(path);
    std::vector<std::int64_t> mine;
    while (auto t = store->ClaimNextTrial(cell)) mine.push_back(t->trial_id);
    std::lock_guard<std::mutex> lock(mu);
    claimed.insert(mine.begin(), mine.end());
  };
  std::thread a(worker, "a"), b(worker, "b");
  a.join();
  b.join();
  EXPECT_EQ(claimed.size(), static_cast<std::size_t>(kTrials));
  EXPECT_EQ(std::set<std::int64_t>(claimed.begin(), claimed.end()).size(),
            static_cast<std::size_t>(kTrials));
  auto store = Store::Open(path);
  const auto s = store->Status();
  EXPECT_EQ(s.campaigns.at(0).running, kTrials);
  EXPECT_EQ(s.campaigns.at(0).pending, 0);
  EXPECT_TRUE(store->CheckInvariants().empty());
}

// A writer ingests trials in many small commits while a reader polls: any
// trial the reader sees as having ground truth has all of it, sample for sample.
TEST(StoreConcurrency, ReaderNeverSeesHalfWrittenTrial) {
  TempDir dir;
  const auto path = dir.File("gt.db");
  constexpr int kTrials = 12;
  std::mt19937 rng(7);  // seeded: sample counts differ per trial
  std::vector<int> counts;
  for (int i = 0; i < kTrials; ++i) counts.push_back(100 + static_cast<int>(rng() % 700));
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    store->CreateCampaign(MakeCampaign(), MakeTrials(kTrials));
  }
  std::atomic<bool> writer_done{false};
  std::atomic<int> checks{0}, complete_seen{0};
  std::string reader_error;
  std::thread reader([&] {
    StoreOptions ro;
    ro.read_only = true;
    auto store = Store::Open(path, ro);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
      const bool last_round = writer_done.load();
      for (const auto& t : store->ListTrials(1)) {
        if (!t.gt_stream_id) continue;
        const auto gt = store->ReadGroundTruth(t.id);
        const int expected = counts[static_cast<std::size_t>(t.index)];
        if (static_cast<int>(gt.samples.size()) != expected) {
          reader_error = "trial " + std::to_string(t.id) + ": " +
                         std::to_string(gt.samples.size()) + " samples visible, expected " +
                         std::to_string(expected);
          return;
        }
        for (int i = 0; i < expected; i += 37) {
          if (gt.samples[static_cast<std::size_t>(i)].t != MakeSample(i).t) {
            reader_error =
                "trial " + std::to_string(t.id) + " sample " + std::to_string(i) + " wrong";
            return;
          }
        }
        ++complete_seen;
      }
      ++checks;
      if (last_round) return;
    }
    reader_error = "reader timed out";
  });
  {
    auto store = Store::Open(path);
    IngestOptions small{25, 50, 10.0};  // many commits per trial: many chances to see a partial one
    while (auto t = store->ClaimNextTrial("c")) {
      auto in = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites(), small);
      const int n = counts[static_cast<std::size_t>(store->GetTrial(t->trial_id).index)];
      for (int i = 0; i < n; ++i) in->Add(MakeSample(i));
      in->Finish();
    }
  }
  writer_done = true;
  reader.join();
  EXPECT_EQ(reader_error, "");
  EXPECT_GT(checks.load(), 1);
  EXPECT_GE(complete_seen.load(), kTrials);  // the last round saw every trial complete
}

// A reader holding an open read transaction (a long export) does not stop
// the writer: with WAL the writer commits at once, and the reader keeps its snapshot.
TEST(StoreConcurrency, WalReaderDoesNotBlockWriter) {
  TempDir dir;
  const auto path = dir.File("wal.db");
  StoreOptions quick;
  quick.busy_timeout_ms = 200;  // a blocked writer would fail fast
  auto writer = Store::Open(path, quick);
  writer->UpsertCell("c", {"point"});
  writer->CreateCampaign(MakeCampaign(), MakeTrials(5));

  sqlite3* reader = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &reader, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(reader, "BEGIN", nullptr, nullptr, nullptr), SQLITE_OK);
  auto count_planned = [&] {
    sqlite3_stmt* s = nullptr;
    sqlite3_prepare_v2(reader, "SELECT COUNT(*) FROM trials WHERE state = 'planned'", -1, &s,
                       nullptr);
    sqlite3_step(s);
    const int n = sqlite3_column_int(s, 0);
    sqlite3_finalize(s);
    return n;
  };
  EXPECT_EQ(count_planned(), 5);  // the snapshot starts here

  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 5; ++i) {
    auto t = writer->ClaimNextTrial("c");
    ASSERT_TRUE(t);
    RunTrialToDone(*writer, *t, 100);
  }
  const double writer_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(writer_s, 5.0);
  EXPECT_EQ(count_planned(), 5);  // still the old snapshot: isolation
  sqlite3_exec(reader, "COMMIT", nullptr, nullptr, nullptr);
  EXPECT_EQ(count_planned(), 0);  // a new snapshot sees the writes
  sqlite3_close(reader);
  EXPECT_EQ(writer->IntegrityCheck(), "ok");
}

// SetBusyTimeout applies from now on: with another connection holding the
// write lock, a store opened patient (5 s) and then made impatient gives up
// with kBusy instead of waiting (the service relies on it to keep its loop
// responsive); a negative timeout is refused with the field named.
TEST(StoreConcurrency, SetBusyTimeoutMakesAWriterGiveUpOnAForeignLock) {
  TempDir dir;
  const auto path = dir.File("busy.db");
  auto store = Store::Open(path);
  store->UpsertCell("c", {"point"});
  sqlite3* other = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &other, SQLITE_OPEN_READWRITE, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(other, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr), SQLITE_OK);
  store->SetBusyTimeout(10);
  try {
    store->UpsertCell("d", {"point"});
    ADD_FAILURE() << "a write under a foreign lock succeeded";
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), StoreError::Kind::kBusy) << e.what();
  }
  sqlite3_exec(other, "ROLLBACK", nullptr, nullptr, nullptr);
  sqlite3_close(other);
  store->UpsertCell("d", {"point"});  // the lock is gone: the same write goes through
  EXPECT_EQ(store->ListCells().size(), 2u);
  try {
    store->SetBusyTimeout(-1);
    ADD_FAILURE() << "a negative busy timeout was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("busy timeout"), std::string::npos) << e.what();
  }
}

// Random interleavings of two services' worth of operations on two
// connections (seeded): the invariants hold after every round.
TEST(StoreConcurrency, RandomOperationsKeepInvariants) {
  TempDir dir;
  const auto path = dir.File("rand.db");
  {
    auto store = Store::Open(path);
    for (const char* c : {"a", "b", "c"}) store->UpsertCell(c, {"point", "line", "patch"});
    store->CreateCampaign(MakeCampaign("x", 1), MakeTrials(40));
    store->CreateCampaign(MakeCampaign("y", 2), MakeTrials(40, "line"));
  }
  auto work = [&](unsigned seed, std::string* error) {
    try {
      std::mt19937 rng(seed);
      auto store = Store::Open(path);
      const char* cells[] = {"a", "b", "c"};
      for (int step = 0; step < 120; ++step) {
        auto t = store->ClaimNextTrial(cells[rng() % 3]);
        if (!t) break;
        switch (rng() % 5) {
          case 0:
            store->RetryTrial(t->trial_id, t->attempt, "random retry", 3, 0);
            break;
          case 1:
            store->FailTrial(t->trial_id, t->attempt, "random failure");
            break;
          default:
            RunTrialToDone(*store, *t, 1 + static_cast<int>(rng() % 40));
            break;
        }
      }
    } catch (const std::exception& e) {
      *error = e.what();
    }
  };
  std::string e1, e2;
  std::thread t1(work, 1u, &e1), t2(work, 2u, &e2);
  t1.join();
  t2.join();
  EXPECT_EQ(e1, "");
  EXPECT_EQ(e2, "");
  auto store = Store::Open(path);
  EXPECT_EQ(store->IntegrityCheck(), "ok");
  const auto v = store->CheckInvariants();
  EXPECT_TRUE(v.empty()) << (v.empty() ? "" : v.front());
  const auto s = store->Status();
  for (const auto& c : s.campaigns) {
    EXPECT_EQ(c.pending + c.running + c.done + c.failed + c.cancelled, c.planned);
    EXPECT_EQ(c.running, 0);
  }
}

}  // namespace
}  // namespace arena::db
