// EvaluateCampaign on a real store: replicates of one condition share a
// scene, so each setting's prediction is made once for them and scored
// against each replicate's own truth (assessment/src/evaluation.cpp).
#include <fstream>
#include <map>
#include <sstream>

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include "arena/assessment/evaluation.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/assessment/truth.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "db/db_test_util.hpp"

namespace arena::assessment {
namespace {

// The canonical example scene, 0.1 s long, at a grip force.
std::string Scene(double grip) {
  std::ifstream f(std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json");
  std::stringstream text;
  text << f.rdbuf();
  nlohmann::json j = nlohmann::json::parse(text.str());
  j["duration"] = 0.1;
  j["grip_force"] = grip;
  return j.dump();
}

TEST(EvaluationStore, ReplicatesShareThePredictionAndKeepTheirOwnTruth) {
  db::testing::TempDir dir;
  const std::string path = dir.File("e.db");
  {
    auto store = db::Store::Open(path);
    // Three conditions, two replicates each (replicates have the same scene).
    std::vector<db::PlannedTrial> trials;
    for (int i = 0; i < 6; ++i) {
      db::PlannedTrial t;
      t.condition = i / 2;
      t.replicate = i % 2;
      t.seed = 100u + static_cast<unsigned>(i);
      t.scene_json = Scene(6.0 + 2 * (i / 2));
      t.params_json = "{}";
      trials.push_back(t);
    }
    store->CreateCampaign(db::testing::MakeCampaign(), trials);
    store->UpsertCell("cell", {"point", "line"});
    // Replicates differ in their truth: the second one's object ends 2 mm
    // further along x.
    for (int i = 0; i < 6; ++i) {
      const auto t = store->ClaimNextTrial("cell");
      ASSERT_TRUE(t.has_value());
      auto ingest = store->BeginIngest(t->trial_id, t->attempt);
      for (int k = 0; k < 30; ++k) {
        db::Sample sample = db::testing::MakeSample(k);
        sample.object_pose[0] += (i % 2) * 0.002;
        ingest->Add(sample);
      }
      ingest->Finish();
      store->BeginReset(t->trial_id, t->attempt);
      db::ResetReport r;
      r.ok = true;
      store->CompleteReset(t->trial_id, t->attempt, r);
      db::Prediction p;
      p.model_key = "g8_k3";
      store->RecordPrediction(t->trial_id, t->attempt, p);
      store->FinishTrial(t->trial_id, t->attempt);
    }
  }
  auto store = db::Store::Open(path);
  EvaluationOptions o;
  o.threads = 2;
  o.convergence_trials = 0;
  FidelityGrid g;
  g.facets = {4, 8};
  g.points = {3};
  g.dt = {0.008};
  o.predictors = {PredictorRequest{}};
  o.predictors[0].arena_grid = g;
  const EvaluationRun run = EvaluateCampaign(*store, 1, o);
  ASSERT_EQ(run.report.trials, 6);
  const auto rows = store->ListEvaluationResults(run.evaluation_id);
  ASSERT_EQ(rows.size(), 12u);

  std::map<std::pair<std::int64_t, std::string>, db::Prediction> by;
  for (const auto& r : rows) by[{r.trial_id, r.prediction.model_key}] = r.prediction;
  for (const auto& t : store->ListTrials(1)) {
    const mechanics::Scene scene = mechanics::ParseScene(t.scene_json);
    const auto truth = ReadTruth(*store, t.id, scene);
    for (int facets : {4, 8}) {
      mechanics::Scene s = scene;
      s.model.facets = facets;
      s.model.points = 3;
      s.model.dt = 0.008;
      const std::string key = "g" + std::to_string(facets) + "_k3_dt0.008_auto";
      SCOPED_TRACE("trial " + std::to_string(t.id) + " " + key);
      ASSERT_EQ(by.count({t.id, key}), 1u);
      const db::Prediction& got = by.at({t.id, key});
      // The same numbers as this trial's own prediction scored on its own truth.
      const db::Prediction want = ScoreSimulation(s, mechanics::Simulate(s), truth);
      EXPECT_EQ(got.status, want.status);
      EXPECT_EQ(got.final_position_error, want.final_position_error);
      EXPECT_EQ(got.final_angle_error, want.final_angle_error);
      EXPECT_EQ(got.force_error, want.force_error);
      EXPECT_EQ(got.mode_agreement, want.mode_agreement);
    }
  }
  // Replicates: one prediction (the same measured run time), two truths.
  const auto list = store->ListTrials(1);
  for (std::size_t i = 0; i + 1 < list.size(); i += 2) {
    const auto& a = by.at({list[i].id, "g8_k3_dt0.008_auto"});
    const auto& b = by.at({list[i + 1].id, "g8_k3_dt0.008_auto"});
    EXPECT_EQ(a.wall_s, b.wall_s);
    EXPECT_NE(a.final_position_error, b.final_position_error);
  }
}

}  // namespace
}  // namespace arena::assessment
