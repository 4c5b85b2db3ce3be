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
#include "arena/orchestrator/scene_facts.hpp"
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
      t.facts = orchestrator::SceneFactsOfJson(t.scene_json);
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
      auto ingest = store->BeginIngest(
          t->trial_id, t->attempt,
          orchestrator::SceneFactsOfJson(store->GetTrial(t->trial_id).scene_json).contacts);
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
  // This test pins the sharing of one scene's prediction, which holds for
  // the planned start (a measured start is each replicate's own: below).
  o.start_from = StartFrom::kPlanned;
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
      const std::string key =
          "g" + std::to_string(facets) + "_k3_dt0.008_auto_cone-aligned_inertia-auto";
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
    const auto& a = by.at({list[i].id, "g8_k3_dt0.008_auto_cone-aligned_inertia-auto"});
    const auto& b = by.at({list[i + 1].id, "g8_k3_dt0.008_auto_cone-aligned_inertia-auto"});
    EXPECT_EQ(a.wall_s, b.wall_s);
    EXPECT_NE(a.final_position_error, b.final_position_error);
  }
}

// The model's own trajectory as the store keeps a stream (true = observed).
std::vector<db::Sample> AsStream(const mechanics::Scene& scene,
                                 const mechanics::SimulationResult& run) {
  const auto normals = ContactNormals(scene);
  std::vector<db::Sample> out;
  for (const auto& t : run.samples) {
    db::Sample s;
    s.t = t.t;
    s.object_pose = {t.position.x(),    t.position.y(),    t.position.z(),   t.orientation.w(),
                     t.orientation.x(), t.orientation.y(), t.orientation.z()};
    s.pusher_pose = {
        t.pusher_position.x(), t.pusher_position.y(), t.pusher_position.z(), 1, 0, 0, 0};
    for (std::size_t c = 0; c < t.contacts.size(); ++c) {
      const Eigen::Vector3d f =
          t.contacts[c].normal_force * normals[c] + t.contacts[c].tangential_force;
      db::ContactWrench w;
      w.force = {f.x(), f.y(), f.z()};
      w.torque = {t.contacts[c].torque.x(), t.contacts[c].torque.y(), t.contacts[c].torque.z()};
      w.mode = static_cast<db::ContactMode>(static_cast<int>(t.contacts[c].mode));
      s.contacts.push_back(w);
    }
    s.observed_object_pose = s.object_pose;
    out.push_back(s);
  }
  return out;
}

// Pins issue 26 item 4: predictions started from the planned pose, so every
// error included the reset's placement error. Each trial here ran arena's
// model from a start the reset left 1..4 mm off the planned pose (along y:
// the push lands off-centre and turns the object); from the start the cell
// measured (the stream's first sample) the same model predicts it exactly,
// from the planned pose it does not, and the report says by how much.
TEST(EvaluationStore, PredictsFromTheMeasuredStartAndSaysTheStartsShare) {
  db::testing::TempDir dir;
  const std::string path = dir.File("s.db");
  const std::string scene_json = Scene(10.0);
  const mechanics::Scene planned = mechanics::ParseScene(scene_json);
  {
    auto store = db::Store::Open(path);
    std::vector<db::PlannedTrial> trials;
    for (int i = 0; i < 4; ++i) {
      db::PlannedTrial t;
      t.condition = 0;
      t.replicate = i;
      t.seed = 7u + static_cast<unsigned>(i);
      t.scene_json = scene_json;
      t.facts = orchestrator::SceneFactsOfJson(t.scene_json);
      t.params_json = "{}";
      trials.push_back(t);
    }
    store->CreateCampaign(db::testing::MakeCampaign(), trials);
    store->UpsertCell("cell", {"point", "line"});
    for (int i = 0; i < 4; ++i) {
      const auto t = store->ClaimNextTrial("cell");
      ASSERT_TRUE(t.has_value());
      PredictionStart start = StartOf(planned, nullptr, StartFrom::kPlanned);
      start.from = StartFrom::kMeasured;
      start.position.y() += 0.001 * (i + 1);
      start.offset_m = 0.001 * (i + 1);
      const mechanics::Scene placed = StartedAt(planned, start);
      const auto run = mechanics::Simulate(placed);
      ASSERT_EQ(run.status, mechanics::SimulationStatus::kOk) << run.error;
      auto ingest = store->BeginIngest(
          t->trial_id, t->attempt,
          orchestrator::SceneFactsOfJson(store->GetTrial(t->trial_id).scene_json).contacts);
      for (const auto& sample : AsStream(placed, run)) ingest->Add(sample);
      ingest->Finish(db::TrialEnd::kOk);
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
  o.threads = 1;
  o.convergence_trials = 0;
  FidelityGrid g;
  g.facets = {8};
  g.points = {3};
  g.dt = {0.004};  // the setting the truth ran at: from its true start, no error
  o.predictors = {PredictorRequest{}};
  o.predictors[0].arena_grid = g;
  const EvaluationRun run = EvaluateCampaign(*store, 1, o);
  const auto rows = store->ListEvaluationResults(run.evaluation_id);
  ASSERT_EQ(rows.size(), 4u);
  for (const auto& r : rows) {
    SCOPED_TRACE("trial " + std::to_string(r.trial_id));
    ASSERT_EQ(r.prediction.status, db::PredictionStatus::kOk) << r.prediction.detail_json;
    EXPECT_LT(*r.prediction.final_position_error, 1e-9);
    EXPECT_LT(*r.prediction.final_angle_error, 1e-9);
    // Every stored prediction says which start it used.
    const auto start = nlohmann::json::parse(r.prediction.detail_json)["start"];
    EXPECT_EQ(start["from"], "measured");
    EXPECT_EQ(start["source"], "observed");
    EXPECT_GT(start["offset_m"].get<double>(), 0.0009);
  }
  ASSERT_EQ(run.start.settings.size(), 1u);
  const StartShare& share = run.start.settings[0];
  EXPECT_EQ(share.trials, 4);
  EXPECT_LT(share.position_measured, 1e-9);
  // From the planned pose the same model misses by about the start's offset.
  EXPECT_GT(share.position_planned, 0.0015);
  EXPECT_EQ(run.start.measured_trials, 4);
  EXPECT_NEAR(run.start.offset_position->max, 0.004, 1e-9);
  const auto j = ToJson(run.start);
  EXPECT_EQ(j["from"], "measured");
  EXPECT_NEAR(j["explained"][0]["position_median_m"]["explained"].get<double>(),
              share.position_planned - share.position_measured, 1e-15);

  // --from planned: the old behaviour, kept to measure the reset's share.
  o.start_from = StartFrom::kPlanned;
  const EvaluationRun from_planned = EvaluateCampaign(*store, 1, o);
  for (const auto& r : store->ListEvaluationResults(from_planned.evaluation_id)) {
    EXPECT_GT(*r.prediction.final_position_error, 0.0005);
    EXPECT_EQ(nlohmann::json::parse(r.prediction.detail_json)["start"]["from"], "planned");
  }
  EXPECT_TRUE(from_planned.start.settings.empty());
}

TEST(PredictionStart, MeasuredFromTheFirstSampleAndPlannedKeptApart) {
  const mechanics::Scene planned = mechanics::ParseScene(Scene(10.0));
  db::Sample first;
  first.object_pose = {0.0, 0.002, 0.0, 1, 0, 0, 0};
  first.observed_object_pose = {0.0, 0.0025, 0.0, 1, 0, 0, 0};
  const PredictionStart seen = StartOf(planned, &first, StartFrom::kMeasured);
  EXPECT_EQ(seen.source, "observed");  // what the cell's sensors saw
  EXPECT_NEAR(seen.offset_m, 0.0025, 1e-12);
  first.observed_valid = false;  // dropped: the sample's own pose
  EXPECT_EQ(StartOf(planned, &first, StartFrom::kMeasured).source, "first_sample");
  EXPECT_NEAR(StartOf(planned, &first, StartFrom::kMeasured).offset_m, 0.002, 1e-12);
  const PredictionStart plan = StartOf(planned, &first, StartFrom::kPlanned);
  EXPECT_EQ(plan.source, "planned");
  EXPECT_EQ(plan.offset_m, 0);
  EXPECT_EQ(StartedAt(planned, plan).object.pose.position, planned.object.pose.position);
  const mechanics::Scene moved = StartedAt(planned, seen);
  EXPECT_NEAR(moved.object.pose.position.y(), 0.0025, 1e-12);
  // A start the fingers cannot close on is an invalid scene, named.
  PredictionStart far = seen;
  far.position.y() = 0.5;  // beside the fingers' closing line: they close on nothing
  far.offset_m = 0.5;
  try {
    (void)StartedAt(planned, far);
    FAIL() << "a start out of the grasp was accepted";
  } catch (const mechanics::SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("start"), std::string::npos) << e.what();
  }
  EXPECT_EQ(StartFromOf(nlohmann::json()), StartFrom::kMeasured);
  EXPECT_EQ(StartFromOf(nlohmann::json{{"start", "planned"}}), StartFrom::kPlanned);
  EXPECT_THROW(StartFromOf(nlohmann::json{{"start", "reset"}}), mechanics::SceneError);
}

}  // namespace
}  // namespace arena::assessment
