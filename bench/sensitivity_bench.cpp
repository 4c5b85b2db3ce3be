// Cost of `arena sensitivity SCENE.json` per scene: every parameter's
// derivatives (4 model runs each) and the stability probes at the default
// 2 % tolerance, on 1 and 2 worker threads. Counters: model runs per report
// and ms per model run. Scenes: the canonical scene (1 s push, line finger)
// and the smoke campaign's short pivoting push (0.2 s).
#include <benchmark/benchmark.h>

#include <chrono>

#include "arena/assessment/sensitivity.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace {

using namespace arena;

mechanics::Scene Canonical() {
  return mechanics::LoadSceneFile(std::string(ARENA_SOURCE_DIR) +
                                  "/examples/scenes/canonical.json");
}

mechanics::Scene ShortPivot() {
  mechanics::Scene s = Canonical();
  s.duration = 0.2;
  s.fingers[1].type = mechanics::ContactType::kPoint;
  s.pusher->position = {0, 0.01, -0.05};
  s.pusher->motion.velocity = {0, 0, 0.02};
  mechanics::ValidateScene(s);
  return s;
}

void Report(benchmark::State& state, const mechanics::Scene& scene, bool stability) {
  assessment::SensitivityOptions o;
  o.threads = static_cast<int>(state.range(0));
  o.check_stability = stability;
  long runs = 0;
  double wall_ms = 0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    const auto r = assessment::AnalyseScene(scene, o);
    wall_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    runs = r.model_runs;
    benchmark::DoNotOptimize(r.parameters.data());
  }
  const double iterations = static_cast<double>(state.iterations());
  state.counters["model_runs"] = static_cast<double>(runs);
  state.counters["parameters"] = static_cast<double>(assessment::SceneParameters(scene).size());
  state.counters["ms_per_report"] = wall_ms / iterations;
  state.counters["ms_per_run"] = wall_ms / iterations / static_cast<double>(runs);
}

void BM_SensitivityCanonical(benchmark::State& state) { Report(state, Canonical(), true); }
void BM_SensitivityCanonicalNoStability(benchmark::State& state) {
  Report(state, Canonical(), false);
}
void BM_SensitivityShortPivot(benchmark::State& state) { Report(state, ShortPivot(), true); }

BENCHMARK(BM_SensitivityCanonical)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_SensitivityCanonicalNoStability)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_SensitivityShortPivot)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
