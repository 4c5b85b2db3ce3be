// What a MuJoCo calibration pays per simulation (issue 17, `arena calibrate
// --predictor mujoco`): the scene compiled afresh every run (Simulate) against
// compiled once and only friction, grip and mass patched (Prepare). Scene:
// the calibration e2e campaign's kind of trial, a box held at 4 N and pushed
// 3 mm up from below 5 mm off centre, 0.3 s, at MuJoCo time steps of 0.5, 1
// and 2 ms (the argument, in microseconds). bench/README.md has the figures.
#include <benchmark/benchmark.h>

#include <memory>

#include "arena/simulators/simulator.hpp"
#include "scenes.hpp"

namespace {

arena::mechanics::Scene PushedBox() {
  arena::mechanics::Scene s = arena::mechanics::testing::HeldBox(0.2, 4.0, 0.5);
  arena::mechanics::PusherSpec p;
  p.name = "pusher";
  p.type = arena::mechanics::ContactType::kPoint;
  p.position = {0, 0.005, -0.05};
  p.normal = {0, 0, 1};
  p.mu = 0.3;
  p.motion.velocity = {0, 0, 0.01};
  s.pusher = p;
  s.duration = 0.3;
  return s;
}

std::unique_ptr<arena::simulators::Simulator> Mujoco(const benchmark::State& state) {
  arena::simulators::MujocoSettings m;
  m.timestep = static_cast<double>(state.range(0)) * 1e-6;
  return arena::simulators::MakeMujocoSimulator(m);
}

// Each iteration a new friction, as the optimiser asks.
void BM_MujocoFreshRun(benchmark::State& state) {
  const auto sim = Mujoco(state);
  arena::mechanics::Scene s = PushedBox();
  int k = 0;
  for (auto _ : state) {
    for (auto& f : s.fingers) f.mu = 0.5 + 0.01 * (++k % 20);
    benchmark::DoNotOptimize(sim->Simulate(s));
  }
}
void BM_MujocoPreparedRun(benchmark::State& state) {
  const auto sim = Mujoco(state);
  arena::mechanics::Scene s = PushedBox();
  const auto prepared = sim->Prepare(s);
  int k = 0;
  for (auto _ : state) {
    for (auto& f : s.fingers) f.mu = 0.5 + 0.01 * (++k % 20);
    benchmark::DoNotOptimize(prepared->Simulate(s));
  }
  if (prepared->rebuilt() != 0) state.SkipWithError("a variant was rebuilt");
}

BENCHMARK(BM_MujocoFreshRun)->Arg(500)->Arg(1000)->Arg(2000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MujocoPreparedRun)->Arg(500)->Arg(1000)->Arg(2000)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
