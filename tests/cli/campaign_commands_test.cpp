// The campaign commands from another process, as an operator's shell or a
// script runs them: submit / list / status / pause / resume / cancel on a
// store file, status --json in the shape issue 6 fixes, a bad campaign
// refused with exit 2 naming the field and the store left byte for byte
// unchanged, and an example in every command's --help.
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena_command_test.hpp"

namespace {

using arena::test::Slurp;
using Result = arena::test::CommandResult;

class CampaignCommands : public arena::test::ArenaCommandTest {
 protected:
  void SetUp() override {
    ArenaCommandTest::SetUp();
    db_ = dir_ + "/lab.db";
  }
  std::string Campaign() const {
    return std::string(ARENA_SOURCE_DIR) + "/tests/orchestrator/data/e2e60.json";
  }
  std::string db_;
};

// Issue 26: an adaptive campaign's submit logged its first round on stdout
// ("[...] [info] campaign 1: adaptive round 0: 16 trials planned"), so
// `id=$(arena submit ...)` caught a log line. Pins: stdout is the id alone.
TEST_F(CampaignCommands, AdaptiveSubmitPrintsTheIdAloneOnStdout) {
  const Result submit = Arena("submit " + std::string(ARENA_SOURCE_DIR) +
                              "/examples/campaigns/closed_loop.json --db " + db_);
  ASSERT_EQ(submit.rc, 0) << submit.err;
  EXPECT_EQ(submit.out, "1\n");
  EXPECT_NE(submit.err.find("adaptive round 0"), std::string::npos) << submit.err;
}

TEST_F(CampaignCommands, SubmitListStatusPauseResumeCancel) {
  const Result submit = Arena("submit " + Campaign() + " --db " + db_);
  ASSERT_EQ(submit.rc, 0) << submit.err;
  EXPECT_EQ(submit.out, "1\n");  // the id alone on stdout, for scripts
  EXPECT_NE(submit.err.find("60 trials planned"), std::string::npos) << submit.err;
  ASSERT_EQ(Arena("submit " + Campaign() + " --db " + db_).out, "2\n");

  const Result list = Arena("list --db " + db_ + " --json");
  ASSERT_EQ(list.rc, 0) << list.err;
  const auto campaigns = nlohmann::json::parse(list.out);
  ASSERT_EQ(campaigns.size(), 2u);
  EXPECT_EQ(campaigns[0]["name"], "e2e60");

  auto status = [&] {
    const Result r = Arena("status --db " + db_ + " --json");
    EXPECT_EQ(r.rc, 0) << r.err;
    return nlohmann::json::parse(r.out);
  };
  auto s = status();
  // The shape scripts rely on (issue 6); more keys may follow, these stay.
  ASSERT_TRUE(s["campaigns"].is_array());
  ASSERT_TRUE(s["cells"].is_array());
  ASSERT_EQ(s["campaigns"].size(), 2u);
  for (const char* key : {"id", "name", "state", "planned", "done", "failed", "running"})
    EXPECT_TRUE(s["campaigns"][0].contains(key)) << key;
  EXPECT_EQ(s["campaigns"][0]["id"], 1);
  EXPECT_EQ(s["campaigns"][0]["state"], "active");
  EXPECT_EQ(s["campaigns"][0]["planned"], 60);
  EXPECT_EQ(s["campaigns"][0]["done"], 0);
  EXPECT_EQ(s["campaigns"][0]["running"], 0);

  EXPECT_EQ(Arena("pause 1 --db " + db_).rc, 0);
  EXPECT_EQ(status()["campaigns"][0]["state"], "paused");
  EXPECT_EQ(Arena("pause 1 --db " + db_).rc, 0);  // idempotent
  EXPECT_EQ(Arena("resume 1 --db " + db_).rc, 0);
  EXPECT_EQ(status()["campaigns"][0]["state"], "active");
  const Result cancel = Arena("cancel 2 --db " + db_);
  EXPECT_EQ(cancel.rc, 0) << cancel.err;
  s = status();
  EXPECT_EQ(s["campaigns"][1]["state"], "cancelled");
  EXPECT_EQ(s["campaigns"][1]["cancelled"], 60);

  // One campaign only; an unknown one is the user's mistake (exit 2) and says where to look.
  const Result one = Arena("status 2 --db " + db_ + " --json");
  EXPECT_EQ(nlohmann::json::parse(one.out)["campaigns"].size(), 1u);
  const Result unknown = Arena("status 9 --db " + db_);
  EXPECT_EQ(unknown.rc, 2);
  EXPECT_NE(unknown.err.find("arena list"), std::string::npos) << unknown.err;
  EXPECT_EQ(Arena("pause 9 --db " + db_).rc, 2);
  // A cancelled campaign cannot be resumed.
  EXPECT_EQ(Arena("resume 2 --db " + db_).rc, 2);
  // The table form names every column.
  const Result table = Arena("status --db " + db_);
  EXPECT_NE(table.out.find("planned"), std::string::npos);
  EXPECT_NE(table.out.find("ETA"), std::string::npos);
}

// Two processes creating the same new store at once (an operator's submit
// racing a starting `arena serve`) both succeed: the WAL switch retries
// instead of failing with "database is locked" (seen in the fault suite).
TEST_F(CampaignCommands, ConcurrentSubmitsToANewStoreBothSucceed) {
  for (int round = 0; round < 5; ++round) {
    const std::string db = dir_ + "/race" + std::to_string(round) + ".db";
    const std::string one = std::string(ARENA_BINARY) + " submit " + Campaign() + " --db " + db;
    const int st = std::system(("(" + one + " >/dev/null 2>" + dir_ + "/e1 & " + one +
                                " >/dev/null 2>" + dir_ + "/e2 & wait %1 && wait %2) ; r=$?; " +
                                one + " >/dev/null 2>>" + dir_ + "/e1; exit $r")
                                   .c_str());
    (void)st;
    const Result list = Arena("list --db " + db + " --json");
    ASSERT_EQ(list.rc, 0) << list.err;
    EXPECT_EQ(nlohmann::json::parse(list.out).size(), 3u)
        << "round " << round << ": " << Slurp(dir_ + "/e1") << Slurp(dir_ + "/e2");
  }
}

TEST_F(CampaignCommands, ReadCommandsOnAMissingStoreSayWhatToDo) {
  for (const char* cmd : {"list", "status"}) {
    const Result r = Arena(std::string(cmd) + " --db " + dir_ + "/nope.db");
    EXPECT_EQ(r.rc, 3) << cmd;
    EXPECT_NE(r.err.find("--db"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ + "/nope.db"));  // a read never creates a store
  }
}

TEST_F(CampaignCommands, BadCampaignIsRefusedAndTheStoreIsUnchanged) {
  ASSERT_EQ(Arena("submit " + Campaign() + " --db " + db_).rc, 0);
  const std::string before = Slurp(db_);
  auto spec = nlohmann::json::parse(Slurp(Campaign()));
  struct Case {
    std::string what, field;
    nlohmann::json spec;
  };
  std::vector<Case> cases;
  {
    auto c = spec;
    c.erase("scene");
    cases.push_back({"missing scene", "scene", c});
  }
  {
    auto c = spec;
    c["replicates"] = "three";
    cases.push_back({"wrong type", "replicates", c});
  }
  {
    auto c = spec;
    c["scene"]["fingers"][0]["mu"] = -0.5;
    cases.push_back({"negative mu", "mu", c});
  }
  {
    auto c = spec;
    c["scene"]["object"]["mass"] = -1;
    cases.push_back({"negative mass", "mass", c});
  }
  {
    auto c = spec;
    c["repetitions"] = 3;
    cases.push_back({"unknown key", "repetitions", c});
  }
  for (const auto& c : cases) {
    const std::string path = dir_ + "/bad.json";
    std::ofstream(path) << c.spec.dump(2);
    const Result r = Arena("submit " + path + " --db " + db_);
    EXPECT_EQ(r.rc, 2) << c.what << ": " << r.err;
    EXPECT_NE(r.err.find(c.field), std::string::npos) << c.what << ": " << r.err;
    EXPECT_EQ(Slurp(db_), before) << c.what << " changed the store";
  }
  // Not JSON at all.
  std::ofstream(dir_ + "/garbage.json") << "{\"name\": ";
  EXPECT_EQ(Arena("submit " + dir_ + "/garbage.json --db " + db_).rc, 2);
  EXPECT_EQ(Slurp(db_), before);
  // A bad campaign does not create a store either.
  EXPECT_EQ(Arena("submit " + dir_ + "/garbage.json --db " + dir_ + "/new.db").rc, 2);
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/new.db"));
  const Result list = Arena("list --db " + db_ + " --json");
  EXPECT_EQ(nlohmann::json::parse(list.out).size(), 1u);
}

// Every subcommand `arena --help` lists has an example in its own --help.
TEST_F(CampaignCommands, EveryCommandsHelpHasAnExample) {
  const Result top = Arena("--help");
  ASSERT_EQ(top.rc, 0);
  const auto at = top.out.find("Subcommands:");
  ASSERT_NE(at, std::string::npos) << top.out;
  std::istringstream lines(top.out.substr(at));
  std::string line;
  std::getline(lines, line);
  int commands = 0;
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    std::string name;
    if (!(words >> name) || line.rfind("  ", 0) != 0) break;
    const Result help = Arena(name + " --help");
    EXPECT_EQ(help.rc, 0) << name;
    EXPECT_NE(help.out.find("Example"), std::string::npos)
        << "`arena " << name << " --help` has no example";
    EXPECT_NE(help.out.find("arena " + name), std::string::npos)
        << "`arena " << name << " --help`: example does not run it";
    ++commands;
  }
  EXPECT_GE(commands, 10);
}

}  // namespace
