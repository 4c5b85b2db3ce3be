// Issue 26 with real processes: `arena serve` does not dispatch a campaign
// no live cell can host. Before the claim gate it dispatched every trial to
// a cell whose pusher limit is below the campaign's push speed, and the cell
// refused them all (100 % failure). Now the campaign waits with a typed,
// stored reason that `arena status` shows (text and --json), no trial leaves
// `planned`, and dispatch resumes when a cell that can host it announces.
#include <fstream>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "service_support.hpp"

namespace arena::test {
namespace {

TEST(ClaimGateDds, ACampaignNoLiveCellCanHostWaitsUntilOneAnnounces) {
  TempDir dir;
  const std::string db = dir / "gate.db";
  const std::string domain = std::to_string(TestDomain(61));
  {
    std::ofstream slow(dir / "slow.json");
    slow << R"({"max_pusher_speed": 0.005})";  // the campaign pushes at 0.02 m/s
  }
  auto slow = StartArena(
      {"cell", "--id", "slow", "--domain", domain, "--speed", "0", "--defects", dir / "slow.json"},
      dir / "slow.log");
  auto serve = StartArena({"serve", "--db", db, "--domain", domain}, dir / "serve.log");
  ASSERT_EQ(RunArena({"submit", TestCampaign("gate4.json"), "--db", db}, dir / "submit.out",
                     std::chrono::seconds(30)),
            0)
      << ReadFile(dir / "submit.out");
  // The wait is stored, typed and named.
  std::optional<db::CampaignWait> wait;
  ASSERT_TRUE(WaitUntil(
      [&] {
        auto waits = OpenReadOnly(db)->ListCampaignWaits();
        if (!waits.empty()) wait = waits.front();
        return wait.has_value();
      },
      std::chrono::seconds(60)))
      << ReadFile(dir / "serve.log");
  EXPECT_EQ(wait->campaign_id, 1);
  EXPECT_EQ(wait->kind, "pusher_speed");
  EXPECT_EQ(wait->rule, "claim_gate.waits");
  EXPECT_NE(wait->reason.find("no live cell can push at 0.02 m/s (pusher limit 0.005 m/s)"),
            std::string::npos)
      << wait->reason;
  EXPECT_NE(wait->reason.find("cell slow: model backend"), std::string::npos) << wait->reason;
  // Nothing was dispatched: a few claim polls later every trial is still planned.
  std::this_thread::sleep_for(std::chrono::seconds(2));
  EXPECT_EQ(CountStates(db, 1)["planned"], 4) << ReadFile(dir / "serve.log");
  // `arena status` says why, in text and in JSON.
  ASSERT_EQ(RunArena({"status", "--db", db}, dir / "status.txt", std::chrono::seconds(20)), 0);
  const std::string text = ReadFile(dir / "status.txt");
  EXPECT_NE(text.find("campaign 1 waits: no live cell can push at 0.02 m/s"), std::string::npos)
      << text;
  ASSERT_EQ(
      RunArena({"status", "--db", db, "--json"}, dir / "status.json", std::chrono::seconds(20)), 0);
  const auto status = nlohmann::json::parse(ReadFile(dir / "status.json"));
  ASSERT_EQ(status["campaigns"].size(), 1u);
  EXPECT_EQ(status["campaigns"][0]["waits"]["kind"], "pusher_speed") << status.dump();
  // A cell that can host it announces: dispatch resumes, the wait is gone.
  auto fast =
      StartArena({"cell", "--id", "fast", "--domain", domain, "--speed", "0"}, dir / "fast.log");
  ASSERT_TRUE(WaitUntil([&] { return CountStates(db, 1)["done"] == 4; }, std::chrono::seconds(120)))
      << ReadFile(dir / "serve.log");
  EXPECT_TRUE(OpenReadOnly(db)->ListCampaignWaits().empty());
  for (const auto& t : OpenReadOnly(db)->ListTrials(1)) EXPECT_EQ(t.cell_id, "fast");
  serve->Signal(SIGTERM);
  auto st = serve->Wait(std::chrono::seconds(40));
  ASSERT_TRUE(st.has_value()) << "serve did not stop on SIGTERM";
  EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) == 0) << ReadFile(dir / "serve.log");
}

}  // namespace
}  // namespace arena::test
