// Issue 16, items 6-8 and 10 through the `arena` binary: options that would
// break the service are refused naming the field, outputs never overwrite a
// store, `arena cells release` lifts a quarantine with an audit row, submit is
// atomic (Ctrl-C: exit 130, nothing stored), a runaway query stops.
#include <signal.h>

#include <chrono>
#include <thread>

#include "arena/db/store.hpp"
#include "arena_command_test.hpp"

namespace arena::test {
namespace {

using ServiceInputs = ArenaCommandTest;

const std::string kCampaign = std::string(ARENA_SOURCE_DIR) + "/tests/orchestrator/data/iso_a.json";

TEST_F(ServiceInputs, ServeRefusesOptionsThatWouldBreakItNamingTheField) {
  const std::string db = dir_ + "/s.db";
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"--reset-timeout nan", "--reset-timeout"},
      {"--reset-timeout -5", "--reset-timeout"},
      {"--execute-timeout -1", "--execute-timeout"},
      {"--execute-timeout inf", "--execute-timeout"},
      {"--execute-timeout nan", "--execute-timeout"},
      {"--drain nan", "--drain"},
      {"--drain -1", "--drain"},
      {"--predictors 100000", "--predictors"},
      {"--predictors 0", "--predictors"},
      {"--domain 232", "--domain"}};
  for (const auto& [args, field] : bad) {
    const auto r = Arena("serve --db " + db + " --domain 7 " + args);
    EXPECT_EQ(r.rc, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find(field), std::string::npos) << args << ": " << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(db)) << "a refused option created the store";
  for (const std::string& cmd :
       std::vector<std::string>{"cell --id c1 --domain 233", "cell --id c1 --domain 232",
                                // the same bad --domain exits 2 from every command (issue 27)
                                "controller --name pivot_to_angle --domain 232",
                                "run " + kCampaign + " --db " + db + " --domain 232"}) {
    const auto r = Arena(cmd);
    EXPECT_EQ(r.rc, 2) << cmd << ": " << r.err;
    EXPECT_NE(r.err.find("--domain"), std::string::npos) << cmd << ": " << r.err;
  }
}

TEST_F(ServiceInputs, StatusRefusesANegativeCampaignId) {
  const std::string db = dir_ + "/s.db";
  ASSERT_EQ(Arena("submit " + kCampaign + " --db " + db).rc, 0);
  const auto r = Arena("status -5 --db " + db);
  EXPECT_EQ(r.rc, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("id"), std::string::npos) << r.err;
  // And submit warns that no service is running.
  EXPECT_NE(Arena("submit " + kCampaign + " --db " + db).err.find("no `arena serve`"),
            std::string::npos);
}

TEST_F(ServiceInputs, OutputsNeverOverwriteAStoreOrAnySqliteFile) {
  const std::string db = dir_ + "/p.db";
  ASSERT_EQ(Arena("submit " + kCampaign + " --db " + db).rc, 0);
  const std::string before = Slurp(db);
  auto r = Arena("plot --db " + db + " 1 --out " + db);
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
  r = Arena("plot --db " + db + " 1 --out " + dir_ + "/../" +
            std::filesystem::path(dir_).filename().string() + "/p.db");
  EXPECT_EQ(r.rc, 2) << "the same store by another path: " << r.err;
  const std::string scene = std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json";
  r = Arena("simulate " + scene + " --trajectory " + db);
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE((r.out + r.err).find("--trajectory"), std::string::npos) << r.out << r.err;
  r = Arena("export --db " + db + " --campaign 1 --format csv --out " + db);
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_EQ(Slurp(db), before) << "the store was written to";
  db::StoreOptions ro;
  ro.read_only = true;
  EXPECT_EQ(db::Store::Open(db, ro)->ListCampaigns().size(), 1u);
}

TEST_F(ServiceInputs, CellsReleaseLiftsAQuarantineWithAnAuditRow) {
  const std::string db = dir_ + "/c.db";
  {
    auto store = db::Store::Open(db);
    store->UpsertCell("c1", {"point"});
    store->QuarantineCell("c1", "3 failures in a row");
  }
  auto r = Arena("cells release c1 --db " + db + " --reason 'pads replaced'");
  EXPECT_EQ(r.rc, 0) << r.err;
  auto store = db::Store::Open(db);
  EXPECT_EQ(store->GetCell("c1").state, db::CellState::kHealthy);
  const auto events = store->ListCellEvents("c1");
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1].event, "released");
  EXPECT_EQ(events[1].reason, "pads replaced");
  EXPECT_FALSE(events[1].by_whom.empty());
  r = Arena("cells release nobody --db " + db);
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("nobody"), std::string::npos) << r.err;
}

TEST_F(ServiceInputs, ARunawayRecursiveQueryStopsAtItsTimeout) {
  const std::string db = dir_ + "/q.db";
  ASSERT_EQ(Arena("submit " + kCampaign + " --db " + db).rc, 0);
  const auto start = std::chrono::steady_clock::now();
  const auto r = Arena("query --db " + db + " --timeout 1 " +
                       "'WITH RECURSIVE c(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM c) "
                       "SELECT count(*) FROM c'");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--timeout"), std::string::npos) << r.err;
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(20));
}

TEST_F(ServiceInputs, SubmitInterruptedExits130AndStoresNothing) {
  const std::string db = dir_ + "/big.db";
  {
    std::ofstream(dir_ + "/big.json") << R"({"name": "big", "seed": 1, "sampler": "uniform",
      "conditions": 400000, "scene": ")"
                                      << ARENA_SOURCE_DIR << R"(/examples/scenes/canonical.json",
      "variations": {"grip_force": {"min": 5, "max": 15}}})";
  }
  db::Store::Open(db);  // the store exists first: the interrupt lands in the planning
  const pid_t pid = fork();
  if (pid == 0) {
    execl(ARENA_BINARY, ARENA_BINARY, "submit", (dir_ + "/big.json").c_str(), "--db", db.c_str(),
          static_cast<char*>(nullptr));
    _exit(127);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  kill(pid, SIGINT);
  const auto interrupted = std::chrono::steady_clock::now();
  int st = 0;
  ASSERT_EQ(waitpid(pid, &st, 0), pid);
  ASSERT_TRUE(WIFEXITED(st));
  EXPECT_EQ(WEXITSTATUS(st), 130);
  EXPECT_LT(std::chrono::steady_clock::now() - interrupted, std::chrono::seconds(3));
  db::StoreOptions ro;
  ro.read_only = true;
  if (std::filesystem::exists(db)) {
    EXPECT_TRUE(db::Store::Open(db, ro)->ListCampaigns().empty()) << "a partial campaign stayed";
  }
}

}  // namespace
}  // namespace arena::test
