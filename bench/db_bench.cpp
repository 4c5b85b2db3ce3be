// Store ingest speed (issue 5): samples/s into a file, and the CPU cost of
// 16 cells streaming at 250 Hz. Figures go in bench/README.md ("Store").
#include <benchmark/benchmark.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <string>
#include <vector>

#include <unistd.h>

#include "arena/db/store.hpp"

namespace {

using namespace arena::db;
namespace fs = std::filesystem;

std::string Scene() {
  return R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.1], "mass": 0.2},
     "grip_force": 10, "duration": 10,
     "fingers": [{"name": "l", "type": "point", "mu": 0.5}, {"name": "r", "type": "line", "mu": 0.5}],
     "pusher": {"type": "point", "mu": 0.3, "motion": {"velocity": [0, 0, 0.01]}}})";
}

// A realistic sample: 3 contacts (2 fingers + pusher), 12 finger F/T values.
Sample MakeSample(int i) {
  Sample s;
  s.t = i / 250.0;
  s.object_pose = {0.001 * i, 0.0002 * i, 0, 1, 0, 0, 0};
  s.object_twist = {0.25, 0.05, 0, 0, 0, 0.01};
  s.pusher_pose = {0, 0, -0.05 + 0.00004 * i, 1, 0, 0, 0};
  s.pusher_twist = {0, 0, 0.01, 0, 0, 0};
  s.contacts.resize(3);
  for (int c = 0; c < 3; ++c) {
    s.contacts[c].force = {0.1 * c, 0.5, 10.0 + 0.001 * i};
    s.contacts[c].torque = {0, 0.001 * c, 0};
    s.contacts[c].mode = static_cast<ContactMode>((i + c) % 3);
  }
  s.observed_object_pose = s.object_pose;
  s.observed_pusher_wrench = {0, 0, 10, 0, 0, 0};
  s.observed_finger_wrenches.assign(12, 0.5);
  return s;
}

NewCampaign MakeNewCampaign(const char* name, int priority) {
  NewCampaign nc;
  nc.name = name;
  nc.spec_json = std::string(R"({"name": "bench"})");
  nc.priority = priority;
  return nc;
}

struct BenchStore {
  fs::path dir;
  std::unique_ptr<Store> store;
  BenchStore(int trials, int cells, bool full_sync) {
    dir = fs::temp_directory_path() / ("arena_db_bench_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    StoreOptions o;
    o.synchronous_full = full_sync;
    store = Store::Open((dir / "bench.db").string(), o);
    for (int c = 0; c < cells; ++c) store->UpsertCell("cell" + std::to_string(c), {"point", "line"});
    const NewCampaign nc = MakeNewCampaign("bench", 0);
    std::vector<PlannedTrial> planned(static_cast<std::size_t>(trials));
    for (auto& p : planned) p.scene_json = Scene();
    store->CreateCampaign(nc, planned);
  }
  ~BenchStore() {
    store.reset();
    fs::remove_all(dir);
  }
};

// Samples per second into a file: each iteration claims a trial and ingests
// 2500 samples (10 s at 250 Hz) with the default batching, then publishes it.
void BM_IngestSamples(benchmark::State& state) {
  constexpr int kSamplesPerTrial = 2500;
  const bool full = state.range(0) != 0;
  std::vector<Sample> samples;
  for (int i = 0; i < kSamplesPerTrial; ++i) samples.push_back(MakeSample(i));
  BenchStore b(static_cast<int>(state.max_iterations), 1, full);
  for (auto _ : state) {
    auto t = b.store->ClaimNextTrial("cell0");
    auto ingest = b.store->BeginIngest(t->trial_id, t->attempt);
    for (const auto& s : samples) ingest->Add(s);
    benchmark::DoNotOptimize(ingest->Finish());
  }
  state.SetItemsProcessed(state.iterations() * kSamplesPerTrial);
  state.counters["db_MB"] = static_cast<double>(fs::file_size(b.dir / "bench.db")) / 1e6;
  state.SetLabel(full ? "synchronous=FULL" : "synchronous=NORMAL");
}
BENCHMARK(BM_IngestSamples)->Arg(0)->Arg(1)->Iterations(200)->UseRealTime()->Unit(benchmark::kMillisecond);

// 16 cells at 250 Hz, run as fast as possible for 60 simulated seconds: every
// tick each cell delivers one sample, each ingest commits every 0.5 simulated
// seconds (its Poll() interval), trials last 10 s and are then published and
// replaced by the next. CPU seconds per simulated second = share of one core.
void BM_SixteenCells250Hz(benchmark::State& state) {
  constexpr int kCells = 16, kRateHz = 250, kSimSeconds = 60, kTrialTicks = 2500;
  constexpr int kCommitTicks = kRateHz / 2;
  std::vector<Sample> samples;
  for (int i = 0; i < kTrialTicks; ++i) samples.push_back(MakeSample(i));
  double cpu_total = 0;
  for (auto _ : state) {
    state.PauseTiming();
    auto b = std::make_unique<BenchStore>(kCells * (kSimSeconds * kRateHz / kTrialTicks + 1), kCells, false);
    std::vector<std::unique_ptr<Ingest>> ingests(kCells);
    std::vector<ClaimedTrial> trials(kCells);
    IngestOptions io;
    io.samples_per_commit = 1 << 30;  // commit by (simulated) time only, like Poll() at 0.5 s
    state.ResumeTiming();
    const std::clock_t c0 = std::clock();
    for (int tick = 0; tick < kSimSeconds * kRateHz; ++tick) {
      const int k = tick % kTrialTicks;
      for (int c = 0; c < kCells; ++c) {
        if (k == 0) {
          if (ingests[c]) ingests[c]->Finish();
          trials[c] = *b->store->ClaimNextTrial("cell" + std::to_string(c));
          ingests[c] = b->store->BeginIngest(trials[c].trial_id, trials[c].attempt, io);
        }
        ingests[c]->Add(samples[static_cast<std::size_t>(k)]);
        if (k % kCommitTicks == kCommitTicks - 1) ingests[c]->Flush();
      }
    }
    for (auto& in : ingests) in->Finish();
    cpu_total += static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    state.PauseTiming();
    b.reset();
    state.ResumeTiming();
  }
  const double per_sim_s = cpu_total / static_cast<double>(state.iterations()) / kSimSeconds;
  state.counters["cpu_s_per_sim_s"] = per_sim_s;
  state.counters["core_percent"] = 100 * per_sim_s;
  state.SetItemsProcessed(state.iterations() * kCells * kRateHz * kSimSeconds);
}
BENCHMARK(BM_SixteenCells250Hz)->Iterations(3)->Unit(benchmark::kMillisecond);

// The store's own per-sample work without SQLite: validation and encoding.
void BM_CheckAndEncodeSample(benchmark::State& state) {
  const Sample s = MakeSample(7);
  std::string block;
  block.reserve(1 << 20);
  for (auto _ : state) {
    if (block.size() > (1 << 19)) block.clear();
    benchmark::DoNotOptimize(CheckSample(s));
    EncodeSamples(&s, 1, &block);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_CheckAndEncodeSample);

// One claim (find + transition + audit row, committed) with 100 000 planned
// trials over 3 campaigns: the scheduler's cost per dispatched trial.
void BM_ClaimNextTrial(benchmark::State& state) {
  BenchStore b(100000, 1, false);
  std::vector<PlannedTrial> planned(1000);
  for (auto& p : planned) p.scene_json = Scene();
  b.store->CreateCampaign(MakeNewCampaign("more", 1), planned);
  for (auto& p : planned) {
    p.scene_json = R"({"fingers": [{"type": "patch"}], "pusher": {"type": "patch"}})";
  }
  b.store->CreateCampaign(MakeNewCampaign("patch-only", 2), planned);  // highest priority, but cell0 cannot host it
  for (auto _ : state) benchmark::DoNotOptimize(b.store->ClaimNextTrial("cell0"));
}
BENCHMARK(BM_ClaimNextTrial)->Iterations(2000)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
