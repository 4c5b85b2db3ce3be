// Issue 28 with the real binary on real stores: a finished evaluation waits
// for a store another process holds locked and is stored when it frees (and
// saved to a file when the wait is interrupted); an evaluation of a campaign
// without done trials and an unknown sensitivity tolerance store nothing;
// the partial directories of SIGKILLed exports are removed by the next.
#include <signal.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena_command_test.hpp"
#include "executors/test_support.hpp"

namespace arena::test {
namespace {

namespace fs = std::filesystem;

std::string Campaign(const std::string& name) {
  return std::string(ARENA_SOURCE_DIR) + "/tests/orchestrator/data/" + name;
}

int Count(const std::string& db, const std::string& table) {
  sqlite3* h = nullptr;
  sqlite3_open_v2(db.c_str(), &h, SQLITE_OPEN_READONLY, nullptr);
  sqlite3_stmt* s = nullptr;
  int n = -1;
  if (sqlite3_prepare_v2(h, ("SELECT count(*) FROM " + table).c_str(), -1, &s, nullptr) ==
          SQLITE_OK &&
      sqlite3_step(s) == SQLITE_ROW)
    n = sqlite3_column_int(s, 0);
  sqlite3_finalize(s);
  sqlite3_close(h);
  return n;
}

// Another process's write transaction, held until Release().
class WriteLock {
 public:
  explicit WriteLock(const std::string& db) {
    sqlite3_open(db.c_str(), &h_);
    EXPECT_EQ(sqlite3_exec(h_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr), SQLITE_OK);
  }
  ~WriteLock() { Release(); }
  void Release() {
    if (!h_) return;
    sqlite3_exec(h_, "ROLLBACK", nullptr, nullptr, nullptr);
    sqlite3_close(h_);
    h_ = nullptr;
  }

 private:
  sqlite3* h_ = nullptr;
};

bool WaitFor(const std::function<bool()>& done, std::chrono::seconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < until) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return done();
}

class TrustE2e : public ArenaCommandTest {
 protected:
  void SetUp() override {
    ArenaCommandTest::SetUp();
    db_ = dir_ + "/lab.db";
    const auto r = Arena("run " + Campaign("eval6.json") + " --db " + db_ + " --cells 1 --quiet");
    ASSERT_EQ(r.rc, 0) << r.out << r.err;
  }
  std::unique_ptr<Child> Evaluate(const std::string& extra, const std::string& log) {
    return std::make_unique<Child>(
        std::vector<std::string>{"/bin/sh", "-c",
                                 std::string(ARENA_BINARY) + " evaluate --db " + db_ +
                                     " --campaign 1 --facets 4 --dt 0.008 --convergence-trials 0 " +
                                     extra},
        log);
  }
  std::string db_;
};

TEST_F(TrustE2e, AFinishedEvaluationWaitsForABusyStoreAndIsNeverThrownAway) {
  {
    WriteLock lock(db_);
    auto eval = Evaluate("", dir_ + "/eval1.log");
    ASSERT_TRUE(WaitFor(
        [&] { return Slurp(dir_ + "/eval1.log").find("waiting to write") != std::string::npos; },
        std::chrono::seconds(120)))
        << Slurp(dir_ + "/eval1.log");
    EXPECT_FALSE(eval->Wait(std::chrono::milliseconds(1500)).has_value())
        << "gave up on a busy store: " << Slurp(dir_ + "/eval1.log");
    lock.Release();
    const auto st = eval->Wait(std::chrono::seconds(60));
    ASSERT_TRUE(st.has_value());
    EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) == 0) << Slurp(dir_ + "/eval1.log");
  }
  EXPECT_EQ(Count(db_, "evaluations"), 1);
  {
    // Ctrl-C while it waits: the finished report is saved to --out, exit 3.
    WriteLock lock(db_);
    const std::string out = dir_ + "/report.json";
    auto eval = std::make_unique<Child>(
        std::vector<std::string>{std::string(ARENA_BINARY), "evaluate", "--db", db_, "--campaign",
                                 "1", "--facets", "4", "--dt", "0.008", "--convergence-trials", "0",
                                 "--out", out},
        dir_ + "/eval2.log");
    ASSERT_TRUE(WaitFor(
        [&] { return Slurp(dir_ + "/eval2.log").find("waiting to write") != std::string::npos; },
        std::chrono::seconds(120)))
        << Slurp(dir_ + "/eval2.log");
    eval->Signal(SIGINT);
    const auto st = eval->Wait(std::chrono::seconds(30));
    ASSERT_TRUE(st.has_value());
    EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) == 3) << Slurp(dir_ + "/eval2.log");
    EXPECT_NE(Slurp(dir_ + "/eval2.log").find("the report is saved in " + out), std::string::npos)
        << Slurp(dir_ + "/eval2.log");
    const auto saved = nlohmann::json::parse(Slurp(out));
    EXPECT_TRUE(saved.contains("not_stored"));
    EXPECT_TRUE(saved.contains("settings"));
  }
  EXPECT_EQ(Count(db_, "evaluations"), 1);
}

TEST_F(TrustE2e, NothingToEvaluateAndUnknownTolerancesAreRefused) {
  const std::string empty = dir_ + "/empty.db";
  ASSERT_EQ(Arena("submit " + Campaign("eval6.json") + " --db " + empty).rc, 0);
  auto r = Arena("evaluate --db " + empty + " --campaign 1");
  EXPECT_EQ(r.rc, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("no done trials"), std::string::npos) << r.err;
  EXPECT_EQ(Count(empty, "evaluations"), 0);
  r = Arena("sensitivity --db " + db_ + " --campaign 1 --ensemble 2 --tolerance nosuch=1");
  EXPECT_EQ(r.rc, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("nosuch"), std::string::npos) << r.err;
  EXPECT_EQ(Count(db_, "sensitivity_runs"), 0);
}

TEST_F(TrustE2e, LeftoversOfKilledExportsAreRemovedByTheNext) {
  const std::string out = dir_ + "/data";
  // One export SIGKILLed while it writes (when the machine lets the test see
  // its partial directory), and one a dead process left (its pid in the name).
  int killed = 0;
  {
    Child exporter(
        {std::string(ARENA_BINARY), "export", "--db", db_, "--campaign", "1", "--out", out},
        dir_ + "/export-killed.log");
    const bool seen = WaitFor(
        [&] {
          for (const auto& e : fs::directory_iterator(dir_))
            if (e.path().filename().string().rfind(".data.partial-", 0) == 0) return true;
          return false;
        },
        std::chrono::seconds(20));
    exporter.Signal(SIGKILL);
    exporter.Wait(std::chrono::seconds(10));
    killed = seen && !fs::exists(out + "/manifest.json") ? 1 : 0;
    if (fs::exists(out)) fs::remove_all(out);  // it finished first: start again
  }
  pid_t dead = fork();
  if (dead == 0) _exit(0);
  waitpid(dead, nullptr, 0);
  const std::string left = dir_ + "/.data.partial-" + std::to_string(dead) + "-Ab3dE9";
  fs::create_directories(left + "/streams");
  std::ofstream(left + "/streams/1_true.h5") << std::string(100000, 'x');
  const auto r = Arena("export --db " + db_ + " --campaign 1 --out " + out);
  ASSERT_EQ(r.rc, 0) << r.err;
  int leftovers = 0;
  for (const auto& e : fs::directory_iterator(dir_))
    leftovers += e.path().filename().string().find(".partial-") != std::string::npos;
  EXPECT_EQ(leftovers, 0);
  EXPECT_TRUE(fs::exists(out + "/manifest.json"));
  std::printf("exports: %d SIGKILLed mid-write + 1 dead one's directory; %d left after the next\n",
              killed, leftovers);
}

}  // namespace
}  // namespace arena::test
