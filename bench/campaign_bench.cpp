// Cost of reading scenes and campaigns and of planning trials: what the
// service pays at submit time and per dispatched trial.
#include <fstream>
#include <sstream>
#include <string>

#include <benchmark/benchmark.h>

#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/sampler.hpp"

namespace {

using namespace arena;

std::string ReadText(const std::string& path) {
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/" + path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

void BM_ParseScene(benchmark::State& state) {
  const std::string text = ReadText("examples/scenes/canonical.json");
  for (auto _ : state) benchmark::DoNotOptimize(mechanics::ParseScene(text));
}
BENCHMARK(BM_ParseScene);

void BM_SceneToJson(benchmark::State& state) {
  const mechanics::Scene scene = mechanics::ParseScene(ReadText("examples/scenes/canonical.json"));
  for (auto _ : state) benchmark::DoNotOptimize(mechanics::SceneToJson(scene));
}
BENCHMARK(BM_SceneToJson);

// Submit-time cost: parse + validate all 512 conditions of the pivot study.
void BM_LoadPivotStudyCampaign(benchmark::State& state) {
  const std::string path = std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/pivot_study.json";
  for (auto _ : state) benchmark::DoNotOptimize(orchestrator::LoadCampaignFile(path));
}
BENCHMARK(BM_LoadPivotStudyCampaign)->Unit(benchmark::kMillisecond);

// Per-dispatch cost: one trial of the pivot study (12 variations, Sobol).
void BM_PlanTrial(benchmark::State& state) {
  const auto campaign = orchestrator::LoadCampaignFile(std::string(ARENA_SOURCE_DIR) +
                                                       "/examples/campaigns/pivot_study.json");
  int64_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(orchestrator::PlanTrial(campaign, i));
    i = (i + 1) % orchestrator::TrialCount(campaign);
  }
}
BENCHMARK(BM_PlanTrial)->Unit(benchmark::kMicrosecond);

void BM_ScrambledSobolCoordinate(benchmark::State& state) {
  uint32_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(orchestrator::ScrambledSobolCoordinate(i++, 7, 42));
}
BENCHMARK(BM_ScrambledSobolCoordinate);

void BM_LatinHypercubeCoordinate(benchmark::State& state) {
  const uint64_t n = 1000000;
  uint64_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(orchestrator::LatinHypercubeCoordinate(i, n, 3, 42));
    i = (i + 1) % n;
  }
}
BENCHMARK(BM_LatinHypercubeCoordinate);

}  // namespace

BENCHMARK_MAIN();
