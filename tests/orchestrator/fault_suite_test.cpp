// The fault suite (issue 8, label `faults`): real `arena serve` and `arena
// cell` processes on a test-unique DDS domain, one fault injected per test:
//
//   ServiceKilledAtTwentySeededRandomPoints  SIGKILL of the service, 20 times
//   CellKilledMidReset                       SIGKILL of a cell while it resets
//   HungCellIsTimedOutAndQuarantined         a cell that accepts, then hangs
//   MalformedStream{Nan,Gap}                 a cell whose samples are NaN / skip a batch
//   StoreRunsOutOfSpace                      the store may not grow (SQLite max_page_count)
//   StoreOnAFullFileSystem                   the store on a 1 MiB tmpfs (skipped if not mountable)
//   ReadOnlyStoreFile                        the store file is immutable
//
// After each: the service continued (the campaign finished) or stopped with
// a clear message and exit code 3; every finished trial is intact, none is
// duplicated, integrity_check is ok (ExpectCampaignConsistent). Each test
// prints one line "fault summary: N injected, M survived".
// The mid-execute cell kill and failing resets are in service_faults_test.cpp.
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "service_support.hpp"

namespace arena::test {
namespace {

constexpr auto kCampaignTimeout = std::chrono::seconds(120);
constexpr int kTrials = 30;

// Totals over the tests this process ran; printed once at the end (one line
// for the whole suite when the binary runs alone, one per test under ctest).
struct SuiteTotals : ::testing::Environment {
  static inline int injected = 0, survived = 0, tests = 0;
  void TearDown() override {
    std::printf("fault suite: %d faults injected in %d tests, %d survived\n", injected, tests,
                survived);
  }
};
const auto* const kTotals = ::testing::AddGlobalTestEnvironment(new SuiteTotals);

struct FaultTally {
  int injected = 0;
  int survived = 0;
  ~FaultTally() {
    SuiteTotals::injected += injected;
    SuiteTotals::survived += survived;
    ++SuiteTotals::tests;
    std::printf("fault summary: %d injected, %d survived (%s)\n", injected, survived,
                ::testing::UnitTest::GetInstance()->current_test_info()
                    ? ::testing::UnitTest::GetInstance()->current_test_info()->name()
                    : "");
  }
};

std::unique_ptr<Child> StartCell(const TempDir& dir, const std::string& domain,
                                 const std::string& id, const std::string& speed,
                                 const std::string& defects = "") {
  std::vector<std::string> args = {"cell", "--id", id, "--domain", domain, "--speed", speed};
  if (!defects.empty()) args.insert(args.end(), {"--defects", defects});
  return StartArena(args, dir / (id + ".log"));
}

int Submit(const TempDir& dir, const std::string& db) {
  return RunArena({"submit", TestCampaign("faults30.json"), "--db", db}, dir / "submit.out",
                  std::chrono::seconds(30));
}

bool AllFinished(const std::string& db) {
  auto c = CountStates(db, 1);
  return c["done"] + c["failed"] + c["cancelled"] == kTrials;
}

void StopService(Child& serve) {
  serve.Signal(SIGTERM);
  ASSERT_TRUE(serve.Wait(std::chrono::seconds(40)).has_value()) << "serve did not stop on SIGTERM";
}

TEST(FaultSuite, ServiceKilledAtTwentySeededRandomPoints) {
  FaultTally tally;
  TempDir dir;
  const std::string db = dir / "kill20.db";
  const std::string domain = std::to_string(TestDomain(21));
  // Wall-clock pacing so the campaign outlasts 20 kills (about 40 s of service
  // time): a trial with its reset (release, pick and place, regrasp, and a
  // 0.2 s pusher move where the pivot offset changes) takes about 2 s, so 60
  // trials on two cells need about a minute.
  auto c1 = StartCell(dir, domain, "c1", "1");
  auto c2 = StartCell(dir, domain, "c2", "1");
  // 60 trials: with the service finding its cells at once after a restart,
  // the 30-trial campaign ends before the 20th kill.
  ASSERT_EQ(RunArena({"submit", TestCampaign("e2e60.json"), "--db", db}, dir / "submit.out",
                     std::chrono::seconds(30)),
            0)
      << ReadFile(dir / "submit.out");
  const auto all_finished = [&db] {
    auto c = CountStates(db, 1);
    return c["done"] + c["failed"] + c["cancelled"] == 60;
  };
  // Seeded: the same 20 kill times on every run (0.3 .. 2.5 s after start:
  // during start-up and recovery, dispatch, ingest, reset and prediction).
  std::mt19937 rng(20261122);
  std::uniform_int_distribution<int> after_ms(300, 2500);
  std::string kills;
  for (int k = 0; k < 20; ++k) {
    const int ms = after_ms(rng);
    auto serve = StartArena({"serve", "--db", db, "--domain", domain},
                            dir / ("serve" + std::to_string(k) + ".log"));
    std::this_thread::sleep_for(std::chrono::milliseconds(ms));
    serve->Signal(SIGKILL);
    ASSERT_TRUE(serve->Wait(std::chrono::seconds(10)).has_value());
    ++tally.injected;
    // Between kills the store is always consistent (nothing half-written).
    {
      auto store = OpenReadOnly(db);
      ASSERT_EQ(store->IntegrityCheck(), "ok") << "after kill " << k;
    }
    kills += std::to_string(ms) + "ms:" + std::to_string(CountStates(db, 1)["done"]) + " ";
    if (all_finished()) break;
  }
  EXPECT_EQ(tally.injected, 20) << "the campaign ended before 20 kills: " << kills;
  auto serve = StartArena({"serve", "--db", db, "--domain", domain}, dir / "serve-final.log");
  // What is left may take minutes on a loaded machine (resets are paced too);
  // a service that stops making progress still fails within a minute.
  ASSERT_TRUE(WaitWhileProgressing(
      all_finished, [&db] { return CountStates(db, 1)["done"]; }, std::chrono::seconds(60),
      std::chrono::seconds(480)))
      << ReadFile(dir / "serve-final.log");
  StopService(*serve);
  EXPECT_EQ(CountStates(db, 1)["done"], 60) << kills;
  ExpectCampaignConsistent(db, 1, 60);
  if (!::testing::Test::HasFailure()) tally.survived = tally.injected;
  std::printf("kill points (delay:done so far): %s\n", kills.c_str());
}

TEST(FaultSuite, CellKilledMidReset) {
  FaultTally tally;
  TempDir dir;
  const std::string db = dir / "cellreset.db";
  const std::string domain = std::to_string(TestDomain(22));
  auto c1 = StartCell(dir, domain, "c1", "0.25");
  auto c2 = StartCell(dir, domain, "c2", "0.25");
  auto serve = StartArena({"serve", "--db", db, "--domain", domain}, dir / "serve.log");
  ASSERT_EQ(Submit(dir, db), 0);
  std::int64_t victim = 0;
  ASSERT_TRUE(WaitUntil(
      [&] {
        for (const auto& t : OpenReadOnly(db)->ListTrials(1)) {
          if (t.cell_id == "c1" && t.state == db::TrialState::kResetting) {
            victim = t.id;
            return true;
          }
        }
        return false;
      },
      kCampaignTimeout))
      << ReadFile(dir / "serve.log");
  c1->Signal(SIGKILL);
  ++tally.injected;
  ASSERT_TRUE(WaitUntil([&] { return AllFinished(db); }, kCampaignTimeout))
      << ReadFile(dir / "serve.log");
  StopService(*serve);
  ExpectCampaignConsistent(db, 1, kTrials);
  auto store = OpenReadOnly(db);
  // The trial's ground truth was complete: a lost reset does not spoil it.
  EXPECT_EQ(store->GetTrial(victim).state, db::TrialState::kDone);
  EXPECT_EQ(store->GetCell("c1").state, db::CellState::kGone);
  EXPECT_EQ(CountStates(db, 1)["done"], kTrials);
  if (!::testing::Test::HasFailure()) tally.survived = tally.injected;
}

// A cell with a fault-injection profile beside a healthy one: the campaign
// finishes on the healthy cell and the faulty one is quarantined.
void ExpectFaultyCellQuarantined(const std::string& name, const std::string& profile,
                                 const std::vector<std::string>& serve_extra, int salt) {
  FaultTally tally;
  TempDir dir;
  const std::string db = dir / (name + ".db");
  const std::string domain = std::to_string(TestDomain(salt));
  std::ofstream(dir / "faulty.json") << profile;
  auto c1 = StartCell(dir, domain, "c1", "0.1", dir / "faulty.json");
  auto c2 = StartCell(dir, domain, "c2", "0.1");
  std::vector<std::string> args = {"serve", "--db", db, "--domain", domain, "--quarantine-after",
                                   "2"};
  args.insert(args.end(), serve_extra.begin(), serve_extra.end());
  auto serve = StartArena(args, dir / "serve.log");
  ASSERT_EQ(Submit(dir, db), 0);
  ASSERT_TRUE(WaitUntil([&] { return AllFinished(db); }, kCampaignTimeout))
      << ReadFile(dir / "serve.log");
  StopService(*serve);
  ExpectCampaignConsistent(db, 1, kTrials);
  auto store = OpenReadOnly(db);
  const auto cell = store->GetCell("c1");
  EXPECT_EQ(cell.state, db::CellState::kQuarantined) << ReadFile(dir / "serve.log");
  tally.injected = cell.total_failures;
  // Every trial the faulty cell spoiled was re-run: none is lost.
  EXPECT_EQ(CountStates(db, 1)["done"], kTrials) << ReadFile(dir / "serve.log");
  EXPECT_GE(tally.injected, 2);
  if (!::testing::Test::HasFailure()) tally.survived = tally.injected;
}

TEST(FaultSuite, HungCellIsTimedOutAndQuarantined) {
  ExpectFaultyCellQuarantined("hang", R"({"fault_injection": {"hang_after_accept": true}})",
                              {"--execute-timeout", "1"}, 23);
}

TEST(FaultSuite, MalformedStreamNan) {
  ExpectFaultyCellQuarantined("nan", R"({"fault_injection": {"stream": "nan"}})", {}, 24);
}

TEST(FaultSuite, MalformedStreamGap) {
  ExpectFaultyCellQuarantined("gap", R"({"fault_injection": {"stream": "gap"}})", {}, 25);
}

// The store may not grow past its size at start + a few pages: the service
// stops with exit 3 and a message naming the cause; what it wrote is intact;
// restarted without the limit it finishes the campaign.
TEST(FaultSuite, StoreRunsOutOfSpace) {
  FaultTally tally;
  TempDir dir;
  const std::string db = dir / "full.db";
  const std::string domain = std::to_string(TestDomain(26));
  ASSERT_EQ(Submit(dir, db), 0);
  const auto pages = std::filesystem::file_size(db) / 4096 + 24;
  auto c1 = StartCell(dir, domain, "c1", "0.1");
  auto serve = StartArena(
      {"serve", "--db", db, "--domain", domain, "--store-max-pages", std::to_string(pages)},
      dir / "serve.log");
  ++tally.injected;
  const auto st = serve->Wait(std::chrono::seconds(90));
  ASSERT_TRUE(st.has_value()) << "serve did not stop on a full store: "
                              << ReadFile(dir / "serve.log");
  EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) == 3) << ReadFile(dir / "serve.log");
  const std::string log = ReadFile(dir / "serve.log");
  EXPECT_NE(log.find("full"), std::string::npos) << log;
  {
    auto store = OpenReadOnly(db);
    EXPECT_EQ(store->IntegrityCheck(), "ok");
    const auto violations = store->CheckInvariants();
    EXPECT_TRUE(violations.empty()) << violations.front();
  }
  const int done_before = CountStates(db, 1)["done"];
  auto again = StartArena({"serve", "--db", db, "--domain", domain}, dir / "serve2.log");
  ASSERT_TRUE(WaitUntil([&] { return AllFinished(db); }, kCampaignTimeout))
      << ReadFile(dir / "serve2.log");
  StopService(*again);
  ExpectCampaignConsistent(db, 1, kTrials);
  EXPECT_EQ(CountStates(db, 1)["done"], kTrials);
  std::printf("done before the store filled: %d\n", done_before);
  if (!::testing::Test::HasFailure()) tally.survived = tally.injected;
}

// The same on a real file system that fills up: a 1 MiB tmpfs the test
// mounts (needs root or CAP_SYS_ADMIN; skipped with the reason otherwise).
// The store, its WAL and the service log all live there.
TEST(FaultSuite, StoreOnAFullFileSystem) {
  FaultTally tally;
  TempDir dir;
  const std::string mnt = dir / "small";
  std::filesystem::create_directory(mnt);
  if (std::system(("mount -t tmpfs -o size=1m tmpfs '" + mnt + "' 2>/dev/null").c_str()) != 0)
    GTEST_SKIP() << "cannot mount a tmpfs here (not root / no CAP_SYS_ADMIN); StoreRunsOutOfSpace "
                    "covers the limit";
  struct Unmount {
    std::string path;
    ~Unmount() { std::system(("umount -l '" + path + "' 2>/dev/null").c_str()); }
  } unmount{mnt};
  const std::string db = mnt + "/full.db";
  const std::string domain = std::to_string(TestDomain(28));
  ASSERT_EQ(Submit(dir, db), 0) << ReadFile(dir / "submit.out");
  auto c1 = StartCell(dir, domain, "c1", "0.1");
  auto serve = StartArena({"serve", "--db", db, "--domain", domain}, dir / "serve.log");
  ++tally.injected;
  const auto st = serve->Wait(std::chrono::seconds(90));
  ASSERT_TRUE(st.has_value()) << "serve did not stop on a full file system: "
                              << ReadFile(dir / "serve.log");
  EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) == 3) << ReadFile(dir / "serve.log");
  EXPECT_NE(ReadFile(dir / "serve.log").find("full"), std::string::npos)
      << ReadFile(dir / "serve.log");
  // Move the store to a roomy file system (as an operator would after
  // freeing space) and finish there.
  const std::string moved = dir / "moved.db";
  for (const char* ext : {"", "-wal", "-shm"}) {
    std::error_code ec;
    std::filesystem::copy_file(db + ext, moved + ext, ec);
  }
  {
    auto store = OpenReadOnly(moved);
    EXPECT_EQ(store->IntegrityCheck(), "ok");
    const auto violations = store->CheckInvariants();
    EXPECT_TRUE(violations.empty()) << violations.front();
  }
  auto again = StartArena({"serve", "--db", moved, "--domain", domain}, dir / "serve2.log");
  ASSERT_TRUE(WaitUntil([&] { return AllFinished(moved); }, kCampaignTimeout))
      << ReadFile(dir / "serve2.log");
  StopService(*again);
  ExpectCampaignConsistent(moved, 1, kTrials);
  EXPECT_EQ(CountStates(moved, 1)["done"], kTrials);
  if (!::testing::Test::HasFailure()) tally.survived = tally.injected;
}

// A store file that cannot be written (immutable: root ignores mode bits).
TEST(FaultSuite, ReadOnlyStoreFile) {
  FaultTally tally;
  TempDir dir;
  const std::string db = dir / "ro.db";
  ASSERT_EQ(Submit(dir, db), 0);
  const auto before = ReadFile(db);
  chmod(db.c_str(), 0444);
  bool immutable = false;
  if (access(db.c_str(), W_OK) == 0) {  // root: mode bits do not stop writes
    immutable = std::system(("chattr +i '" + db + "' 2>/dev/null").c_str()) == 0;
    if (!immutable)
      GTEST_SKIP()
          << "running as root and chattr +i is not permitted: cannot make the store read-only";
  }
  ++tally.injected;
  const int rc = RunArena({"serve", "--db", db, "--domain", std::to_string(TestDomain(27))},
                          dir / "serve.log", std::chrono::seconds(30));
  const int submit_rc = RunArena({"submit", TestCampaign("faults30.json"), "--db", db},
                                 dir / "submit2.out", std::chrono::seconds(30));
  const int pause_rc =
      RunArena({"pause", "1", "--db", db}, dir / "pause.out", std::chrono::seconds(30));
  if (immutable) std::system(("chattr -i '" + db + "'").c_str());
  chmod(db.c_str(), 0644);
  EXPECT_EQ(rc, 3) << ReadFile(dir / "serve.log");
  EXPECT_NE(ReadFile(dir / "serve.log").find("read-only"), std::string::npos)
      << ReadFile(dir / "serve.log");
  EXPECT_EQ(submit_rc, 3) << ReadFile(dir / "submit2.out");
  EXPECT_EQ(pause_rc, 3) << ReadFile(dir / "pause.out");
  EXPECT_EQ(ReadFile(db), before);  // not one byte changed
  auto store = OpenReadOnly(db);
  EXPECT_EQ(store->IntegrityCheck(), "ok");
  EXPECT_EQ(store->ListCampaigns().size(), 1u);
  if (!::testing::Test::HasFailure()) tally.survived = tally.injected;
}

}  // namespace
}  // namespace arena::test
