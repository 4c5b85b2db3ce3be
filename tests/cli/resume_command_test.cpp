// Issue 29 through the `arena` binary: `arena resume ID [--cell C]` lifts the
// campaign's, the service's and the cell's suspensions (lifted_by "arena
// resume") and resumes a paused campaign; `arena status` lists what holds
// dispatch back (text and JSON); `arena serve --suspenders` refuses a bad
// limit naming it, before anything is stored.
#include <fstream>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena_command_test.hpp"

namespace arena::test {
namespace {

using ResumeCommand = ArenaCommandTest;

const std::string kCampaign = std::string(ARENA_SOURCE_DIR) + "/tests/orchestrator/data/iso_a.json";

db::Suspension Make(const std::string& condition, const std::string& scope, std::int64_t campaign,
                    const std::string& cell) {
  db::Suspension s;
  s.condition = condition;
  s.scope = scope;
  s.campaign_id = campaign;
  s.cell_id = cell;
  s.rule = condition + ".fired";
  s.evidence = "a test's evidence";
  return s;
}

TEST_F(ResumeCommand, LiftsTheCampaignsTheServicesAndTheNamedCellsSuspensions) {
  const std::string db = dir_ + "/r.db";
  ASSERT_EQ(Arena("submit " + kCampaign + " --db " + db).rc, 0);
  {
    auto store = db::Store::Open(db);
    store->RecordSuspension(Make("deadline_misses", "campaign", 1, ""));
    store->RecordSuspension(Make("store_free_space", "service", 0, ""));
    store->RecordSuspension(Make("reset_failure_rate", "cell", 0, "c1"));
    store->RecordSuspension(Make("sample_drop_rate", "cell", 0, "c2"));
    EXPECT_EQ(store->GetCampaign(1).state, db::CampaignState::kPaused);
  }
  auto status = Arena("status --db " + db);
  ASSERT_EQ(status.rc, 0) << status.err;
  EXPECT_NE(status.out.find("suspended (dispatch held back"), std::string::npos) << status.out;
  EXPECT_NE(status.out.find("cell c1: reset_failure_rate since"), std::string::npos) << status.out;
  EXPECT_NE(status.out.find("every campaign: store_free_space"), std::string::npos) << status.out;
  const auto json = nlohmann::json::parse(Arena("status --db " + db + " --json").out);
  ASSERT_EQ(json["suspensions"].size(), 4u);
  EXPECT_TRUE(json["suspensions"][0]["active"].get<bool>());

  const auto r = Arena("resume 1 --cell c1 --db " + db);
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("lifted: deadline_misses"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("lifted: reset_failure_rate suspension of cell c1"), std::string::npos)
      << r.err;
  auto store = db::Store::Open(db);
  EXPECT_EQ(store->GetCampaign(1).state, db::CampaignState::kActive);
  const auto active = store->ListSuspensions(true);
  ASSERT_EQ(active.size(), 1u) << "c2's suspension is not the operator's to lift with --cell c1";
  EXPECT_EQ(active[0].cell_id, "c2");
  for (const auto& s : store->ListSuspensions(false)) {
    if (!s.lifted_at) continue;
    EXPECT_EQ(s.lifted_by, "arena resume");
  }
  status = Arena("status --db " + db);
  EXPECT_NE(status.out.find("last suspensions lifted"), std::string::npos) << status.out;
}

TEST_F(ResumeCommand, StillResumesAnOperatorsPauseAndRefusesADoneCampaign) {
  const std::string db = dir_ + "/p.db";
  ASSERT_EQ(Arena("submit " + kCampaign + " --db " + db).rc, 0);
  ASSERT_EQ(Arena("pause 1 --db " + db).rc, 0);
  auto r = Arena("resume 1 --db " + db);
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("campaign 1: active"), std::string::npos) << r.err;
  ASSERT_EQ(Arena("cancel 1 --db " + db).rc, 0);
  r = Arena("resume 1 --db " + db);
  EXPECT_NE(r.rc, 0);
  EXPECT_NE(r.err.find("cancelled"), std::string::npos) << r.err;
  r = Arena("resume 7 --db " + db);
  EXPECT_NE(r.rc, 0);
  EXPECT_NE(r.err.find("no campaign 7"), std::string::npos) << r.err;
}

TEST_F(ResumeCommand, ServeRefusesABadSuspendersFileNamingTheField) {
  const std::string db = dir_ + "/s.db";
  const std::string file = dir_ + "/suspenders.json";
  const std::vector<std::pair<std::string, std::string>> bad = {
      {R"({"cell_silence": {"hold_s": -3}})", "suspenders.cell_silence.hold_s"},
      {R"({"reset_rate": {}})", "suspenders.reset_rate: unknown condition"},
      {"{not json", "not valid JSON"}};
  for (const auto& [text, field] : bad) {
    std::ofstream(file) << text;
    const auto r = Arena("serve --db " + db + " --domain 7 --suspenders " + file);
    EXPECT_EQ(r.rc, 2) << text << ": " << r.err;
    EXPECT_NE(r.err.find(field), std::string::npos) << text << ": " << r.err;
  }
  auto r = Arena("serve --db " + db + " --domain 7 --suspenders " + dir_ + "/missing.json");
  EXPECT_EQ(r.rc, 2) << r.err;
  r = Arena("serve --db " + db + " --domain 7 --notify-queue 0");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--notify-queue"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(db)) << "a refused option created the store";
}

}  // namespace
}  // namespace arena::test
