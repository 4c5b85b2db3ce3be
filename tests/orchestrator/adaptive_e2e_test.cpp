// Adaptive campaigns and calibration with real cells (arena processes over
// DDS): the boundary sampler brackets the pivot boundary to its resolution,
// the replicates sampler adds replicates only where the spread is large,
// and calibration recovers a cell's known friction scale and improves the
// predictions of a campaign that uses it.
#include <algorithm>
#include <cmath>
#include <cstdio>
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

// Pipelined rounds (round k+1 decided from rounds <= k-1 with round k
// pending, queued while round k runs) choose the same trials whichever cell
// finishes first: one cell and two cells, same campaign (batch fixed at 2),
// same sequence, same reasons; and each decision says what it was based on.
TEST(AdaptiveE2E, PipelinedRoundsChooseTheSameSequenceOnOneCellAndOnTwo) {
  TempDir dir;
  struct Choice {
    std::string params, reason;
    int round;
  };
  auto run = [&](const std::string& cells, int domain) {
    const std::string db = dir / ("cells" + cells + ".db");
    EXPECT_EQ(RunArena({"run", TestCampaign("boundary_2d_small.json"), "--db", db, "--cells", cells,
                        "--domain", std::to_string(TestDomain(domain)), "--quiet"},
                       dir / ("cells" + cells + ".log"), kRunTimeout),
              0)
        << ReadFile(dir / ("cells" + cells + ".log"));
    auto store = OpenReadOnly(db);
    EXPECT_EQ(store->GetCampaign(1).state, db::CampaignState::kDone);
    std::vector<Choice> out;
    const auto trials = store->ListTrials(1);
    for (const auto& d : store->ListDecisions(1)) {
      std::string params;
      for (const auto& t : trials)
        if (d.trial_id == t.id) params = t.params_json;
      out.push_back({params, d.reason, d.round});
    }
    return std::make_pair(out, store->ListDecisions(1));
  };
  const auto one = run("1", 37).first;
  const auto [two, two_decisions] = run("2", 38);
  ASSERT_GT(one.size(), 12u);
  ASSERT_EQ(one.size(), two.size());
  for (size_t i = 0; i < one.size(); ++i) {
    EXPECT_EQ(one[i].params, two[i].params) << "decision " << i;
    EXPECT_EQ(one[i].reason, two[i].reason) << "decision " << i;
    EXPECT_EQ(one[i].round, two[i].round) << "decision " << i;
  }
  // Round 1 is decided from round 0; later rounds first from the rounds
  // before the last one, that one pending.
  int pipelined = 0;
  for (const auto& d : two_decisions) {
    if (!d.trial_id || d.round < 1) continue;
    const json basis = json::parse(d.basis_json);
    ASSERT_TRUE(basis.contains("known_through_round")) << d.basis_json;
    const int known = basis["known_through_round"].get<int>();
    if (basis["pending_round"].is_null()) {
      EXPECT_EQ(known, d.round - 1);
    } else {
      EXPECT_EQ(known, d.round - 2);
      EXPECT_EQ(basis["pending_round"].get<int>(), d.round - 1);
      EXPECT_FALSE(basis["pending_trials"].empty());
      EXPECT_NE(d.reason.find("pending"), std::string::npos) << d.reason;
      ++pipelined;
    }
  }
  EXPECT_GT(pipelined, 0);
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
      if (p.status == db::PredictionStatus::kOk && p.force_error) {
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
  // The fingers slide in these trials: the data bound their friction.
  const json& profile = r["params"]["mu_fingers"]["profile"];
  EXPECT_TRUE(profile["identified"].get<bool>()) << text;
  EXPECT_LT(profile["range"][0].get<double>(), scale) << text;
  EXPECT_GT(profile["range"][1].get<double>(), scale) << text;
  EXPECT_TRUE(r["applied"].get<bool>());
  EXPECT_LT(r["report"]["heldout_loss"]["after"].get<double>(),
            r["report"]["heldout_loss"]["before"].get<double>());
  // Pins issue 26: the fit predicts from the start each trial's cell
  // measured, as evaluate does (it predicted from the planned pose); these
  // cells place each trial off its planned pose.
  EXPECT_EQ(r["start"]["from"], "measured") << text;
  EXPECT_GT(r["start"]["trials_moved"].get<int>(), 0) << text;

  // Fitting arena's model at other settings than the campaign's: a setting
  // that is not arena's, or a bad value, is refused naming it; nothing stored.
  for (const char* bad : {R"({"timestep": 0.001})", R"({"dt": -1})", "[1]", "{"}) {
    const std::string log = dir / "bad_settings.log";
    EXPECT_EQ(RunArena({"calibrate", "--db", db, "--campaign", "1", "--params", "mu_fingers",
                        "--predictor-settings", bad},
                       log, std::chrono::seconds(60)),
              2)
        << bad;
    EXPECT_NE(ReadFile(log).find("--predictor-settings"), std::string::npos) << ReadFile(log);
  }
  EXPECT_EQ(OpenReadOnly(db)->ListCalibrations(1).size(), 1u);
  // The profile drawn: one panel per parameter; a calibration that does not
  // exist is refused.
  EXPECT_EQ(RunArena({"plot", "--db", db, "--calibration", "1", "--out", dir / "profile.svg"},
                     dir / "plot.log", std::chrono::seconds(30)),
            0)
      << ReadFile(dir / "plot.log");
  EXPECT_NE(ReadFile(dir / "profile.svg").find("data-name=\"loss mu_fingers\""), std::string::npos);
  EXPECT_EQ(RunArena({"plot", "--db", db, "--calibration", "9", "--out", dir / "none.svg"},
                     dir / "plot9.log", std::chrono::seconds(30)),
            2);

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

  // --from planned fits from the scene's pose and says so; another value is
  // refused naming the option, nothing stored.
  const std::string planned = dir / "planned.json";
  ASSERT_EQ(RunArena({"calibrate", "--db", db, "--campaign", "1", "--params", "mu_fingers",
                      "--bootstrap", "2", "--max-evaluations", "10", "--from", "planned", "--json"},
                     planned, std::chrono::seconds(120)),
            0)
      << ReadFile(planned);
  const std::string planned_text = ReadFile(planned);
  EXPECT_EQ(json::parse(planned_text.substr(planned_text.find('{')))["start"]["from"], "planned");
  const std::size_t stored = OpenReadOnly(db)->ListCalibrations(1).size();
  EXPECT_EQ(RunArena({"calibrate", "--db", db, "--campaign", "1", "--params", "mu_fingers",
                      "--from", "sideways"},
                     dir / "from.log", std::chrono::seconds(60)),
            2);
  EXPECT_NE(ReadFile(dir / "from.log").find("--from"), std::string::npos);
  EXPECT_EQ(OpenReadOnly(db)->ListCalibrations(1).size(), stored);
}

// --predictor mujoco: cells whose physics is MuJoCo (--backend mujoco) with a
// true friction 1.3x the scenes' (+-1 % per trial); the fit runs MuJoCo as the
// predictor, each trial's model built once, within a small budget (12
// evaluations of 17 training trials at a 1 ms step: ~5 s). Asserted: the
// scale within 10 % (1.3642 in every run: each trial's truth is its own,
// whichever cell ran it), the budget, the prepared models, a held-out error
// that improves, the calibration stored with its predictor and usable only by
// a campaign predicting with MuJoCo. The 10 % is a stated tolerance, not a
// margin found by trying: on these short pushes MuJoCo's coupled sliding
// fingers chatter, and other seeds of the same campaign gave 1.353-1.392
// (docs/adaptive.md).
TEST(AdaptiveE2E, MujocoCalibrationRecoversTheFrictionScaleWithinItsBudget) {
  TempDir dir;
  const std::string db = dir / "mj.db";
  json grid = json::parse(ReadFile(TestCampaign("calibration_grid.json")));
  grid["scene"] = std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json";
  grid["replicates"] = 4;  // 24 short pushes: 4 held-out trials alone are too noisy a judge
  const std::string campaign = dir / "grid.json";
  std::ofstream(campaign) << grid.dump();
  ASSERT_EQ(RunArena({"run", campaign, "--db", db, "--cells", "2", "--domain",
                      std::to_string(TestDomain(35)), "--quiet", "--backend", "mujoco",
                      "--cell-defects", TestCampaign("friction_scaled_cell.json")},
                     dir / "run.log", kRunTimeout),
            0)
      << ReadFile(dir / "run.log");

  const std::string out = dir / "calibrate.json";
  ASSERT_EQ(RunArena({"calibrate", "--db", db, "--campaign", "1", "--params", "mu_fingers",
                      "--predictor", "mujoco", "--predictor-settings", R"({"timestep": 0.001})",
                      "--max-evaluations", "12", "--bootstrap", "20", "--threads", "2", "--json"},
                     out, std::chrono::seconds(240)),
            0)
      << ReadFile(out);
  const std::string text = ReadFile(out);
  const json r = json::parse(text.substr(text.find('{')));
  EXPECT_EQ(r["predictor"], "mujoco");
  const double scale = r["params"]["mu_fingers"]["scale"].get<double>();
  std::printf("mujoco calibration: mu_fingers scale %.4f (true 1.3), held-out loss %.4g -> %.4g\n",
              scale, r["report"]["heldout_loss"]["before"].get<double>(),
              r["report"]["heldout_loss"]["after"].get<double>());
  EXPECT_NEAR(scale, 1.3, 0.13) << text;  // within 10 %
  EXPECT_TRUE(r["applied"].get<bool>());
  EXPECT_LT(r["report"]["heldout_loss"]["after"].get<double>(),
            r["report"]["heldout_loss"]["before"].get<double>())
      << text;
  EXPECT_LE(r["report"]["train_loss"]["after"].get<double>(),
            r["report"]["train_loss"]["before"].get<double>());
  // The budget held: at most 12 evaluations of the training trials, the
  // profile's scales (mujoco's default 6 over the bounds, 6 near the fit and
  // the fit), the held-out trials twice; the reuse bootstrap simulated
  // nothing more.
  const auto train = r["report"]["train_ids"].size(), held = r["report"]["heldout_ids"].size();
  EXPECT_EQ(train + held, 24u);
  EXPECT_LE(r["report"]["evaluations"].get<int>(), 12);
  EXPECT_LE(r["report"]["simulations"].get<std::size_t>(), (12 + 13) * train + 2 * held);
  EXPECT_TRUE(r["params"]["mu_fingers"].contains("profile")) << text;
  EXPECT_EQ(r["report"]["bootstrap_method"], "reuse");
  // Every run on the model its trial's scene built once (none rebuilt).
  EXPECT_EQ(r["report"]["models_reused"].get<std::size_t>(),
            r["report"]["simulations"].get<std::size_t>());
  const double lo = r["params"]["mu_fingers"]["ci95"][0].get<double>();
  const double hi = r["params"]["mu_fingers"]["ci95"][1].get<double>();
  EXPECT_LE(lo, scale);
  EXPECT_GE(hi, scale);

  auto store = OpenReadOnly(db);
  const auto cals = store->ListCalibrations(1);
  ASSERT_EQ(cals.size(), 1u);
  const json settings = json::parse(cals[0].settings_json);
  EXPECT_EQ(settings["predictor"], "mujoco");
  EXPECT_DOUBLE_EQ(settings["predictor_settings"]["timestep"].get<double>(), 0.001);
  EXPECT_DOUBLE_EQ(settings["loss_scales"]["force_window_s"].get<double>(), 0.04);

  // Fitted for MuJoCo: refused by a campaign predicting with arena, nothing stored.
  json spec = grid;
  spec["prediction"] = {{"calibration", 1}};
  const std::string arena_spec = dir / "arena_calibrated.json";
  std::ofstream(arena_spec) << spec.dump();
  EXPECT_EQ(
      RunArena({"submit", arena_spec, "--db", db}, dir / "refused.log", std::chrono::seconds(30)),
      2)
      << ReadFile(dir / "refused.log");
  EXPECT_NE(ReadFile(dir / "refused.log").find("fitted for the mujoco predictor"),
            std::string::npos)
      << ReadFile(dir / "refused.log");
  // ... and accepted by one predicting with MuJoCo.
  spec["prediction"] = {{"predictor", "mujoco"}, {"timestep", 0.001}, {"calibration", 1}};
  const std::string mujoco_spec = dir / "mujoco_calibrated.json";
  std::ofstream(mujoco_spec) << spec.dump();
  EXPECT_EQ(
      RunArena({"submit", mujoco_spec, "--db", db}, dir / "accepted.log", std::chrono::seconds(30)),
      0)
      << ReadFile(dir / "accepted.log");
  EXPECT_EQ(OpenReadOnly(db)->ListCampaigns().size(), 2u);
}

}  // namespace
}  // namespace arena::test
