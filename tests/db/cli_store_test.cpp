// arena query and arena export as a user runs them: the real binary on a
// store built through the Store API. Exit codes: cli/src/commands.hpp.
#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "arena/db/export.hpp"
#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeTrials;
using testing::RunTrialToDone;
using testing::TempDir;

struct Run {
  int code = -1;
  std::string out;
  std::string err;
};

Run Arena(const std::string& args, const TempDir& dir) {
  const std::string err_file = dir.File("stderr.txt");
  const std::string cmd = std::string(ARENA_BINARY) + " " + args + " 2>" + err_file;
  Run r;
  FILE* p = ::popen(cmd.c_str(), "r");
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream e(err_file);
  std::stringstream ss;
  ss << e.rdbuf();
  r.err = ss.str();
  return r;
}

class CliStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    db_ = dir_.File("lab.db");
    auto store = Store::Open(db_);
    store->UpsertCell("c", {"point"});
    store->CreateCampaign(MakeCampaign("first"), MakeTrials(5));
    for (int i = 0; i < 3; ++i) {
      auto t = store->ClaimNextTrial("c");
      RunTrialToDone(*store, *t, 30);
    }
  }
  TempDir dir_;
  std::string db_;
};

TEST_F(CliStoreTest, QueryFormatsAndFilters) {
  const auto table = Arena("query --db " + db_ + " --campaign 1", dir_);
  EXPECT_EQ(table.code, 0) << table.err;
  EXPECT_NE(table.out.find("(5 rows)"), std::string::npos) << table.out;
  const auto json =
      Arena("query --db " + db_ + " --where 'grip_force >= 6' --outcome ok --format json", dir_);
  ASSERT_EQ(json.code, 0) << json.err;
  const auto rows = nlohmann::json::parse(json.out);
  EXPECT_EQ(rows.size(), 2u);  // grip 6 and 7 finished ok; 8 and 9 are planned
  const auto csv =
      Arena("query --db " + db_ + " \"SELECT id, name FROM campaigns\" --format csv", dir_);
  EXPECT_EQ(csv.out, "id,name\n1,first\n");
}

TEST_F(CliStoreTest, QueryRefusesWritesAndExplains) {
  const auto r = Arena("query --db " + db_ + " \"DELETE FROM trials\"", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("refused"), std::string::npos) << r.err;
  const auto missing = Arena("query --db " + dir_.File("nope.db"), dir_);
  EXPECT_EQ(missing.code, 3);
  EXPECT_NE(missing.err.find("no store"), std::string::npos) << missing.err;
  const auto bad = Arena("query --db " + db_ + " \"SELECT nonsense FROM\"", dir_);
  EXPECT_EQ(bad.code, 2);
  EXPECT_EQ(
      Arena("query --db " + db_ + " \"SELECT COUNT(*) AS n FROM trials\" --format csv", dir_).out,
      "n\n5\n");
}

TEST_F(CliStoreTest, ExportWritesAVerifiedDataset) {
  const std::string out = dir_.File("dataset");
  const auto r = Arena("export --db " + db_ + " --campaign 1 --format csv --out " + out, dir_);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("3 trials, 90 samples"), std::string::npos) << r.out;
  const auto verified = VerifyExport(out);
  EXPECT_EQ(verified.trials, 3);
  std::ifstream m(out + "/manifest.json");
  const auto manifest = nlohmann::json::parse(m);
  EXPECT_FALSE(manifest["arena_version"].get<std::string>().empty());
  EXPECT_FALSE(manifest["arena_commit"].get<std::string>().empty());
  // A second export into the same directory is refused; nothing is overwritten.
  const auto again = Arena("export --db " + db_ + " --campaign 1 --format csv --out " + out, dir_);
  EXPECT_EQ(again.code, 2);
  EXPECT_NE(again.err.find("not empty"), std::string::npos) << again.err;
  const auto unknown = Arena("export --db " + db_ + " --campaign 7 --out " + dir_.File("x"), dir_);
  EXPECT_EQ(unknown.code, 2);
}

}  // namespace
}  // namespace arena::db
