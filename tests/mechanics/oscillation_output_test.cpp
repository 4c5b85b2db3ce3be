// The oscillation flag where it is read: `arena simulate`'s JSON carries it
// as an added field (present, detected or not), and a scored prediction's
// stored detail mentions it when the run ends oscillating. The scenes: the
// issue 31 pivot past its stall with its momentum carried (ends rocking
// about 0.026 rad at about 80 Hz: quasi_static_test.cpp) and the canonical
// scene (ends on its path). The quasi-static statistics (the repeated
// solves, the steps that fell back to the carried one) and the oscillation's
// periods reach a stored prediction in a real SQLite file.
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "db/db_test_util.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
const fs::path kSourceDir = ARENA_SOURCE_DIR;

constexpr const char* kCarriedPivot =
    R"({"object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{"position":[0,0,0],)"
    R"("rpy":[0,0,0]}},"gravity":[0,0,0],"duration":0.6,"grip_force":1000.0,"fingers":[)"
    R"({"name":"left","type":"point","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5},)"
    R"({"name":"right","type":"point","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5}],)"
    R"("model":{"facets":8,"points":3,"dt":0.001,"reduce":"auto","inertia":"carried"},)"
    R"("pusher":{"type":"point",)"
    R"("position":[0,0.01,-0.05],"normal":[0,0,1],"mu":0.0,"motion":{"velocity":[0,0,0.01],)"
    R"("angular_velocity":[0,0,0]}}})";

// A grasp too weak for the weight (2 μ N = 1 N < m g = 1.96 N), quasi-static:
// no step can balance, so every one of its 25 steps (dt 4 ms, 0.1 s) is
// the carried one.
constexpr const char* kWeakGraspQuasiStatic =
    R"({"object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2},"gravity":[0,0,-9.81],)"
    R"("duration":0.1,"grip_force":1.0,"fingers":[)"
    R"({"name":"left","type":"point","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5},)"
    R"({"name":"right","type":"point","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5}],)"
    R"("model":{"inertia":"quasi_static"}})";

json SimulateCli(const fs::path& file) {
  const std::string command =
      std::string("'") + ARENA_BINARY + "' simulate '" + file.string() + "' 2>/dev/null";
  std::string out;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return json();
  std::array<char, 4096> buf{};
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) out.append(buf.data(), n);
  const int status = ::pclose(pipe);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;
  return json::parse(out, nullptr, false);
}

TEST(OscillationOutput, SimulateJsonCarriesTheFlag) {
  const fs::path dir = fs::temp_directory_path() / ("arena_osc_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path pivot = dir / "pivot.json";
  std::ofstream(pivot) << kCarriedPivot;
  const json rocking = SimulateCli(pivot);
  ASSERT_TRUE(rocking.is_object());
  ASSERT_TRUE(rocking.contains("oscillation")) << rocking.dump();
  EXPECT_EQ(rocking["oscillation"]["detected"], true);
  EXPECT_GT(rocking["oscillation"]["amplitude_rad"].get<double>(), 0.01);
  EXPECT_GT(rocking["oscillation"]["frequency_hz"].get<double>(), 50);
  const json canonical = SimulateCli(kSourceDir / "examples/scenes/canonical.json");
  ASSERT_TRUE(canonical.contains("oscillation")) << canonical.dump();
  EXPECT_EQ(canonical["oscillation"]["detected"], false);
  EXPECT_EQ(canonical["oscillation"]["amplitude_rad"].get<double>(), 0.0);
  fs::remove_all(dir);
}

// A quasi-static run whose steps found no balance says how many fell back to
// the carried step (solver.quasi_static_carried, added for issue 31): a
// grasp too weak for the weight (2 μ N = 1 N < m g = 1.96 N) slides out, so
// all 25 steps (dt 4 ms, 0.1 s) are carried. A balanced run (the canonical
// scene, held: "auto" is quasi-static) reports its solves and none carried;
// a carried run 0 of both.
TEST(OscillationOutput, SimulateJsonCountsCarriedSteps) {
  const fs::path dir = fs::temp_directory_path() / ("arena_qsc_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path weak = dir / "weak.json";
  std::ofstream(weak) << kWeakGraspQuasiStatic;
  const json sliding = SimulateCli(weak);
  ASSERT_TRUE(sliding.is_object());
  ASSERT_TRUE(sliding["solver"].contains("quasi_static_carried")) << sliding.dump();
  EXPECT_EQ(sliding["solver"]["steps"], 25);
  EXPECT_EQ(sliding["solver"]["quasi_static_carried"], 25);
  EXPECT_GE(sliding["solver"]["quasi_static_solves"].get<int>(), 25);
  const json canonical = SimulateCli(kSourceDir / "examples/scenes/canonical.json");
  ASSERT_TRUE(canonical["solver"].contains("quasi_static_carried")) << canonical.dump();
  EXPECT_EQ(canonical["model"]["inertia"], "quasi_static");
  EXPECT_EQ(canonical["solver"]["quasi_static_carried"], 0);
  // Its first step's start is no balance (the object at rest, the pusher
  // moving): one solve more; every later step balanced at its first solve.
  EXPECT_EQ(canonical["solver"]["quasi_static_solves"], 1);
  const fs::path pivot = dir / "pivot.json";
  std::ofstream(pivot) << kCarriedPivot;
  const json carried = SimulateCli(pivot);
  EXPECT_EQ(carried["model"]["inertia"], "carried");
  EXPECT_EQ(carried["solver"]["quasi_static_carried"], 0);
  EXPECT_EQ(carried["solver"]["quasi_static_solves"], 0);
  fs::remove_all(dir);
}

TEST(OscillationOutput, PredictionDetailMentionsIt) {
  using namespace arena;
  const mechanics::Scene scene = mechanics::ParseScene(kCarriedPivot);
  const mechanics::SimulationResult r = mechanics::Simulate(scene);
  ASSERT_EQ(r.status, mechanics::SimulationStatus::kOk) << r.error;
  const json detail = json::parse(assessment::ScoreSimulation(scene, r, r.samples).detail_json);
  ASSERT_TRUE(detail.contains("oscillation")) << detail.dump();
  EXPECT_NEAR(detail["oscillation"]["amplitude_rad"].get<double>(), r.oscillation.amplitude_rad,
              1e-12);
  EXPECT_NEAR(detail["oscillation"]["frequency_hz"].get<double>(), r.oscillation.frequency_hz,
              1e-12);
  // Quasi-static, the same scene ends on its path: nothing to mention.
  mechanics::Scene qs = scene;
  qs.model.inertia = mechanics::InertiaModel::kQuasiStatic;
  // With the polyhedral cone (quasi_static_test.cpp says why).
  qs.model.cone = mechanics::ConeModel::kPolyhedral;
  const mechanics::SimulationResult settled = mechanics::Simulate(qs);
  const json quiet =
      json::parse(assessment::ScoreSimulation(qs, settled, settled.samples).detail_json);
  EXPECT_FALSE(quiet.contains("oscillation")) << quiet.dump();
}

// The stored prediction (assessment::PredictTrial, as the orchestrator
// records it) carries every field of the run's statistics and oscillation:
// written to a real store, read back from the file. The trials' logged
// truth is the predictions' own run (the store reads no scene).
TEST(OscillationOutput, StoredPredictionCarriesThem) {
  using namespace arena;
  db::testing::TempDir dir;
  const std::string path = dir.File("predictions.db");
  const mechanics::Scene weak = mechanics::ParseScene(kWeakGraspQuasiStatic);
  const mechanics::Scene pivot = mechanics::ParseScene(kCarriedPivot);
  const mechanics::SimulationResult weak_run = mechanics::Simulate(weak);
  const mechanics::SimulationResult pivot_run = mechanics::Simulate(pivot);
  ASSERT_EQ(weak_run.solver.quasi_static_carried, 25);
  ASSERT_TRUE(pivot_run.oscillation.detected);
  std::vector<std::int64_t> ids;
  {
    auto store = db::Store::Open(path);
    std::vector<db::PlannedTrial> trials(2);
    for (int i = 0; i < 2; ++i) {
      trials[i].condition = i;
      trials[i].seed = 7u + static_cast<unsigned>(i);
      trials[i].scene_json = db::testing::SceneJson();
      trials[i].facts = db::testing::SceneFactsFor();
      trials[i].params_json = "{}";
    }
    store->CreateCampaign(db::testing::MakeCampaign(), trials);
    store->UpsertCell("cell", {"point", "line"});
    for (const auto* run : {&weak_run, &pivot_run}) {
      const auto t = store->ClaimNextTrial("cell");
      ASSERT_TRUE(t.has_value());
      auto ingest = store->BeginIngest(t->trial_id, t->attempt, db::testing::SceneSites());
      for (int k = 0; k < 30; ++k) ingest->Add(db::testing::MakeSample(k));
      ingest->Finish();
      store->BeginReset(t->trial_id, t->attempt);
      db::ResetReport reset;
      reset.ok = true;
      store->CompleteReset(t->trial_id, t->attempt, reset);
      const mechanics::Scene& scene = run == &weak_run ? weak : pivot;
      store->RecordPrediction(t->trial_id, t->attempt,
                              assessment::PredictTrial(scene, run->samples));
      store->FinishTrial(t->trial_id, t->attempt);
      ids.push_back(t->trial_id);
    }
  }
  auto store = db::Store::Open(path);
  const auto weak_stored = store->ListPredictions(ids[0]);
  ASSERT_EQ(weak_stored.size(), 1u);
  const json weak_detail = json::parse(weak_stored[0].detail_json);
  ASSERT_TRUE(weak_detail.contains("solver")) << weak_detail.dump();
  EXPECT_EQ(weak_detail["solver"]["steps"], 25);
  EXPECT_EQ(weak_detail["solver"]["quasi_static_carried"], 25) << weak_detail.dump();
  EXPECT_EQ(weak_detail["solver"]["quasi_static_solves"].get<long>(),
            weak_run.solver.quasi_static_solves);
  EXPECT_GE(weak_detail["solver"]["quasi_static_solves"].get<long>(), 25);
  EXPECT_EQ(json::parse(weak_stored[0].model_json)["inertia"], "quasi_static");

  const auto pivot_stored = store->ListPredictions(ids[1]);
  ASSERT_EQ(pivot_stored.size(), 1u);
  const json pivot_detail = json::parse(pivot_stored[0].detail_json);
  ASSERT_TRUE(pivot_detail.contains("oscillation")) << pivot_detail.dump();
  const json& osc = pivot_detail["oscillation"];
  EXPECT_EQ(osc["detected"], true);
  EXPECT_EQ(osc["periods"].get<double>(), pivot_run.oscillation.periods);
  EXPECT_GE(osc["periods"].get<double>(), 3.0);  // a fast mode: its swings counted
  EXPECT_EQ(osc["amplitude_rad"].get<double>(), pivot_run.oscillation.amplitude_rad);
  EXPECT_EQ(osc["window_s"].get<double>(), pivot_run.oscillation.window_s);
  EXPECT_EQ(pivot_detail["solver"]["quasi_static_carried"], 0);
  EXPECT_EQ(pivot_detail["solver"]["quasi_static_solves"], 0);
  EXPECT_EQ(json::parse(pivot_stored[0].model_json)["inertia"], "carried");
}

}  // namespace
