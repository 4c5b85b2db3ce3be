// The honest trade (issue 14) on known inputs: the noise floor on synthetic
// replicates with a known spread, a diverging prediction counted as its own
// outcome, mode agreement that moves when modes differ, budgets of each
// kind (error, time, floor multiple), and the default grid for patch scenes.
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/evaluation.hpp"
#include "arena/assessment/noise_floor.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/assessment/predictor.hpp"
#include "arena/assessment/scoring.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace arena::assessment {
namespace {

mechanics::Scene Canonical() {
  std::ifstream f(std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json");
  std::stringstream text;
  text << f.rdbuf();
  auto scene = mechanics::ParseScene(text.str());
  scene.duration = 0.2;
  return scene;
}

TEST(NoiseFloor, KnownSpreadOfSyntheticReplicates) {
  // Condition c: three replicates at x = -d, 0, +d (d = (c + 1) mm) and turned
  // -a, 0, +a about z (a = (c + 1) mrad): Bessel's spread is exactly d and a.
  std::vector<FinalPose> finals;
  std::int64_t id = 1;
  for (int c = 0; c < 5; ++c) {
    const double d = (c + 1) * 1e-3, a = (c + 1) * 1e-3;
    for (int k = -1; k <= 1; ++k) {
      FinalPose f;
      f.trial_id = id++;
      f.condition = c;
      f.position = Eigen::Vector3d(0.1 + k * d, 0.02, -0.01);
      f.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(k * a, Eigen::Vector3d::UnitZ()));
      finals.push_back(f);
    }
  }
  // A condition with one replicate has no spread and is left out.
  finals.push_back(FinalPose{id++, 9, Eigen::Vector3d(5, 5, 5), Eigen::Quaterniond::Identity()});
  const auto spreads = ReplicateSpreads(finals);
  ASSERT_EQ(spreads.size(), 5u);
  for (int c = 0; c < 5; ++c) {
    EXPECT_NEAR(spreads[c].position, (c + 1) * 1e-3, 1e-12) << c;
    EXPECT_NEAR(spreads[c].angle, (c + 1) * 1e-3, 1e-9) << c;
    EXPECT_EQ(spreads[c].replicates, 3);
  }
  const auto floor = ComputeNoiseFloor(finals);
  ASSERT_TRUE(floor);
  EXPECT_EQ(floor->conditions, 5);
  EXPECT_EQ(floor->trials, 15);
  EXPECT_NEAR(floor->position_median, 3e-3, 1e-12);
  EXPECT_NEAR(floor->position_p95, 4.8e-3, 1e-12);  // rank 3.8 of 1..5 mm
  EXPECT_NEAR(floor->angle_median, 3e-3, 1e-9);
  EXPECT_FALSE(ComputeNoiseFloor({finals.back()}));
}

TEST(Divergence, ABlownUpPredictionIsItsOwnOutcome) {
  const auto scene = Canonical();
  auto result = mechanics::Simulate(scene);
  ASSERT_EQ(result.status, mechanics::SimulationStatus::kOk) << result.error;
  const auto truth = result.samples;
  EXPECT_FALSE(DivergenceReason(scene, result.samples, truth));
  EXPECT_EQ(ScoreSimulation(scene, result, truth).status, db::PredictionStatus::kOk);

  // The object flies 1 m away: far beyond the pusher's 2 mm plus the object's 10 cm.
  auto flying = result;
  flying.samples.back().position.x() += 1.0;
  const auto why = DivergenceReason(scene, flying.samples, truth);
  ASSERT_TRUE(why);
  EXPECT_NE(why->find("diverged"), std::string::npos) << *why;
  const auto p = ScoreSimulation(scene, flying, truth);
  EXPECT_EQ(p.status, db::PredictionStatus::kDiverged);
  EXPECT_STREQ(db::ToString(p.status), "diverged");  // the stored text

  // Every finger separated at the end while the truth holds: left the grasp.
  auto dropped = result;
  for (std::size_t i = 0; i < scene.fingers.size(); ++i)
    dropped.samples.back().contacts[i].mode = mechanics::ContactMode::kSeparate;
  EXPECT_FALSE(DivergenceReason(scene, dropped.samples, truth));  // one sample: a flicker
  for (std::size_t k = dropped.samples.size() * 3 / 4; k < dropped.samples.size(); ++k)
    for (std::size_t i = 0; i < scene.fingers.size(); ++i)
      dropped.samples[k].contacts[i].mode = mechanics::ContactMode::kSeparate;
  const auto left = DivergenceReason(scene, dropped.samples, truth);
  ASSERT_TRUE(left);
  EXPECT_NE(left->find("left the grasp"), std::string::npos) << *left;

  // A NaN is a divergence, not a number to average.
  auto nan = result;
  nan.samples[3].velocity.x() = std::nan("");
  EXPECT_EQ(ScoreSimulation(scene, nan, truth).status, db::PredictionStatus::kDiverged);

  // In a summary it is counted and listed, never in the error distribution.
  std::vector<TrialEvaluation> rows;
  for (int t = 1; t <= 40; ++t) {
    TrialEvaluation r;
    r.trial_id = t;
    r.truth_duration_s = 0.2;
    r.prediction = t == 7 ? p : ScoreSimulation(scene, result, truth);
    r.prediction.wall_s = 1e-3;
    rows.push_back(r);
  }
  const auto report = Summarise(ArenaSettings({scene.model}), rows, {ParseBudget("1mm")});
  const auto& s = report.settings[0];
  EXPECT_EQ(s.trials, 40);
  EXPECT_EQ(s.ok, 39);
  EXPECT_EQ(s.diverged, 1);
  ASSERT_EQ(s.diverged_trials.size(), 1u);
  EXPECT_EQ(s.diverged_trials[0].trial_id, 7);
  EXPECT_NEAR(s.position->max, 0, 1e-12);  // the 1 m is not in it
  EXPECT_FALSE(s.eligible());
  EXPECT_FALSE(s.pareto);
  // 1 of 40: the p95 over all trials (R-7 rank 37.05, the divergence counted as +inf at
  // rank 39) stays finite, so the p95 budget holds; three divergences (7.5 %) break it.
  EXPECT_TRUE(s.within_budget);
  rows[8].prediction = p;
  rows[9].prediction = p;
  const auto two = Summarise(ArenaSettings({scene.model}), rows, {ParseBudget("1mm")});
  EXPECT_EQ(two.settings[0].diverged, 3);
  EXPECT_FALSE(two.settings[0].within_budget);
  EXPECT_TRUE(ToJson(two)["settings"][0]["position_p95_all_trials_m"].is_null());
}

TEST(ModeAgreement, MovesWhenPredictedAndTrueModesDiffer) {
  using mechanics::ContactMode;
  std::vector<mechanics::TrajectorySample> truth(10), predicted(10);
  for (int i = 0; i < 10; ++i) {
    truth[i].contacts.resize(2);
    predicted[i].contacts.resize(2);
    for (auto& c : truth[i].contacts) c.mode = ContactMode::kStick;
    for (auto& c : predicted[i].contacts) c.mode = ContactMode::kStick;
  }
  EXPECT_DOUBLE_EQ(ScorePrediction(predicted, truth).mode_agreement, 1.0);
  for (int i = 5; i < 10; ++i) predicted[i].contacts[1].mode = ContactMode::kSlide;
  EXPECT_DOUBLE_EQ(ScorePrediction(predicted, truth).mode_agreement, 15.0 / 20);

  // The summary shows the bad tail (5th percentile, minimum) even when the
  // median is 100 %.
  std::vector<TrialEvaluation> rows;
  for (int t = 1; t <= 20; ++t) {
    TrialEvaluation r;
    r.trial_id = t;
    r.prediction.final_position_error = 0;
    r.prediction.final_angle_error = 0;
    r.prediction.force_error = 0;
    r.prediction.mode_agreement = t == 20 ? 0.5 : 1.0;
    rows.push_back(r);
  }
  const auto report = Summarise(ArenaSettings({mechanics::ModelOptions{}}), rows, {});
  const auto& m = *report.settings[0].mode_agreement;
  EXPECT_DOUBLE_EQ(m.median, 1.0);
  EXPECT_LT(m.p95, 1.0);         // the 5th percentile
  EXPECT_DOUBLE_EQ(m.max, 0.5);  // the minimum
}

// Two settings: A cheap (1 ms) with p95 3 mm, B dear (5 ms) with p95 1 mm.
std::vector<TrialEvaluation> TwoSettings() {
  std::vector<TrialEvaluation> rows;
  for (int t = 1; t <= 20; ++t) {
    for (std::size_t s = 0; s < 2; ++s) {
      TrialEvaluation r;
      r.trial_id = t;
      r.setting = s;
      r.truth_duration_s = 0.5;
      const double e = (s == 0 ? 3e-3 : 1e-3) * t / 20.0;
      r.prediction.final_position_error = e;
      r.prediction.final_angle_error = e;
      r.prediction.force_error = 0;
      r.prediction.mode_agreement = 1;
      r.prediction.wall_s = s == 0 ? 1e-3 : 5e-3;
      rows.push_back(r);
    }
  }
  return rows;
}

TEST(Budgets, ErrorTimeAndFloorMultiple) {
  const auto settings =
      ArenaSettings({mechanics::ModelOptions{8, 3, 0.008, mechanics::Reduce::kAuto},
                     mechanics::ModelOptions{8, 3, 0.002, mechanics::Reduce::kAuto}});
  const auto rows = TwoSettings();
  // Error budget: the cheapest within it.
  auto r = Summarise(settings, rows, {ParseBudget("5mm")});
  ASSERT_TRUE(r.recommended);
  EXPECT_EQ(*r.recommended, 0u);
  r = Summarise(settings, rows, {ParseBudget("2mm")});
  ASSERT_TRUE(r.recommended);
  EXPECT_EQ(*r.recommended, 1u);
  EXPECT_NE(r.recommendation.find("cheapest"), std::string::npos) << r.recommendation;
  r = Summarise(settings, rows, {ParseBudget("0.5mm")});
  EXPECT_FALSE(r.recommended);
  // Time budget alone: the most accurate within it.
  r = Summarise(settings, rows, {ParseBudget("10ms")});
  ASSERT_TRUE(r.recommended);
  EXPECT_EQ(*r.recommended, 1u);
  EXPECT_NE(r.recommendation.find("most accurate"), std::string::npos) << r.recommendation;
  r = Summarise(settings, rows, {ParseBudget("2ms")});
  ASSERT_TRUE(r.recommended);
  EXPECT_EQ(*r.recommended, 0u);
  r = Summarise(settings, rows, {ParseBudget("0.5ms")});
  EXPECT_FALSE(r.recommended);
  // Floor multiple: floor median 1 mm; 1.5 floor = 1.5 mm admits only B.
  NoiseFloor floor;
  floor.conditions = 4;
  floor.position_median = 1e-3;
  floor.angle_median = 1e-3;
  r = Summarise(settings, rows, {ParseBudget("1.5floor")}, floor);
  ASSERT_TRUE(r.recommended);
  EXPECT_EQ(*r.recommended, 1u);
  EXPECT_NEAR(r.budgets[0].limit, 1.5e-3, 1e-15);
  EXPECT_NE(r.recommendation.find("noise floor"), std::string::npos) << r.recommendation;
  const auto j = ToJson(r);
  EXPECT_NEAR(j["settings"][1]["position_floor_multiple"]["p95"].get<double>(),
              r.settings[1].position->p95 / 1e-3, 1e-12);
  EXPECT_NEAR(j["noise_floor"]["position_m"]["median"].get<double>(), 1e-3, 1e-15);
  // Without a floor a floor budget can be met by nothing.
  r = Summarise(settings, rows, {ParseBudget("1.5floor")});
  EXPECT_FALSE(r.recommended);
  // Time per simulated second: 1 ms / 0.5 s.
  EXPECT_NEAR(r.settings[0].time_per_sim_s->median, 2e-3, 1e-15);
}

TEST(DefaultGrid, NeverInvalidForTheScenes) {
  auto patch = Canonical();
  patch.fingers[1].type = mechanics::ContactType::kPatch;
  patch.fingers[1].radius = 0.005;
  patch.model.points = 3;
  mechanics::ValidateScene(patch);
  auto short_trial = Canonical();
  short_trial.duration = 0.005;  // shorter than an 8 ms step
  const auto grid = DefaultArenaGrid({Canonical(), patch, short_trial});
  ASSERT_FALSE(grid.empty());
  for (const auto& m : grid) {
    EXPECT_GE(m.points, 3);
    EXPECT_LE(m.dt, 0.005);
    for (auto s : {Canonical(), patch, short_trial}) {
      s.model = m;
      EXPECT_NO_THROW(mechanics::ValidateScene(s)) << ModelKey(m);
    }
  }
  EXPECT_EQ(DefaultArenaGrid({Canonical()}).size(), 16u);
}

// MuJoCo's grid takes contact softness too (solref, solimp): a setting's key
// names them only when they differ from the simulator's defaults, so keys
// of the default grid stay what they were.
TEST(MujocoGrid, SolrefAndSolimpAreGridAxesNamedOnlyWhenNotDefault) {
  MujocoGrid grid;
  grid.timestep = {0.001};
  grid.solref = {{0.002, 1.0}, {0.01, 1.0}};
  grid.solimp = {{0.9, 0.95, 0.001, 0.5, 2.0}, {0.95, 0.99, 0.001, 0.5, 2.0}};
  const auto p = MakeMujocoPredictor(grid);
  ASSERT_EQ(p->settings().size(), 4u);
  std::set<std::string> keys;
  for (const auto& s : p->settings()) keys.insert(s.key);
  EXPECT_TRUE(keys.count("mujoco_ts0.001_elliptic_ns0")) << *keys.begin();
  EXPECT_TRUE(keys.count("mujoco_ts0.001_elliptic_ns0_sr0.01:1"));
  EXPECT_TRUE(keys.count("mujoco_ts0.001_elliptic_ns0_si0.95:0.99:0.001:0.5:2"));
  EXPECT_TRUE(keys.count("mujoco_ts0.001_elliptic_ns0_sr0.01:1_si0.95:0.99:0.001:0.5:2"));
  for (const auto& s : p->settings()) {
    if (s.key.find("_sr") != std::string::npos) {
      EXPECT_NE(s.knobs_json.find(R"("solref":[0.01,1.0])"), std::string::npos) << s.knobs_json;
    }
  }
  // A campaign's own MuJoCo prediction is keyed the same way.
  EXPECT_EQ(MujocoSettingKey(nlohmann::json::object()), "mujoco_ts0.0005_elliptic_ns0");
  EXPECT_EQ(MujocoSettingKey({{"timestep", 0.001}, {"solref", {0.002, 1.0}}}),
            "mujoco_ts0.001_elliptic_ns0");
  EXPECT_EQ(MujocoSettingKey({{"solimp", {0.95, 0.99, 0.001, 0.5, 2.0}}}),
            "mujoco_ts0.0005_elliptic_ns0_si0.95:0.99:0.001:0.5:2");
  grid.solref = {{0.01, 1.0}, {0.01, 1.0}};
  EXPECT_THROW(MakeMujocoPredictor(grid), std::invalid_argument);
  grid.solref = {{-1, 1.0}};
  EXPECT_THROW(MakeMujocoPredictor(grid), std::invalid_argument);  // the simulator refuses it
}

}  // namespace
}  // namespace arena::assessment
