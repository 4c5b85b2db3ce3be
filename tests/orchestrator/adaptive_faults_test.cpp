// An adaptive campaign survives SIGKILL of its service: the run killed in
// the middle and restarted chooses exactly the same trials, in the same
// order, for the same reasons, as a run that was never killed.
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "service_support.hpp"

namespace arena::test {
namespace {

constexpr auto kTimeout = std::chrono::seconds(200);

struct Choice {
  int index;
  std::string params, reason;
  bool operator==(const Choice&) const = default;
};

std::vector<Choice> Sequence(const std::string& db) {
  auto store = OpenReadOnly(db);
  std::vector<Choice> out;
  const auto decisions = store->ListDecisions(1);
  for (const auto& t : store->ListTrials(1)) {
    std::string reason;
    for (const auto& d : decisions)
      if (d.trial_id == t.id) reason = d.reason;
    out.push_back({t.index, t.params_json, reason});
  }
  for (const auto& d : decisions)
    if (!d.trial_id) out.push_back({-1, "", d.reason});  // the stop
  return out;
}

bool CampaignDone(const std::string& db) {
  return OpenReadOnly(db)->GetCampaign(1).state == db::CampaignState::kDone;
}

// Runs the campaign under `arena serve` with two cells; kills the service
// with SIGKILL after `kill_after` done trials (0: never) and restarts it.
void RunCampaign(const TempDir& dir, const std::string& name, int domain, int kill_after) {
  const std::string db = dir / (name + ".db");
  const std::string d = std::to_string(TestDomain(domain));
  std::vector<std::unique_ptr<Child>> cells;
  for (const char* id : {"k1", "k2"})
    cells.push_back(StartArena({"cell", "--id", id, "--domain", d, "--speed", "0"},
                               dir / (name + "-" + id + ".log")));
  ASSERT_EQ(RunArena({"submit", TestCampaign("boundary_2d_small.json"), "--db", db},
                     dir / (name + "-submit.log"), std::chrono::seconds(30)),
            0);
  if (kill_after > 0) {
    auto serve = StartArena({"serve", "--db", db, "--domain", d}, dir / (name + "-serve1.log"));
    ASSERT_TRUE(WaitUntil([&] { return CountStates(db, 1)["done"] >= kill_after; }, kTimeout))
        << ReadFile(dir / (name + "-serve1.log"));
    serve->Signal(SIGKILL);
    ASSERT_TRUE(serve->Wait(std::chrono::seconds(10)).has_value());
    EXPECT_FALSE(CampaignDone(db)) << "killed too late to test anything";
  }
  auto serve = StartArena({"serve", "--db", db, "--domain", d}, dir / (name + "-serve2.log"));
  ASSERT_TRUE(WaitUntil([&] { return CampaignDone(db); }, kTimeout))
      << ReadFile(dir / (name + "-serve2.log"));
  serve->Signal(SIGTERM);
  ASSERT_TRUE(serve->Wait(std::chrono::seconds(40)).has_value());
  ExpectCampaignConsistent(db, 1, static_cast<int>(OpenReadOnly(db)->ListTrials(1).size()));
}

TEST(AdaptiveFaults, ServiceKilledMidCampaignChoosesTheSameSequence) {
  TempDir dir;
  RunCampaign(dir, "clean", 35, 0);
  RunCampaign(dir, "killed", 36, 12);  // past the 9-point coarse grid, inside a round
  const auto clean = Sequence(dir / "clean.db");
  const auto killed = Sequence(dir / "killed.db");
  ASSERT_GT(clean.size(), 12u);
  ASSERT_EQ(clean.size(), killed.size());
  for (size_t i = 0; i < clean.size(); ++i) {
    EXPECT_EQ(clean[i].params, killed[i].params) << "trial " << i;
    EXPECT_EQ(clean[i].reason, killed[i].reason) << "trial " << i;
  }
}

}  // namespace
}  // namespace arena::test
