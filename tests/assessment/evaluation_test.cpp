// The evaluation logic of `arena evaluate` on known inputs: percentiles,
// budgets, the Pareto front and the recommendation
// (assessment/include/arena/assessment/evaluation.hpp).
#include <cmath>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/evaluation.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {
namespace {

TEST(EvaluationPercentile, InterpolatesBetweenClosestRanks) {
  EXPECT_DOUBLE_EQ(Percentile({3, 1, 2}, 0.5), 2);
  EXPECT_DOUBLE_EQ(Percentile({1, 2, 3, 4}, 0.5), 2.5);
  EXPECT_DOUBLE_EQ(Percentile({7}, 0.95), 7);
  // numpy.percentile(range(1, 101), 95) == 95.05
  std::vector<double> v;
  for (int i = 1; i <= 100; ++i) v.push_back(i);
  EXPECT_NEAR(Percentile(v, 0.95), 95.05, 1e-12);
  EXPECT_DOUBLE_EQ(Percentile(v, 0), 1);
  EXPECT_DOUBLE_EQ(Percentile(v, 1), 100);
  EXPECT_THROW(Percentile({}, 0.5), std::invalid_argument);
  EXPECT_THROW(Percentile({1}, 1.5), std::invalid_argument);
  EXPECT_THROW(Percentile({1}, std::nan("")), std::invalid_argument);
}

// A prediction's key names every knob that changes its answer: two settings
// that differ only in pads, cone or inertia stored under one key would let
// one be read back as the other's prediction. The bare key is the
// polyhedral cone with carried steps, as stored before issue 31 made the
// aligned cone and "auto" the defaults: the defaults' key names both.
TEST(ModelKeys, NameEveryKnobThatIsNotItsDefault) {
  mechanics::ModelOptions m;
  EXPECT_EQ(ModelKey(m), "g8_k3_dt0.004_auto_cone-aligned_inertia-auto");
  m.cone = mechanics::ConeModel::kPolyhedral;
  m.inertia = mechanics::InertiaModel::kCarried;
  EXPECT_EQ(ModelKey(m), "g8_k3_dt0.004_auto");
  m.inertia = mechanics::InertiaModel::kAuto;
  EXPECT_EQ(ModelKey(m), "g8_k3_dt0.004_auto_inertia-auto");
  m.cone = mechanics::ConeModel::kAligned;
  m.pads = mechanics::PadModel::kRigid;
  m.contacts = mechanics::ContactTracking::kFixed;
  EXPECT_EQ(ModelKey(m), "g8_k3_dt0.004_auto_fixed_pads-rigid_cone-aligned_inertia-auto");
  mechanics::ModelOptions quasi_static;
  quasi_static.inertia = mechanics::InertiaModel::kQuasiStatic;
  EXPECT_EQ(ModelKey(quasi_static), "g8_k3_dt0.004_auto_cone-aligned_inertia-quasi_static");
}

TEST(EvaluationGrid, CrossProductInOrderAndBadListsRefused) {
  FidelityGrid g;
  g.facets = {4, 8};
  g.points = {2, 3, 5};
  g.dt = {0.004, 0.002};
  g.reduce = {mechanics::Reduce::kAuto};
  const auto m = ExpandGrid(g);
  ASSERT_EQ(m.size(), 12u);
  EXPECT_EQ(ModelKey(m[0]), "g4_k2_dt0.004_auto_cone-aligned_inertia-auto");
  EXPECT_EQ(ModelKey(m[1]), "g4_k2_dt0.002_auto_cone-aligned_inertia-auto");
  EXPECT_EQ(ModelKey(m[11]), "g8_k5_dt0.002_auto_cone-aligned_inertia-auto");
  auto bad = g;
  bad.facets = {};
  EXPECT_THROW(ExpandGrid(bad), std::invalid_argument);
  bad = g;
  bad.facets = {2};
  EXPECT_THROW(ExpandGrid(bad), std::invalid_argument);
  bad = g;
  bad.points = {3, 3};
  EXPECT_THROW(ExpandGrid(bad), std::invalid_argument);
  bad = g;
  bad.dt = {-1};
  EXPECT_THROW(ExpandGrid(bad), std::invalid_argument);
}

// The model's opt-in choices are grid axes too (innermost), so an evaluation
// weighs the aligned cone or quasi-static steps against their cost; left
// alone they are the model's defaults, and every setting has its own key.
TEST(EvaluationGrid, OptInChoicesAreAxesWithTheModelsDefaults) {
  FidelityGrid g;
  g.facets = {8};
  g.dt = {0.004};
  const auto defaults = ExpandGrid(g);
  ASSERT_EQ(defaults.size(), 1u);
  const mechanics::ModelOptions model;
  EXPECT_EQ(defaults[0].pads, model.pads);
  EXPECT_EQ(defaults[0].cone, model.cone);
  EXPECT_EQ(defaults[0].inertia, model.inertia);
  g.cone = {mechanics::ConeModel::kPolyhedral, mechanics::ConeModel::kAligned};
  g.inertia = {mechanics::InertiaModel::kCarried, mechanics::InertiaModel::kAuto};
  g.pads = {mechanics::PadModel::kRigid};
  const auto m = ExpandGrid(g);
  ASSERT_EQ(m.size(), 4u);
  EXPECT_EQ(ModelKey(m[0]), "g8_k3_dt0.004_auto_pads-rigid");
  EXPECT_EQ(ModelKey(m[1]), "g8_k3_dt0.004_auto_pads-rigid_inertia-auto");
  EXPECT_EQ(ModelKey(m[2]), "g8_k3_dt0.004_auto_pads-rigid_cone-aligned");
  EXPECT_EQ(ModelKey(m[3]), "g8_k3_dt0.004_auto_pads-rigid_cone-aligned_inertia-auto");
  auto bad = g;
  bad.cone = {};
  EXPECT_THROW(ExpandGrid(bad), std::invalid_argument);
  auto repeated = g;
  repeated.inertia = {mechanics::InertiaModel::kAuto, mechanics::InertiaModel::kAuto};
  EXPECT_THROW(ExpandGrid(repeated), std::invalid_argument);
  repeated = g;
  repeated.pads = {};
  EXPECT_THROW(ExpandGrid(repeated), std::invalid_argument);
}

TEST(EvaluationBudget, ParsesShorthandMetricsAndUnits) {
  auto b = ParseBudget("1mm");
  EXPECT_EQ(b.metric, ErrorMetric::kPositionP95);  // budgets are met on p95
  EXPECT_DOUBLE_EQ(b.limit, 1e-3);
  b = ParseBudget("position_p95=0.005");
  EXPECT_EQ(b.metric, ErrorMetric::kPositionP95);
  EXPECT_DOUBLE_EQ(b.limit, 0.005);
  b = ParseBudget("angle_median=1deg");
  EXPECT_NEAR(b.limit, M_PI / 180, 1e-15);
  b = ParseBudget("force_p95=20mN");
  EXPECT_DOUBLE_EQ(b.limit, 0.02);
  b = ParseBudget("mode_agreement_median=95%");
  EXPECT_DOUBLE_EQ(b.limit, 0.95);
  // Issue 26: one unit per quantity in human output (it was "<= 0.002 m"
  // beside a table in mm).
  EXPECT_EQ(FormatBudget(ParseBudget("2mm")), "position_p95 <= 2 mm");
  EXPECT_EQ(FormatBudget(ParseBudget("position_median=2mm")), "position_median <= 2 mm");
  b = ParseBudget("2ms");
  EXPECT_EQ(b.metric, ErrorMetric::kTimeP95);
  EXPECT_DOUBLE_EQ(b.limit, 2e-3);
  b = ParseBudget("1.5floor");
  EXPECT_EQ(b.metric, ErrorMetric::kPositionP95);
  EXPECT_DOUBLE_EQ(b.floor_multiple, 1.5);
  b = ParseBudget("angle_p95=2floor");
  EXPECT_EQ(b.metric, ErrorMetric::kAngleP95);
  EXPECT_DOUBLE_EQ(b.floor_multiple, 2);
  for (const char* bad :
       {"", "mm", "1 mm", "1kg", "angle_median=1mm", "speed=1", "-1mm", "mode_agreement_median=1.5",
        "nan", "position_median=inf", "force_p95=2floor", "0floor", "time_p95=1mm", "2 ms"}) {
    EXPECT_THROW(ParseBudget(bad), std::invalid_argument) << bad;
  }
}

mechanics::ModelOptions Model(int facets) {
  return mechanics::ModelOptions{facets, 3, 0.004, mechanics::Reduce::kAuto};
}

TrialEvaluation Result(std::int64_t trial, std::size_t setting, double position, double time,
                       const std::string& status = "ok") {
  TrialEvaluation r;
  r.trial_id = trial;
  r.attempt = 1;
  r.setting = setting;
  r.prediction.status = db::ParsePredictionStatus(status).value();
  r.prediction.wall_s = time;
  if (status == "ok") {
    r.prediction.final_position_error = position;
    r.prediction.final_angle_error = position * 10;
    r.prediction.force_error = position * 100;
    r.prediction.mode_agreement = 1 - position;
  }
  return r;
}

// Four settings over three trials (position error m, time s):
//   g4:  error 4 mm, 1 ms   (front: cheapest)
//   g8:  error 2 mm, 2 ms   (front)
//   g16: error 3 mm, 3 ms   (dominated by g8)
//   g32: error 0.5 mm, 8 ms but fails on one trial (not eligible)
//   g6:  error 1 mm, 4 ms   (front)
std::vector<TrialEvaluation> KnownResults() {
  std::vector<TrialEvaluation> r;
  for (int t = 1; t <= 3; ++t) {
    const double jitter = (t - 2) * 1e-4;  // medians are the t = 2 values
    r.push_back(Result(t, 0, 4e-3 + jitter, 1e-3 + jitter * 1e-2));
    r.push_back(Result(t, 1, 2e-3 + jitter, 2e-3));
    r.push_back(Result(t, 2, 3e-3 + jitter, 3e-3));
    r.push_back(Result(t, 3, 0.5e-3, 8e-3, t == 3 ? "solver_failure" : "ok"));
    r.push_back(Result(t, 4, 1e-3 + jitter, 4e-3));
  }
  return r;
}

const std::vector<SettingInfo> kModels =
    ArenaSettings({Model(4), Model(8), Model(16), Model(32), Model(6)});

TEST(EvaluationSummary, DistributionsParetoFrontAndFailures) {
  const auto report = Summarise(kModels, KnownResults(), {});
  EXPECT_EQ(report.trials, 3);
  ASSERT_EQ(report.settings.size(), 5u);
  const auto& g4 = report.settings[0];
  EXPECT_EQ(g4.trials, 3);
  EXPECT_EQ(g4.ok, 3);
  EXPECT_NEAR(g4.position->median, 4e-3, 1e-15);
  EXPECT_NEAR(g4.position->p95, 4e-3 + 0.9e-4, 1e-12);  // rank 1.9 of 3.9, 4.0, 4.1 mm
  EXPECT_NEAR(g4.angle->median, 4e-2, 1e-14);
  EXPECT_NEAR(g4.force->median, 0.4, 1e-12);
  EXPECT_NEAR(g4.time.median, 1e-3, 1e-15);
  const auto& g32 = report.settings[3];
  EXPECT_EQ(g32.ok, 2);
  EXPECT_EQ(g32.failures, 1);
  EXPECT_FALSE(g32.eligible());
  EXPECT_EQ(g32.failed_trials.size(), 1u);
  EXPECT_EQ(g32.failed_trials[0].trial_id, 3);
  std::vector<bool> front;
  for (const auto& s : report.settings) front.push_back(s.pareto);
  EXPECT_EQ(front, (std::vector<bool>{true, true, false, false, true}));
  // No budget: nothing picked; the front is described instead.
  EXPECT_FALSE(report.recommended);
  EXPECT_NE(report.front.find("3 setting(s) on the front"), std::string::npos) << report.front;
  EXPECT_NE(report.front.find("g4_k3_dt0.004_auto"), std::string::npos) << report.front;
  // Tails: max and the worst trials by id.
  EXPECT_NEAR(g4.position->max, 4.1e-3, 1e-15);
  ASSERT_EQ(g4.worst.size(), 3u);
  EXPECT_EQ(g4.worst[0].trial_id, 3);
  EXPECT_EQ(g4.worst[2].trial_id, 1);
}

// A prediction whose detail carries the steered-slip flag (issue 31) is
// counted for its setting, over the ok trials only; so is one that ended
// oscillating.
TEST(EvaluationSummary, CountsTheTrialsTheConeSteered) {
  auto results = KnownResults();
  const std::string steered = R"({"steered_slip":{"detected":true,"share":0.3}})";
  for (auto& r : results) {
    if (r.setting == 0 && r.trial_id != 2) r.prediction.detail_json = steered;
    if (r.setting == 3) r.prediction.detail_json = steered;  // one of them failed
    if (r.setting == 1) r.prediction.detail_json = R"({"oscillation":{"detected":true}})";
  }
  const auto report = Summarise(kModels, results, {});
  EXPECT_EQ(report.settings[0].steered, 2);
  EXPECT_EQ(report.settings[1].steered, 0);
  EXPECT_EQ(report.settings[2].steered, 0);
  EXPECT_EQ(report.settings[3].steered, 2);
  EXPECT_EQ(ToJson(report)["settings"][0]["steered_slip_trials"], 2);
  // The oscillation flag is counted the same way, on its own.
  EXPECT_EQ(report.settings[1].oscillating, 3);
  EXPECT_EQ(report.settings[0].oscillating, 0);
  EXPECT_EQ(ToJson(report)["settings"][1]["oscillating_trials"], 3);
}

// A campaign's `prediction` may choose issue 31's model options (pads, cone,
// inertia): they reach the live predictor's scene, its stored settings and
// its key; MuJoCo's own `cone` is not arena's; a bad value names its field.
TEST(PredictionSettings, TheModelsChoicesReachThePredictor) {
  const mechanics::Scene scene =
      mechanics::LoadSceneFile(std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json");
  const mechanics::Scene chosen = ApplyModelSettings(
      scene, nlohmann::json({{"cone", "aligned"}, {"pads", "rigid"}, {"inertia", "auto"}}));
  EXPECT_EQ(chosen.model.cone, mechanics::ConeModel::kAligned);
  EXPECT_EQ(chosen.model.pads, mechanics::PadModel::kRigid);
  EXPECT_EQ(chosen.model.inertia, mechanics::InertiaModel::kAuto);
  const mechanics::Scene mujoco =
      ApplyModelSettings(scene, nlohmann::json({{"predictor", "mujoco"}, {"cone", "elliptic"}}));
  EXPECT_EQ(mujoco.model.cone, scene.model.cone);
  for (const char* key : {"cone", "pads", "inertia"}) {
    try {
      ApplyModelSettings(scene, nlohmann::json({{key, "round"}}));
      ADD_FAILURE() << key << " \"round\" was accepted";
    } catch (const mechanics::SceneError& e) {
      EXPECT_EQ(e.field(), std::string("model.") + key);
    }
  }
  // The cone is written since the aligned one became the default (settings
  // stored before without it are the polyhedral cone's).
  EXPECT_EQ(nlohmann::json::parse(ModelSettingsJson(scene.model)).value("cone", ""),
            mechanics::ToString(scene.model.cone));
  const auto truth = mechanics::Simulate(scene).samples;
  const nlohmann::json aligned = {{"cone", "aligned"}};
  const db::Prediction p = PredictTrial(ApplyModelSettings(scene, aligned), truth, aligned);
  EXPECT_EQ(p.status, db::PredictionStatus::kOk);
  EXPECT_NE(p.model_key.find("_cone-aligned"), std::string::npos) << p.model_key;
  EXPECT_EQ(nlohmann::json::parse(p.model_json).value("cone", ""), "aligned");
}

TEST(EvaluationSummary, RecommendsCheapestWithinBudget) {
  auto report = Summarise(kModels, KnownResults(), {ParseBudget("position_median=2.5mm")});
  ASSERT_TRUE(report.recommended);
  EXPECT_EQ(report.settings[*report.recommended].model_key, ModelKey(Model(8)));
  EXPECT_NE(report.recommendation.find("within position_median <= 2.5 mm"), std::string::npos)
      << report.recommendation;
  // On p95: g8's p95 is 2.09 mm, so 2.05 mm rules it out and g6 (1.09 mm) is the cheapest.
  report = Summarise(kModels, KnownResults(), {ParseBudget("2.05mm")});
  ASSERT_TRUE(report.recommended);
  EXPECT_EQ(report.settings[*report.recommended].model_key, ModelKey(Model(6)));
  // g32 would meet 0.6 mm but failed on a trial: nothing is within budget.
  report = Summarise(kModels, KnownResults(), {ParseBudget("0.6mm")});
  EXPECT_FALSE(report.recommended);
  EXPECT_NE(report.recommendation.find("none"), std::string::npos);
  // Two budgets must both hold; the primary metric (Pareto) is the first one's.
  report =
      Summarise(kModels, KnownResults(), {ParseBudget("angle_p95=25mrad"), ParseBudget("5mm")});
  EXPECT_EQ(report.primary, ErrorMetric::kAngleP95);
  ASSERT_TRUE(report.recommended);
  EXPECT_EQ(report.settings[*report.recommended].model_key, ModelKey(Model(8)));
  // Mode agreement is a minimum: of the eligible ones only g6 (median 0.999) reaches 0.9985.
  report = Summarise(kModels, KnownResults(), {ParseBudget("mode_agreement_median=0.9985")});
  ASSERT_TRUE(report.recommended);
  EXPECT_EQ(report.settings[*report.recommended].model_key, ModelKey(Model(6)));
}

TEST(EvaluationSummary, EmptyCampaignAndJson) {
  const auto empty = Summarise(kModels, {}, {ParseBudget("position_median=1mm")});
  EXPECT_EQ(empty.trials, 0);
  EXPECT_FALSE(empty.recommended);
  EXPECT_FALSE(empty.settings[0].position);
  for (const auto& s : empty.settings) EXPECT_FALSE(s.pareto);
  const auto j = ToJson(empty);
  EXPECT_TRUE(j["settings"][0]["position_error_m"].is_null());
  EXPECT_TRUE(j["recommended"].is_null());

  const auto full =
      ToJson(Summarise(kModels, KnownResults(), {ParseBudget("position_median=2.5mm")}));
  EXPECT_EQ(full["recommended"], ModelKey(Model(8)));
  EXPECT_EQ(full["settings"].size(), 5u);
  EXPECT_EQ(full["settings"][1]["pareto"], true);
  EXPECT_EQ(full["settings"][1]["within_budget"], true);
  EXPECT_NEAR(full["settings"][1]["position_error_m"]["median"].get<double>(), 2e-3, 1e-15);
  EXPECT_EQ(full["primary_metric"], "position_median");
  EXPECT_EQ(full["settings"][1]["predictor"], "arena");
  EXPECT_NEAR(full["settings"][1]["position_error_m"]["max"].get<double>(), 2.1e-3, 1e-15);
  EXPECT_EQ(full["settings"][3]["failed_trials"][0]["trial_id"], 3);
  // Parses back (no NaN written).
  EXPECT_EQ(nlohmann::json::parse(full.dump()), full);
}

// Pins issue 26: `evaluate --json` gave the front only as prose in mm
// ("3 setting(s) on the front ...: arena g4_... 1 ms -> 4 mm; ..."), which a
// script cannot read. `front_points` gives the same points, cheapest first,
// with named SI fields; `front` keeps the prose (scripts may read it).
TEST(EvaluationSummary, JsonFrontIsStructuredSi) {
  const auto report = Summarise(kModels, KnownResults(), {ParseBudget("position_median=2.5mm")});
  const auto j = ToJson(report);
  EXPECT_TRUE(j["front"].is_string());
  const auto& points = j["front_points"];
  ASSERT_EQ(points.size(), 3u) << points.dump();  // g4, g8, g6 (g16 dominated, g32 failed)
  const std::vector<std::string> keys = {ModelKey(Model(4)), ModelKey(Model(8)),
                                         ModelKey(Model(6))};
  const std::vector<double> errors = {4e-3, 2e-3, 1e-3}, times = {1e-3, 2e-3, 4e-3};
  for (std::size_t k = 0; k < 3; ++k) {
    SCOPED_TRACE(points[k].dump());
    EXPECT_EQ(points[k]["model_key"], keys[k]);
    EXPECT_EQ(points[k]["predictor"], "arena");
    EXPECT_EQ(points[k]["metric"], "position_median");
    EXPECT_EQ(points[k]["error_unit"], "m");
    EXPECT_NEAR(points[k]["error"].get<double>(), errors[k], 1e-12);         // metres, not mm
    EXPECT_NEAR(points[k]["time_median_s"].get<double>(), times[k], 1e-12);  // seconds, not ms
    const auto setting = points[k]["setting"].get<std::size_t>();
    EXPECT_EQ(j["settings"][setting]["model_key"], keys[k]);
    EXPECT_EQ(points[k]["recommended"], k == 1);         // g8: the cheapest within 2.5 mm
    EXPECT_TRUE(points[k]["floor_multiple"].is_null());  // no noise floor here
  }
  // An angle metric's front is in radians.
  const auto angle = ToJson(Summarise(kModels, KnownResults(), {ParseBudget("angle_p95=25mrad")}));
  ASSERT_FALSE(angle["front_points"].empty());
  EXPECT_EQ(angle["front_points"][0]["error_unit"], "rad");
  EXPECT_LT(angle["front_points"][0]["error"].get<double>(), 0.1);
}

}  // namespace
}  // namespace arena::assessment
