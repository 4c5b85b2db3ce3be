// Prediction of a closed-loop trial (issue 19): the recorded commands are
// replayed open-loop through the predictor and scored like any trial.
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/assessment/predictor.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {
namespace {

const char* kClosedLoopPivot =
    R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2},
  "gravity": [0, 0, -9.81], "duration": 0.2, "grip_force": 10.0,
  "fingers": [
    {"name": "left", "type": "patch", "radius": 0.005, "position": [-0.025, 0, 0],
     "normal": [1, 0, 0], "mu": 0.5},
    {"name": "right", "type": "patch", "radius": 0.005, "position": [0.025, 0, 0],
     "normal": [-1, 0, 0], "mu": 0.5}],
  "pusher": {"type": "point", "position": [0, -0.015, -0.04], "normal": [0, 1, 0], "mu": 0.3,
             "motion": {"controller": "pivot_to_angle", "target": 0.1, "gain": 0.1}},
  "model": {"facets": 8, "points": 3, "dt": 0.004, "reduce": "auto"}})";

// A speed that changes every sample, as a controller's would (m/s).
RecordedCommands Ramp(std::size_t n) {
  RecordedCommands out(n);
  for (std::size_t k = 0; k < n; ++k) out[k].velocity = {0, 0.002 + 0.0004 * (k % 20), 0};
  return out;
}

TEST(ClosedLoopReplay, ReplayingTheCommandsThatMadeTheTruthPredictsItExactly) {
  const mechanics::Scene scene = mechanics::ParseScene(kClosedLoopPivot);
  const RecordedCommands commands = Ramp(51);  // one answer per sample (0.2 s at 250 Hz)
  const mechanics::SimulationResult truth = mechanics::Simulate(scene, ReplayCommands(commands));
  ASSERT_EQ(truth.status, mechanics::SimulationStatus::kOk) << truth.error;
  ASSERT_EQ(truth.samples.size(), 51u);
  ASSERT_GT((truth.samples.back().pusher_position - truth.samples.front().pusher_position).norm(),
            1e-4);  // the commands moved the pusher

  const db::Prediction p = PredictTrial(scene, truth.samples, nlohmann::json(), &commands);
  ASSERT_EQ(p.status, db::PredictionStatus::kOk) << p.detail_json;
  EXPECT_LT(*p.final_position_error, 1e-12);
  EXPECT_LT(*p.final_angle_error, 1e-12);
  EXPECT_EQ(nlohmann::json::parse(p.detail_json)["replayed_commands"], 51);

  // Other commands are another prediction: the replay does use them.
  const RecordedCommands faster = [&] {
    RecordedCommands f = commands;
    for (auto& c : f) c.velocity *= 2;
    return f;
  }();
  const db::Prediction q = PredictTrial(scene, truth.samples, nlohmann::json(), &faster);
  ASSERT_EQ(q.status, db::PredictionStatus::kOk) << q.detail_json;
  EXPECT_GT(*q.final_position_error + *q.final_angle_error, 1e-5);
}

TEST(ClosedLoopReplay, WithoutCommandsItSaysWhyInsteadOfRunningOpenLoop) {
  const mechanics::Scene scene = mechanics::ParseScene(kClosedLoopPivot);
  const RecordedCommands commands = Ramp(51);
  const auto truth = mechanics::Simulate(scene, ReplayCommands(commands)).samples;
  const db::Prediction none = PredictTrial(scene, truth, nlohmann::json(), nullptr);
  EXPECT_EQ(none.status, db::PredictionStatus::kError);
  EXPECT_NE(none.detail_json.find("without recorded pusher commands"), std::string::npos);

  // MuJoCo replays the recorded commands like arena's model does.
  const db::Prediction mujoco =
      PredictTrial(scene, truth, nlohmann::json({{"predictor", "mujoco"}}), &commands);
  EXPECT_EQ(mujoco.status, db::PredictionStatus::kOk) << mujoco.detail_json;
  ASSERT_TRUE(mujoco.final_position_error.has_value()) << mujoco.detail_json;
  EXPECT_TRUE(std::isfinite(*mujoco.final_position_error));

  const PredictedRun run = SimulatePrediction(scene, nlohmann::json(), nullptr);
  EXPECT_EQ(run.result.status, mechanics::SimulationStatus::kInvalidScene);
}

TEST(ClosedLoopReplay, TheArenaPredictorReplaysAtEachOfItsSettings) {
  const mechanics::Scene scene = mechanics::ParseScene(kClosedLoopPivot);
  const RecordedCommands commands = Ramp(51);
  mechanics::ModelOptions coarse = scene.model, fine = scene.model;
  fine.dt = 0.001;
  const auto predictor = MakeArenaPredictor({coarse, fine});
  for (std::size_t s = 0; s < 2; ++s) {
    const auto r = predictor->RunClosedLoop(scene, s, ReplayCommands(commands));
    ASSERT_EQ(r.status, mechanics::SimulationStatus::kOk) << r.error;
    EXPECT_EQ(r.model.dt, s == 0 ? 0.004 : 0.001);
    mechanics::Scene at = scene;
    at.model = s == 0 ? coarse : fine;
    const auto direct = mechanics::Simulate(at, ReplayCommands(commands));
    ASSERT_EQ(r.samples.size(), direct.samples.size());
    EXPECT_LT((r.samples.back().position - direct.samples.back().position).norm(), 1e-12);
  }
  // MuJoCo drives its pusher with the same commands, each from the sample it
  // answers. arena's model emits sample 0 once its first step has run, so
  // its answer to sample 0 moves the pusher one step later: the two pusher
  // paths differ by that one step of the first command, and by nothing else.
  const auto mujoco = MakeMujocoPredictor(MujocoGrid{{0.002}, {"elliptic"}, {10}});
  const auto m = mujoco->RunClosedLoop(scene, 0, ReplayCommands(commands));
  ASSERT_EQ(m.status, mechanics::SimulationStatus::kOk) << m.error;
  const auto direct = mechanics::Simulate(scene, ReplayCommands(commands));
  ASSERT_EQ(m.samples.size(), direct.samples.size());
  const Eigen::Vector3d first_step = commands[0].velocity * scene.model.dt;
  for (std::size_t i = 1; i < m.samples.size(); ++i) {
    const Eigen::Vector3d ahead = m.samples[i].pusher_position - direct.samples[i].pusher_position;
    EXPECT_LT((ahead - first_step).norm(), 1e-12) << i;
  }
}

}  // namespace
}  // namespace arena::assessment
