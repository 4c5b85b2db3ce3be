// End to end: `arena run` starts the service and two simulated cells as
// processes over DDS on a test-unique domain, runs a 60-trial campaign and
// leaves a consistent store behind; `arena submit` + `arena serve` do the same
// from separate processes.
#include <algorithm>
#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "service_support.hpp"

namespace arena::test {
namespace {

TEST(ServiceEndToEnd, RunsSixtyTrialsOnTwoCells) {
  TempDir dir;
  const std::string db = dir / "e2e.db";
  const int rc = RunArena({"run", TestCampaign("e2e60.json"), "--db", db, "--cells", "2",
                           "--domain", std::to_string(TestDomain(1)), "--quiet"},
                          dir / "run.out", std::chrono::seconds(150));
  ASSERT_EQ(rc, 0) << ReadFile(dir / "run.out") << ReadFile(db + ".log");
  const auto counts = CountStates(db, 1);
  EXPECT_EQ(counts.at("done"), 60) << ReadFile(db + ".log");
  ExpectCampaignConsistent(db, 1, 60);
  // Both cells took part.
  auto store = OpenReadOnly(db);
  std::map<std::string, int> per_cell;
  for (const auto& t : store->ListTrials(1)) per_cell[t.cell_id]++;
  EXPECT_EQ(per_cell.size(), 2u);
  // Pins issue 26: the run's cells, stopped by it, say so in `arena status`
  // (they read "no sign within its lease", as a lost cell would).
  for (const auto& c : store->ListCells()) {
    EXPECT_EQ(c.state, db::CellState::kGone) << c.id;
    EXPECT_EQ(c.quarantine_reason, "stopped: its arena run ended") << c.id;
  }
  // The summary names the outcome.
  const std::string out = ReadFile(dir / "run.out");
  EXPECT_NE(out.find("60 done"), std::string::npos) << out;
  // ... and arena's own time per trial (TrialTiming): a median over the clean
  // trials of the cell's busy time minus its execute and reset times. It is
  // positive (DDS round trips and store steps take time) and a part of each
  // clean trial's busy time, claim to verified reset, as the audit rows date it.
  const auto at = out.find("orchestration ");
  ASSERT_NE(at, std::string::npos) << out;
  double median_ms = -1, p95_ms = -1;
  ASSERT_EQ(
      std::sscanf(out.c_str() + at, "orchestration %lf ms median, %lf ms p95", &median_ms, &p95_ms),
      2)
      << out;
  const auto clean_at = out.find("reset time, ", at);
  ASSERT_NE(clean_at, std::string::npos) << out;
  std::size_t clean = 0;
  ASSERT_EQ(std::sscanf(out.c_str() + clean_at, "reset time, %zu clean trials)", &clean), 1) << out;
  EXPECT_GE(clean, 1u) << out;
  EXPECT_LE(clean, 60u) << out;
  std::vector<double> busy_ms;
  for (const auto& t : store->ListTrials(1)) {
    double claimed = -1, verified = -1;
    for (const auto& row : store->ListTransitions(t.id)) {
      if (row.rule == "dispatch.claimed") claimed = row.at;
      if (row.rule == "reset.verified") verified = row.at;
    }
    if (claimed >= 0 && verified >= claimed) busy_ms.push_back((verified - claimed) * 1e3);
  }
  ASSERT_GE(busy_ms.size(), clean) << "fewer verified resets in the audit than clean trials";
  std::sort(busy_ms.begin(), busy_ms.end());
  EXPECT_GT(median_ms, 0.0) << out;
  EXPECT_LT(median_ms, busy_ms[busy_ms.size() / 2]) << out;
  EXPECT_GE(p95_ms, median_ms) << out;
}

TEST(ServiceEndToEnd, SubmitToARunningServe) {
  TempDir dir;
  const std::string db = dir / "serve.db";
  const std::string domain = std::to_string(TestDomain(2));
  auto cell1 =
      StartArena({"cell", "--id", "c1", "--domain", domain, "--speed", "0"}, dir / "c1.log");
  auto cell2 =
      StartArena({"cell", "--id", "c2", "--domain", domain, "--speed", "0"}, dir / "c2.log");
  auto serve = StartArena({"serve", "--db", db, "--domain", domain}, dir / "serve.log");
  ASSERT_EQ(RunArena({"submit", TestCampaign("e2e60.json"), "--db", db}, dir / "submit.out",
                     std::chrono::seconds(30)),
            0)
      << ReadFile(dir / "submit.out");
  ASSERT_TRUE(
      WaitUntil([&] { return CountStates(db, 1)["done"] == 60; }, std::chrono::seconds(120)))
      << ReadFile(dir / "serve.log");
  serve->Signal(SIGTERM);
  auto st = serve->Wait(std::chrono::seconds(40));
  ASSERT_TRUE(st.has_value()) << "serve did not stop on SIGTERM";
  EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) == 0);
  ExpectCampaignConsistent(db, 1, 60);
  // status --json is what scripts read.
  ASSERT_EQ(
      RunArena({"status", "--db", db, "--json"}, dir / "status.json", std::chrono::seconds(20)), 0);
  const std::string status = ReadFile(dir / "status.json");
  EXPECT_NE(status.find("\"done\":60"), std::string::npos) << status;
  EXPECT_NE(status.find("\"id\":\"c1\""), std::string::npos) << status;
}

}  // namespace
}  // namespace arena::test
