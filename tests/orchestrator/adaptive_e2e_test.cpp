// Adaptive campaigns and calibration with real cells (arena processes over
// DDS): the boundary sampler brackets the pivot boundary to its resolution,
// the replicates sampler adds replicates only where the spread is large,
// and calibration recovers a cell's known friction scale and improves the
// predictions of a campaign that uses it.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "service_support.hpp"

namespace arena::test {
namespace {

using nlohmann::json;
constexpr auto kRunTimeout = std::chrono::seconds(240);

int RunCampaignFile(const TempDir& dir, const std::string& campaign, const std::string& db,
                    int domain, const std::vector<std::string>& extra = {}) {
  std::vector<std::string> args = {"run",      TestCampaign(campaign),
                                   "--db",     db,
                                   "--cells",  "2",
                                   "--domain", std::to_string(TestDomain(domain)),
                                   "--quiet"};
  args.insert(args.end(), extra.begin(), extra.end());
  return RunArena(args, dir / (campaign + ".run.log"), kRunTimeout);
}

TEST(AdaptiveE2E, BoundarySamplerBracketsThePivotToItsResolution) {
  TempDir dir;
  const std::string db = dir / "b1.db";
  ASSERT_EQ(RunCampaignFile(dir, "boundary_1d.json", db, 31), 0)
      << ReadFile(dir / "boundary_1d.json.run.log");
  auto store = OpenReadOnly(db);
  EXPECT_EQ(store->GetCampaign(1).state, db::CampaignState::kDone);
  const auto trials = store->ListTrials(1);
  const auto decisions = store->ListDecisions(1);
  ASSERT_GE(trials.size(), 6u);
  EXPECT_LE(trials.size(), 30u);
  // One decision per trial, and the stop.
  ASSERT_EQ(decisions.size(), trials.size() + 1);
  EXPECT_FALSE(decisions.back().trial_id);
  EXPECT_NE(decisions.back().reason.find("resolved"), std::string::npos) << decisions.back().reason;

  // Classes along the offset change exactly once, and the bracket is within
  // 2 x resolution of the range (the estimate, its midpoint, within 1 x).
  std::vector<std::pair<double, bool>> points;
  for (const auto& t : trials) {
    ASSERT_EQ(t.state, db::TrialState::kDone) << t.id;
    const double offset = json::parse(t.params_json)["pivot_offset"].get<double>();
    const auto gt = store->ReadGroundTruth(t.id);
    const auto& q0 = gt.samples.front().object_pose;
    const auto& q1 = gt.samples.back().object_pose;
    const double dot = std::abs(q0[3] * q1[3] + q0[4] * q1[4] + q0[5] * q1[5] + q0[6] * q1[6]);
    const double angle = 2 * std::acos(std::min(1.0, dot));
    points.emplace_back(offset, angle > 0.1);
  }
  std::sort(points.begin(), points.end());
  int changes = 0;
  double below = 0, above = 0;
  for (size_t i = 1; i < points.size(); ++i) {
    if (points[i].second != points[i - 1].second) {
      ++changes;
      below = points[i - 1].first;
      above = points[i].first;
    }
  }
  // Exactly once: each trial's start pose is its own (reset::PlacementForTrial),
  // so which cell ran a trial next to the boundary cannot flip its class.
  EXPECT_EQ(changes, 1);
  EXPECT_FALSE(points.front().second);  // little offset: no pivot
  EXPECT_TRUE(points.back().second);    // at the edge: pivots
  EXPECT_LE(above - below, 2 * 0.03 * 0.007 + 1e-9);
  // A grid to that resolution would need 1 / 0.03 + 1 = 35 points.
  EXPECT_LE(trials.size(), 35u / 2);

  // Why each trial was chosen, and what is being refined.
  const std::string q = dir / "q.txt";
  ASSERT_EQ(RunArena({"query", "--db", db, "--campaign", "1", "--decisions", "--format", "csv"}, q,
                     std::chrono::seconds(30)),
            0);
  const std::string decisions_csv = ReadFile(q);
  EXPECT_NE(decisions_csv.find("coarse grid point 1 of 5"), std::string::npos) << decisions_csv;
  EXPECT_NE(decisions_csv.find("on the estimated boundary between trial"), std::string::npos);
  const std::string s = dir / "status.txt";
  ASSERT_EQ(RunArena({"status", "--db", db, "1"}, s, std::chrono::seconds(30)), 0);
  EXPECT_NE(ReadFile(s).find("refining pivoted boundary in pivot_offset"), std::string::npos)
      << ReadFile(s);
  EXPECT_NE(ReadFile(s).find("finished: resolved"), std::string::npos) << ReadFile(s);
  ExpectCampaignConsistent(db, 1, static_cast<int>(trials.size()));
}

TEST(AdaptiveE2E, ReplicatesGoWhereTheSpreadIsLarge) {
  TempDir dir;
  const std::string db = dir / "r.db";
  ASSERT_EQ(RunCampaignFile(dir, "replicates.json", db, 32,
                            {"--cell-defects", TestCampaign("velocity_noise_cell.json")}),
            0)
      << ReadFile(dir / "replicates.json.run.log");
  auto store = OpenReadOnly(db);
  EXPECT_EQ(store->GetCampaign(1).state, db::CampaignState::kDone);
  int per_condition[2] = {0, 0};
  for (const auto& t : store->ListTrials(1)) {
    ASSERT_EQ(t.state, db::TrialState::kDone);
    ++per_condition[t.condition];
  }
  // The 0.5 mm push spreads its final position by ~15 um (3 % velocity noise):
  // on target after min_replicates. The 8 mm push spreads by ~0.24 mm: more.
  EXPECT_EQ(per_condition[0], 3);
  EXPECT_GT(per_condition[1], 3);
  EXPECT_LE(per_condition[1], 6);
  const auto decisions = store->ListDecisions(1);
  ASSERT_FALSE(decisions.empty());
  EXPECT_FALSE(decisions.back().trial_id);
  bool saw_ci_reason = false;
  for (const auto& d : decisions)
    saw_ci_reason |= d.reason.find("condition 1: 95 % CI of the mean final position") == 0;
  EXPECT_TRUE(saw_ci_reason);
}

double MeanForceError(const db::Store& store, std::int64_t campaign) {
  double sum = 0;
  int n = 0;
  for (const auto& t : store.ListTrials(campaign)) {
    for (const auto& p : store.ListPredictions(t.id)) {
      if (p.status == "ok" && p.force_error) {
        sum += *p.force_error;
        ++n;
      }
    }
  }
  return n ? sum / n : NAN;
}

TEST(AdaptiveE2E, CalibrationRecoversTheCellsFrictionScale) {
  TempDir dir;
  const std::string db = dir / "cal.db";
  const std::string cell_defects = TestCampaign("friction_scaled_cell.json");
  ASSERT_EQ(RunCampaignFile(dir, "calibration_grid.json", db, 33, {"--cell-defects", cell_defects}),
            0)
      << ReadFile(dir / "calibration_grid.json.run.log");

  const std::string out = dir / "calibrate.json";
  ASSERT_EQ(RunArena({"calibrate", "--db", db, "--campaign", "1", "--params", "mu_fingers",
                      "--bootstrap", "4", "--json"},
                     out, std::chrono::seconds(120)),
            0)
      << ReadFile(out);
  const std::string text = ReadFile(out);
  const json r = json::parse(text.substr(text.find('{')));
  const double scale = r["params"]["mu_fingers"]["scale"].get<double>();
  EXPECT_NEAR(scale, 1.3, 0.13) << text;  // within 10 %
  EXPECT_NEAR(r["params"]["mu_fingers"]["value"].get<double>(), 0.65, 0.065);
  EXPECT_TRUE(r["applied"].get<bool>());
  EXPECT_LT(r["report"]["heldout_loss"]["after"].get<double>(),
            r["report"]["heldout_loss"]["before"].get<double>());

  // The same campaign predicted with the calibration: closer to the truth.
  json spec = json::parse(ReadFile(TestCampaign("calibration_grid.json")));
  spec["name"] = "calibrated";
  spec["scene"] = std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json";
  spec["prediction"]["calibration"] = 1;
  const std::string calibrated = dir / "calibrated.json";
  std::ofstream(calibrated) << spec.dump();
  ASSERT_EQ(RunArena({"run", calibrated, "--db", db, "--cells", "2", "--domain",
                      std::to_string(TestDomain(34)), "--quiet", "--cell-defects", cell_defects},
                     dir / "calibrated.log", kRunTimeout),
            0)
      << ReadFile(dir / "calibrated.log");
  auto store = OpenReadOnly(db);
  const double before = MeanForceError(*store, 1), after = MeanForceError(*store, 2);
  // Closer by nearly half. The figure is reproducible to the last bit (1.0670
  // N before, 0.5697 N after, in every run): each trial starts at its own
  // placement (reset::PlacementForTrial), whichever cell ran it. Not below
  // 0.5 as before trials started off their planned pose (issue 12): the
  // prediction starts at the planned pose, and calibrating friction cannot
  // remove the start-pose error's share.
  EXPECT_LT(after, 0.6 * before) << "force error before " << before << " N, after " << after;
  EXPECT_NE(store->GetCampaign(2).spec_json.find("\"calibrated\""), std::string::npos);

  // A calibration that does not exist is refused at submit, nothing stored.
  spec["prediction"]["calibration"] = 99;
  std::ofstream(calibrated) << spec.dump();
  EXPECT_EQ(RunArena({"submit", calibrated, "--db", db}, dir / "bad.log", std::chrono::seconds(30)),
            2);
  EXPECT_EQ(OpenReadOnly(db)->ListCampaigns().size(), 2u);
}

}  // namespace
}  // namespace arena::test
