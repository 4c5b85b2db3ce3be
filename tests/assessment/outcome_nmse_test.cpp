// Scoring against real pushes (issue 30): the outcome in the object's
// initial frame, its NMSE over a set of trials, per group in a summary, and
// calibration of the support (mu_support, pressure_rim) with a split by a
// trial parameter, on known inputs.
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "arena/assessment/evaluation.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/assessment/scoring.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/support.hpp"

namespace arena::assessment {
namespace {

Eigen::Quaterniond Yaw(double a) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()));
}

TEST(PlanarOutcome, IsTheFinalPoseInTheInitialFrame) {
  // Start turned 90 deg: a move along the table's +y is the object's +x.
  const auto o = PlanarOutcomeOf({1, 2, 0}, Yaw(std::numbers::pi / 2), {1, 2.03, 0},
                                 Yaw(std::numbers::pi / 2 + 0.2));
  EXPECT_NEAR(o.dx, 0.03, 1e-12);
  EXPECT_NEAR(o.dy, 0, 1e-12);
  EXPECT_NEAR(o.dtheta, 0.2, 1e-12);
  // Across the +-pi seam the turn stays small and signed.
  const auto w = PlanarOutcomeOf({0, 0, 0}, Yaw(3.1), {0, 0, 0}, Yaw(-3.1));
  EXPECT_NEAR(w.dtheta, 2 * std::numbers::pi - 6.2, 1e-9);
}

TEST(OutcomeNmse, KnownValuesAndRefusals) {
  const std::vector<PlanarOutcome> truth = {{0, 0, 0}, {2, 4, 0.2}};  // var 1, 4, 0.01
  // Predicting the mean outcome scores 1 on every output.
  const std::vector<PlanarOutcome> mean = {{1, 2, 0.1}, {1, 2, 0.1}};
  auto n = ComputeNmse(mean, truth);
  ASSERT_TRUE(n);
  EXPECT_NEAR(n->dx, 1, 1e-12);
  EXPECT_NEAR(n->dy, 1, 1e-12);
  EXPECT_NEAR(n->dtheta, 1, 1e-9);
  EXPECT_NEAR(n->mean, 1, 1e-9);
  EXPECT_EQ(n->trials, 2);
  n = ComputeNmse(truth, truth);
  ASSERT_TRUE(n);
  EXPECT_EQ(n->mean, 0);
  // Off by 0.5 in dx only: mse 0.25 over var 1, averaged over three outputs.
  const std::vector<PlanarOutcome> off = {{0.5, 0, 0}, {2.5, 4, 0.2}};
  n = ComputeNmse(off, truth);
  ASSERT_TRUE(n);
  EXPECT_NEAR(n->dx, 0.25, 1e-12);
  EXPECT_NEAR(n->mean, 0.25 / 3, 1e-12);
  std::string why;
  EXPECT_FALSE(ComputeNmse({truth[0]}, {truth[0]}, &why));
  EXPECT_NE(why.find("at least 2"), std::string::npos) << why;
  EXPECT_FALSE(ComputeNmse(mean, {{1, 0, 0}, {3, 0, 0.1}}, &why));
  EXPECT_NE(why.find("dy does not vary"), std::string::npos) << why;
  EXPECT_THROW(ComputeNmse(mean, {truth[0]}), std::invalid_argument);
}

// A scored prediction as ScoreSimulation stores it.
TrialEvaluation Scored(std::int64_t id, PlanarOutcome predicted, PlanarOutcome truth, bool force) {
  TrialEvaluation r;
  r.trial_id = id;
  r.truth_duration_s = 1;
  r.prediction.model_key = "g8_k3_dt0.004_auto";
  r.prediction.final_position_error = std::hypot(predicted.dx - truth.dx, predicted.dy - truth.dy);
  r.prediction.final_angle_error = std::abs(predicted.dtheta - truth.dtheta);
  if (force) r.prediction.force_error = 0.5;
  r.prediction.wall_s = 0.01;
  r.prediction.detail_json =
      nlohmann::json{{"outcome",
                      {{"true", {truth.dx, truth.dy, truth.dtheta}},
                       {"predicted", {predicted.dx, predicted.dy, predicted.dtheta}}}}}
          .dump();
  return r;
}

TEST(OutcomeNmse, SummarisedOverallAndPerGroupWithEachGroupsOwnVariance) {
  mechanics::ModelOptions m;
  const auto settings = ArenaSettings({m});
  // Group a: outcomes 0 and 2 (var 1 per output), predicted off by 0.5 in dx.
  // Group b: outcomes 10 and 14 (var 4), predicted exactly; no force measured.
  std::vector<TrialEvaluation> results = {
      Scored(1, {0.5, 0, 0}, {0, 0, 0}, true), Scored(2, {2.5, 2, 0.2}, {2, 2, 0.2}, true),
      Scored(3, {10, 10, 1}, {10, 10, 1}, false), Scored(4, {14, 14, 1.4}, {14, 14, 1.4}, false)};
  results[1].prediction.detail_json =
      nlohmann::json{{"outcome", {{"true", {2, 2, 0.2}}, {"predicted", {2.5, 2, 0.2}}}}}.dump();
  results[0].prediction.detail_json =
      nlohmann::json{{"outcome", {{"true", {0, 0, 0}}, {"predicted", {0.5, 0, 0}}}}}.dump();
  const auto all = Summarise(settings, results, {});
  ASSERT_TRUE(all.settings[0].nmse);
  // Overall: dx errors 0.5, 0.5, 0, 0 -> mse 0.125 over var of {0, 2, 10, 14} = 32.75.
  EXPECT_NEAR(all.settings[0].nmse->dx, 0.125 / 32.75, 1e-12);
  EXPECT_EQ(all.settings[0].force_trials, 2);
  const auto groups = SummariseGroups(settings, results, {{1, "a"}, {2, "a"}, {3, "b"}, {4, "b"}});
  ASSERT_EQ(groups.size(), 2u);
  EXPECT_EQ(groups[0].value, "a");
  EXPECT_EQ(groups[0].trials, 2);
  ASSERT_TRUE(groups[0].settings[0].nmse);
  EXPECT_NEAR(groups[0].settings[0].nmse->dx, 0.25, 1e-12);  // 0.25 over the group's var 1
  ASSERT_TRUE(groups[1].settings[0].nmse);
  EXPECT_EQ(groups[1].settings[0].nmse->mean, 0);
  EXPECT_FALSE(groups[1].settings[0].force);  // no trial of b had its force scored
  EXPECT_EQ(groups[1].settings[0].force_trials, 0);
  EXPECT_THROW(SummariseGroups(settings, results, {{1, "a"}}), std::invalid_argument);
  // The JSON carries both.
  EvaluationReport r = all;
  r.group_by = "shape";
  r.groups = groups;
  const auto j = ToJson(r);
  EXPECT_NEAR(j["settings"][0]["outcome_nmse"]["dx"].get<double>(), 0.125 / 32.75, 1e-12);
  EXPECT_EQ(j["group_by"], "shape");
  EXPECT_EQ(j["groups"][1]["value"], "b");
  EXPECT_EQ(j["groups"][1]["settings"][0]["outcome_nmse"]["value"].get<double>(), 0);
  // A prediction stored without its outcome: no NMSE, and why.
  results[3].prediction.detail_json = "{}";
  const auto missing = Summarise(settings, results, {});
  EXPECT_FALSE(missing.settings[0].nmse);
  EXPECT_NE(missing.settings[0].nmse_note.find("without their outcome"), std::string::npos);
}

TEST(OutcomeNmse, ScoreSimulationStoresBothOutcomes) {
  std::vector<mechanics::TrajectorySample> truth(3), predicted(3);
  for (int i = 0; i < 3; ++i) {
    truth[i].t = predicted[i].t = i / 250.0;
    truth[i].orientation = Yaw(0.01 * i);
    predicted[i].orientation = Yaw(0.02 * i);
    truth[i].position = {0.001 * i, 0, 0};
    predicted[i].position = {0.002 * i, 0, 0};
  }
  const auto e = ScorePrediction(predicted, truth);
  EXPECT_NEAR(e.true_outcome.dx, 0.002, 1e-12);
  EXPECT_NEAR(e.predicted_outcome.dx, 0.004, 1e-12);
  EXPECT_NEAR(e.predicted_outcome.dtheta, 0.04, 1e-12);
}

// A box resting on a support, pushed by a point pusher (free pushing).
mechanics::Scene SupportScene(const std::string& object) {
  return mechanics::ParseScene(R"({"object": )" + object + R"(,
    "gravity": [0, 0, -9.81], "duration": 0.1, "grip_force": 0, "fingers": [],
    "support": {"mu": 0.3, "pressure": "uniform"},
    "pusher": {"type": "point", "radius": 0.005, "position": [-0.06, 0, 0], "normal": [1, 0, 0],
               "mu": 0.2, "motion": {"velocity": [0.05, 0, 0]}}})");
}

TEST(CalibrateSupport, MuSupportAndThePressureFamily) {
  const auto box = SupportScene(
      R"({"shape": "box", "size": [0.1, 0.06, 0.02], "mass": 0.5, "pose": {"position": [0, 0, 0.01]}})");
  EXPECT_NEAR(ApplyScales(box, {{"mu_support", 2}}).support->mu, 0.6, 1e-12);
  // k = 1 is the scene's own (uniform) pressure: unchanged.
  EXPECT_TRUE(ApplyScales(box, {{"pressure_rim", 1}}).support->pressure_points.empty());
  // k = 3: the farthest point weighs 3x the centre's share (per area), and
  // the centre of pressure stays under the centre of mass (the scene is valid).
  const auto rim = ApplyScales(box, {{"pressure_rim", 3}});
  const auto base = mechanics::SupportPressureOf(box);
  ASSERT_EQ(rim.support->pressure_points.size(), base.points_O.size());
  double near_w = 0, far_w = 0, near_r = 1, far_r = 0;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double total = 0;
  for (std::size_t i = 0; i < base.points_O.size(); ++i) {
    const auto& p = rim.support->pressure_points[i];
    const double w = p.z() / base.weights[i], r = p.head<2>().norm();
    if (r < near_r) near_r = r, near_w = w;
    if (r > far_r) far_r = r, far_w = w;
    centre += p.z() * p.head<2>();
    total += p.z();
  }
  EXPECT_NEAR(far_w / near_w, std::pow(3.0, 1 - near_r / far_r), 1e-6);
  EXPECT_LT((centre / total).norm(), 1e-9);
  EXPECT_NO_THROW(mechanics::ValidateScene(rim));
  // The centre-loaded side, on a face not symmetric about its centroid (a
  // triangle): tilted back under the centre of mass, still valid.
  const auto tri = SupportScene(
      R"({"shape": "prism", "polygon": [[-0.03, -0.02], [0.05, -0.02], [-0.03, 0.04]], "height": 0.02,
          "mass": 0.5, "pose": {"position": [0, 0, 0.01]}})");
  EXPECT_NO_THROW(mechanics::ValidateScene(ApplyScales(tri, {{"pressure_rim", 0.3}})));
  EXPECT_NO_THROW(mechanics::ValidateScene(ApplyScales(tri, {{"pressure_rim", 3}})));
  EXPECT_EQ(ParseCalibrationParam("mu_support"), CalibrationParam::kMuSupport);
  EXPECT_STREQ(ToString(CalibrationParam::kPressureRim), "pressure_rim");
}

// A stand-in for free pushing: the object slides dx = 0.1 mu_pusher and
// dy = 0.002 mu_support and turns 0.05 mu_support, each per unit of the
// scene's grip force (a trial's own scale), in 10 samples.
mechanics::SimulationResult FakePush(const mechanics::Scene& s) {
  mechanics::SimulationResult r;
  for (int i = 0; i < 10; ++i) {
    mechanics::TrajectorySample t;
    t.t = i / 250.0;
    const double f = i / 9.0;
    t.position = {0.1 * s.pusher->mu * f * s.grip_force, 0.002 * s.support->mu * f * s.grip_force,
                  0};
    t.orientation = Yaw(0.05 * s.support->mu * f * s.grip_force);
    r.samples.push_back(t);
  }
  return r;
}

TEST(CalibrateSupport, SplitsByAGroupShareTheirSimulations) {
  const auto base = SupportScene(
      R"({"shape": "box", "size": [0.1, 0.06, 0.02], "mass": 0.5, "pose": {"position": [0, 0, 0.01]}})");
  std::vector<CalibrationTrial> trials;
  std::vector<std::vector<std::int64_t>> groups(3);
  for (int i = 0; i < 12; ++i) {
    CalibrationTrial t;
    t.trial_id = 10 + i;
    t.scene = base;
    t.scene.grip_force = 1 + i;  // the stand-in's per-trial scale
    t.truth = FakePush(ApplyScales(t.scene, {{"mu_pusher", 1.5}, {"mu_support", 0.7}})).samples;
    groups[static_cast<std::size_t>(i % 3)].push_back(t.trial_id);
    trials.push_back(t);
  }
  CalibrationOptions o;
  o.params = {CalibrationParam::kMuPusher, CalibrationParam::kMuSupport};
  o.bootstrap = 0;
  o.profile_points = 0;
  const auto rs = CalibrateSplits(trials, FakePush, o, groups);
  ASSERT_EQ(rs.size(), 3u);
  long simulations = 0;
  for (std::size_t k = 0; k < rs.size(); ++k) {
    EXPECT_EQ(rs[k].heldout_ids, groups[k]);
    EXPECT_EQ(rs[k].train_ids.size(), 8u);
    EXPECT_NEAR(rs[k].fitted[0].scale, 1.5, 0.01);
    EXPECT_NEAR(rs[k].fitted[1].scale, 0.7, 0.01);
    EXPECT_TRUE(rs[k].improved);
    ASSERT_TRUE(rs[k].heldout_figures_before.nmse);
    ASSERT_TRUE(rs[k].heldout_figures_after.nmse);
    EXPECT_LT(rs[k].heldout_figures_after.nmse->mean, 1e-3);
    EXPECT_GT(rs[k].heldout_figures_before.nmse->mean, 0.01);
    EXPECT_EQ(rs[k].heldout_errors_after.size(), 4u);
    simulations += rs[k].simulations;
  }
  // The splits' first steps (start, initial steps) were simulated once.
  EXPECT_LT(simulations, rs[0].simulations * 3);
  // Nothing held out: the fit is judged on the trials it fitted.
  o.holdout = 0;
  const auto all = Calibrate(trials, FakePush, o);
  EXPECT_TRUE(all.heldout_ids.empty());
  EXPECT_EQ(all.train_ids.size(), 12u);
  EXPECT_TRUE(all.improved);
  ASSERT_TRUE(all.train_figures_after.nmse);
  EXPECT_LT(all.train_figures_after.nmse->mean, 1e-3);
  // The outcome loss: the mean training loss is the training trials' NMSE.
  o.outcome_loss = true;
  const auto by_nmse = Calibrate(trials, FakePush, o);
  EXPECT_NEAR(by_nmse.fitted[0].scale, 1.5, 0.01);
  EXPECT_NEAR(by_nmse.fitted[1].scale, 0.7, 0.01);
  ASSERT_TRUE(by_nmse.train_figures_before.nmse);
  EXPECT_NEAR(by_nmse.train_before, by_nmse.train_figures_before.nmse->mean, 1e-9);
  o.outcome_loss = false;
  // A split naming a trial the campaign lacks, or leaving < 2 to fit.
  EXPECT_THROW(CalibrateSplits(trials, FakePush, o, {{999}}), CalibrationError);
  std::vector<std::int64_t> almost_all;
  for (const auto& t : trials)
    if (t.trial_id != 10) almost_all.push_back(t.trial_id);
  EXPECT_THROW(CalibrateSplits(trials, FakePush, o, {almost_all}), CalibrationError);
  EXPECT_THROW(CalibrateSplits(trials, FakePush, o, {}), CalibrationError);
}

}  // namespace
}  // namespace arena::assessment
