// Evaluation throughput (issue 14): `arena evaluate`'s EvaluateCampaign on
// 1,000 done trials × 16 settings, in trial-settings per second of wall time
// and CPU seconds, with the threads used. The store is made once by `arena
// run` on a 1,000-trial campaign (smoke's scene and variations, Sobol over
// 500 conditions × 2 replicates, 4 mm pushes) and kept in
// $ARENA_EVAL_BENCH_DB (default /tmp/arena_evaluation_bench.db).
//
//   build/bench/evaluation_bench --benchmark_filter=Reference
//
// "Reference" is the grid of the figure (facets 4,8,16,32 × points
// 2,3,5,9 at dt 4 ms: 36 × 16 in 1.3 s, about 440/s); "Default" is the
// default grid of `arena evaluate` (facets 4..32 × dt 8..1 ms).
#include <sys/resource.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>

#include <benchmark/benchmark.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/evaluation.hpp"
#include "arena/db/store.hpp"

namespace {

namespace fs = std::filesystem;

std::string StorePath() {
  const char* env = std::getenv("ARENA_EVAL_BENCH_DB");
  return env ? env : "/tmp/arena_evaluation_bench.db";
}

// 0 when there is no usable store: a file a read-only open refuses (made by an
// older build at an older schema, which read-only cannot migrate) is rebuilt
// rather than aborting the benchmark.
int DoneTrials(const std::string& path) {
  if (!fs::exists(path)) return 0;
  arena::db::StoreOptions ro;
  ro.read_only = true;
  try {
    auto store = arena::db::Store::Open(path, ro);
    int done = 0;
    for (const auto& t : store->ListTrials(1)) done += t.state == arena::db::TrialState::kDone;
    return done;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "evaluation_bench: rebuilding %s (%s)\n", path.c_str(), e.what());
    return 0;
  }
}

// A 1,000-trial campaign run once with `arena run` (2 cells).
void EnsureStore(const std::string& path) {
  if (DoneTrials(path) >= 1000) return;
  for (const char* suffix : {"", "-wal", "-shm", ".log"}) fs::remove(path + suffix);
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/smoke.json");
  nlohmann::json c = nlohmann::json::parse(in);
  c["name"] = "evaluation_bench";
  c["sampler"] = "sobol";
  c["conditions"] = 500;
  c["replicates"] = 2;
  c["variations"]["grip_force"] = {{"min", 8}, {"max", 12}};
  c["variations"]["pivot_offset"] = {{"min", 0}, {"max", 0.01}};
  const std::string campaign = path + ".campaign.json";
  std::ofstream(campaign) << c.dump();
  const std::string cmd = std::string(ARENA_BINARY) + " run " + campaign + " --db " + path +
                          " --cells 2 --domain 211 --quiet > " + path + ".run.out 2>&1";
  if (std::system(cmd.c_str()) != 0 || DoneTrials(path) < 1000) {
    throw std::runtime_error("evaluation_bench: `arena run` did not finish 1,000 trials (" + path +
                             ".run.out)");
  }
}

double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_utime.tv_usec * 1e-6 + u.ru_stime.tv_sec +
         u.ru_stime.tv_usec * 1e-6;
}

void Evaluate(benchmark::State& state, bool reference) {
  const std::string path = StorePath();
  EnsureStore(path);
  arena::assessment::EvaluationOptions o;
  o.threads = static_cast<int>(state.range(0));
  o.convergence_trials = 0;
  arena::assessment::PredictorRequest arena_predictor;
  if (reference) {
    arena::assessment::FidelityGrid g;
    g.facets = {4, 8, 16, 32};
    g.points = {2, 3, 5, 9};
    g.dt = {0.004};
    arena_predictor.arena_grid = g;
  }
  o.predictors = {arena_predictor};
  long jobs = 0;
  double cpu = 0;
  for (auto _ : state) {
    auto store = arena::db::Store::Open(path, {});
    const double cpu0 = CpuSeconds();
    const auto run = arena::assessment::EvaluateCampaign(*store, 1, o);
    cpu += CpuSeconds() - cpu0;
    jobs += static_cast<long>(run.report.trials) * static_cast<long>(run.report.settings.size());
  }
  state.counters["trial_settings"] = static_cast<double>(jobs) / state.iterations();
  state.counters["trial_settings_per_s"] =
      benchmark::Counter(static_cast<double>(jobs), benchmark::Counter::kIsRate);
  state.counters["cpu_s"] = cpu / state.iterations();
  state.counters["threads"] = static_cast<double>(o.threads);
}

void BM_EvaluateReference(benchmark::State& state) { Evaluate(state, true); }
void BM_EvaluateDefault(benchmark::State& state) { Evaluate(state, false); }

BENCHMARK(BM_EvaluateReference)
    ->Arg(2)
    ->Arg(1)
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kSecond);
BENCHMARK(BM_EvaluateDefault)->Arg(2)->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

}  // namespace

BENCHMARK_MAIN();
