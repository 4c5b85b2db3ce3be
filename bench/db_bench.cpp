// Store ingest speed (issue 5): samples/s into a file, and the CPU cost of
// 16 cells streaming at 250 Hz. Figures go in bench/README.md ("Store").
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <random>
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

// What the service hands the store of Scene() (db reads no scene): its
// columns, and contacts without geometry (the scene gives none).
SceneFacts Facts() {
  SceneFacts f;
  f.object_shape = "box";
  f.object_mass = 0.2;
  f.grip_force = 10;
  f.duration = 10;
  f.finger_type = "mixed";
  f.finger_count = 2;
  f.finger_mu = 0.5;
  f.pusher_type = "point";
  f.pusher_mu = 0.3;
  f.pusher_speed = 0.01;
  f.contact_mask = kPointBit | kLineBit;
  f.contacts = {
      {"l", false, {}, {}, false}, {"r", false, {}, {}, false}, {"pusher", true, {}, {}, false}};
  return f;
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

// A sample as a cell streams it: smooth but not polynomial true motion and
// contact forces (every mantissa bit in use, as a solver's output), and the
// sensors' Gaussian noise on top (examples/campaigns/smoke.json's defects:
// 0.5 mm, 0.005 rad, 0.05 N; 1 % dropped observations). The bit patterns of
// noise do not compress; this is the honest input for a packing codec.
std::vector<Sample> MakeRealisticStream(int n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> gauss(0, 1);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::vector<Sample> out;
  out.reserve(static_cast<std::size_t>(n));
  int mode_run = 0;
  ContactMode modes[3] = {ContactMode::kStick, ContactMode::kStick, ContactMode::kSlide};
  for (int i = 0; i < n; ++i) {
    const double t = i / 250.0;
    Sample s;
    s.t = t;
    const double z = 0.02 * t - 0.001 * std::sin(3 * t), yaw = 0.05 * std::sin(0.7 * t);
    s.object_pose = {0.0004 * std::sin(1.3 * t), 0.0002 * std::cos(0.9 * t), z,
                     std::cos(yaw / 2),          0.001 * std::sin(2 * t),    0.0005 * std::cos(t),
                     std::sin(yaw / 2)};
    s.object_twist = {0.00052 * std::cos(1.3 * t),    -0.00018 * std::sin(0.9 * t),
                      0.02 - 0.003 * std::cos(3 * t), 0.002 * std::cos(2 * t),
                      -0.0005 * std::sin(t),          0.035 * std::cos(0.7 * t)};
    s.pusher_pose = {0.0, 0.0, -0.05 + 0.02 * t, 1, 0, 0, 0};  // commanded motion: exact
    s.pusher_twist = {0, 0, 0.02, 0, 0, 0};
    if (++mode_run > 100 + static_cast<int>(rng() % 200)) {  // modes change in runs
      mode_run = 0;
      modes[rng() % 3] = static_cast<ContactMode>(rng() % 3);
    }
    s.contacts.resize(3);
    for (int c = 0; c < 3; ++c) {
      const double normal = 10.0 + 0.8 * std::sin(0.5 * t + c) + 0.01 * std::sin(40 * t + 3 * c);
      s.contacts[static_cast<std::size_t>(c)].force = {
          (c == 0 ? 1 : -1) * normal, 0.3 * std::sin(t + c), 0.49 + 0.2 * std::cos(1.1 * t + c)};
      s.contacts[static_cast<std::size_t>(c)].torque = {
          0.001 * std::sin(2 * t + c), 0.0005 * std::cos(t - c), 0.002 * std::sin(0.3 * t + c)};
      s.contacts[static_cast<std::size_t>(c)].mode = modes[c];
    }
    s.observed_valid = uniform(rng) >= 0.01;
    s.observed_object_pose = s.object_pose;
    for (int k = 0; k < 3; ++k)
      s.observed_object_pose[static_cast<std::size_t>(k)] += 0.0005 * gauss(rng);
    for (int k = 3; k < 7; ++k)
      s.observed_object_pose[static_cast<std::size_t>(k)] += 0.0025 * gauss(rng);
    const auto& pf = s.contacts[2].force;
    s.observed_pusher_wrench = {-pf[0] + 0.05 * gauss(rng), -pf[1] + 0.05 * gauss(rng),
                                -pf[2] + 0.05 * gauss(rng), 0.005 * gauss(rng),
                                0.005 * gauss(rng),         0.005 * gauss(rng)};
    for (int f = 0; f < 2; ++f) {
      for (int k = 0; k < 3; ++k) {
        s.observed_finger_wrenches.push_back(
            -s.contacts[static_cast<std::size_t>(f)].force[static_cast<std::size_t>(k)] +
            0.05 * gauss(rng));
      }
      for (int k = 0; k < 3; ++k) s.observed_finger_wrenches.push_back(0.005 * gauss(rng));
    }
    out.push_back(std::move(s));
  }
  return out;
}

// Real ground truth: every published stream of the store named by
// ARENA_BENCH_GT_STORE (make one with `arena run bench/long_push_campaign.json
// --db long.db --cells 2`: simulator + cells with sensor noise, a straight
// and a pivoting push of 1876 samples each). Empty when the variable is not set.
std::vector<std::vector<Sample>> LoadRealStreams() {
  std::vector<std::vector<Sample>> out;
  const char* path = std::getenv("ARENA_BENCH_GT_STORE");
  if (path == nullptr || *path == '\0') return out;
  StoreOptions ro;
  ro.read_only = true;
  auto store = Store::Open(path, ro);
  for (const auto& t : store->ListTrials(1)) {
    if (t.gt_stream_id) out.push_back(store->ReadGroundTruth(t.id).samples);
  }
  return out;
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
  BenchStore(int trials, int cells, bool full_sync, const StoreOptions& base = {}) {
    dir = fs::temp_directory_path() / ("arena_db_bench_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    StoreOptions o = base;
    o.synchronous_full = full_sync;
    store = Store::Open((dir / "bench.db").string(), o);
    for (int c = 0; c < cells; ++c)
      store->UpsertCell("cell" + std::to_string(c), {"point", "line"});
    const NewCampaign nc = MakeNewCampaign("bench", 0);
    std::vector<PlannedTrial> planned(static_cast<std::size_t>(trials));
    for (auto& p : planned) {
      p.scene_json = Scene();
      p.facts = Facts();
    }
    store->CreateCampaign(nc, planned);
  }
  ~BenchStore() {
    store.reset();
    fs::remove_all(dir);
  }
};

// Samples per second into a file: each iteration claims a trial and ingests
// 2500 samples (10 s at 250 Hz) with the default batching, then publishes it.
// Args: synchronous FULL (1) or NORMAL (0); data 0 = the regular synthetic
// sample of MakeSample (the first figures), 1 = MakeRealisticStream, 2 = a
// real stream (LoadRealStream; skipped without ARENA_BENCH_GT_STORE); chunks
// packed (AGT2, default) or raw (AGT1); `old`: the settings before
// 2026-11-22 (4 KiB pages, 4 MiB WAL checkpoints) instead of the defaults.
void BM_IngestSamples(benchmark::State& state) {
  const bool full = state.range(0) != 0;
  const int data = static_cast<int>(state.range(1));
  const bool realistic = data != 0;
  IngestOptions io;
  io.pack_chunks = state.range(2) != 0;
  const bool old = state.range(3) != 0;
  StoreOptions so;
  if (old) {
    so.new_file_page_size = 4096;
    so.wal_autocheckpoint_bytes = 1000 * 4096;
  }
  std::vector<std::vector<Sample>> streams(1);  // trial k ingests streams[k % size]
  if (data == 2) {
    streams = LoadRealStreams();
    if (streams.empty()) {
      state.SkipWithError(
          "set ARENA_BENCH_GT_STORE to a store with ground truth (see LoadRealStreams)");
      return;
    }
  } else if (realistic) {
    streams[0] = MakeRealisticStream(2500, 1);
  } else {
    for (int i = 0; i < 2500; ++i) streams[0].push_back(MakeSample(i));
  }
  std::int64_t ingested = 0;
  std::size_t k = 0;
  BenchStore b(static_cast<int>(state.max_iterations), 1, full, so);
  for (auto _ : state) {
    auto t = b.store->ClaimNextTrial("cell0");
    auto ingest = b.store->BeginIngest(t->trial_id, t->attempt, Facts().contacts, io);
    const auto& samples = streams[k++ % streams.size()];
    for (const auto& s : samples) ingest->Add(s);
    benchmark::DoNotOptimize(ingest->Finish());
    ingested += static_cast<std::int64_t>(samples.size());
  }
  state.SetItemsProcessed(ingested);
  b.store.reset();  // closes the file: the last checkpoint is in the figure's size
  const double samples_total = static_cast<double>(ingested);
  state.counters["db_MB"] = static_cast<double>(fs::file_size(b.dir / "bench.db")) / 1e6;
  state.counters["db_bytes_per_sample"] =
      static_cast<double>(fs::file_size(b.dir / "bench.db")) / samples_total;
  state.SetLabel(std::string(full ? "synchronous=FULL" : "synchronous=NORMAL") +
                 (data == 2   ? " real"
                  : realistic ? " realistic"
                              : " regular") +
                 (io.pack_chunks ? " packed" : " raw") +
                 (old ? " 4KiB-pages 4MiB-checkpoints" : " 8KiB-pages 16MiB-checkpoints"));
}
BENCHMARK(BM_IngestSamples)
    ->ArgNames({"full", "realistic", "packed", "old"})
    ->Args({0, 0, 0, 1})
    ->Args({0, 1, 0, 1})  // before: raw chunks, old settings
    ->Args({0, 1, 0, 0})
    ->Args({0, 1, 1, 1})  // each change alone (realistic data)
    ->Args({0, 0, 1, 0})
    ->Args({0, 1, 1, 0})  // after: packed, new settings
    ->Args({1, 1, 1, 0})
    ->Args({0, 2, 0, 1})
    ->Args({0, 2, 1, 0})  // real ground truth: before, after
    ->Iterations(200)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

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
    auto b = std::make_unique<BenchStore>(kCells * (kSimSeconds * kRateHz / kTrialTicks + 1),
                                          kCells, false);
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
          ingests[c] =
              b->store->BeginIngest(trials[c].trial_id, trials[c].attempt, Facts().contacts, io);
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

// Packing and unpacking one 250-sample chunk (1 s at 250 Hz) of the realistic
// stream: CPU per sample, and the packed size.
void BM_PackChunk(benchmark::State& state) {
  const auto samples = MakeRealisticStream(250, 2);
  std::string raw;
  EncodeSamples(samples.data(), samples.size(), &raw);
  std::string packed;
  for (auto _ : state) {
    packed.clear();
    benchmark::DoNotOptimize(PackBlock(raw.data(), raw.size(), &packed));
  }
  state.SetItemsProcessed(state.iterations() * 250);
  state.counters["raw_bytes_per_sample"] = static_cast<double>(raw.size()) / 250;
  state.counters["packed_bytes_per_sample"] = static_cast<double>(packed.size()) / 250;
}
BENCHMARK(BM_PackChunk);

void BM_UnpackChunk(benchmark::State& state) {
  const auto samples = MakeRealisticStream(250, 2);
  std::string raw, packed;
  EncodeSamples(samples.data(), samples.size(), &raw);
  PackBlock(raw.data(), raw.size(), &packed);
  for (auto _ : state) benchmark::DoNotOptimize(DecodeSamples(packed.data(), packed.size()));
  state.SetItemsProcessed(state.iterations() * 250);
}
BENCHMARK(BM_UnpackChunk);

// One claim (find + transition + audit row, committed) with 100 000 planned
// trials over 3 campaigns: the scheduler's cost per dispatched trial.
void BM_ClaimNextTrial(benchmark::State& state) {
  BenchStore b(100000, 1, false);
  std::vector<PlannedTrial> planned(1000);
  for (auto& p : planned) {
    p.scene_json = Scene();
    p.facts = Facts();
  }
  b.store->CreateCampaign(MakeNewCampaign("more", 1), planned);
  for (auto& p : planned) {
    p.scene_json = R"({"fingers": [{"type": "patch"}], "pusher": {"type": "patch"}})";
    p.facts = SceneFacts{};
    p.facts.finger_type = "patch";
    p.facts.finger_count = 1;
    p.facts.pusher_type = "patch";
    p.facts.contact_mask = kPatchBit;
  }
  b.store->CreateCampaign(MakeNewCampaign("patch-only", 2),
                          planned);  // highest priority, but cell0 cannot host it
  for (auto _ : state) benchmark::DoNotOptimize(b.store->ClaimNextTrial("cell0"));
}
BENCHMARK(BM_ClaimNextTrial)->Iterations(2000)->Unit(benchmark::kMicrosecond);

// One trial's store steps on the service's path (issue 27: the overhead
// per trial), as `arena serve` runs them for a clean smoke trial at
// --speed 0: claim, begin ingest, 50 samples, record execution, finish
// (summary, outcomes, executed), begin reset, complete reset (its observed
// pose aimed at the next trial); the prediction and `done` run after the
// next dispatch, off the path, and are left out of the time. CPU time per
// trial of this thread: the store's own cost, without the DDS hops and the
// scheduling of a loaded machine that blur orchestration_bench. Counters
// `<step>_us`: each step's thread CPU time per trial (each a transaction).
// Arg: the new file's page size (8192, the default; 4096 as before
// 2026-11-22): a commit writes each page it dirtied as one WAL frame.
double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

void BM_TrialStorePath(benchmark::State& state) {
  const std::vector<Sample> stream = MakeRealisticStream(50, 7);
  StoreOptions so;
  so.new_file_page_size = static_cast<int>(state.range(0));
  // full:1 is synchronous=FULL (an fsync per commit): what the path costs
  // when no commit may be lost to a power loss (bench/README.md, part IV).
  BenchStore b(static_cast<int>(state.max_iterations) + 1, 1, state.range(1) != 0, so);
  Prediction p;
  p.model_key = "bench";
  p.model_json = "{}";
  p.status = PredictionStatus::kOk;
  p.final_position_error = 0.001;
  p.wall_s = 0.01;
  const char* names[] = {"claim_us",  "begin_ingest_us", "add_us",           "record_execution_us",
                         "finish_us", "begin_reset_us",  "complete_reset_us"};
  double spent[7] = {};
  for (auto _ : state) {
    double t0 = ThreadCpuSeconds();
    int k = 0;
    const auto step = [&] {
      const double t1 = ThreadCpuSeconds();
      spent[k++] += t1 - t0;
      t0 = t1;
    };
    auto t = b.store->ClaimNextTrial("cell0");
    step();
    auto ingest = b.store->BeginIngest(t->trial_id, t->attempt, Facts().contacts, {});
    step();
    ingest->Add(stream);
    step();
    // As the service: the execution record and the move to resetting join
    // Finish's transaction (record_execution_us and begin_reset_us stay 0).
    step();
    FinishAlso also;
    also.execution = ExecutionRecord{"model", "simulated", "{}"};
    also.begin_reset_rule = "reset.after_execute";
    benchmark::DoNotOptimize(ingest->Finish(TrialEnd::kOk, also));
    step();
    step();
    ResetReport r;
    r.ok = true;
    r.pose_observed = true;
    r.observed_pose = {0.0004, 0.0002, 0.0, 1, 0, 0, 0};
    r.position_error = 0.0004;
    r.aimed_at_trial = t->trial_id + 1;
    b.store->CompleteReset(t->trial_id, t->attempt, r, "reset.verified");
    step();
    state.PauseTiming();  // after the next dispatch in the service: off the path
    b.store->RecordPrediction(t->trial_id, t->attempt, p);
    b.store->FinishTrial(t->trial_id, t->attempt);
    state.ResumeTiming();
  }
  const double n = static_cast<double>(state.iterations());
  for (int i = 0; i < 7; ++i) state.counters[names[i]] = n > 0 ? 1e6 * spent[i] / n : 0;
}
BENCHMARK(BM_TrialStorePath)
    ->ArgNames({"page", "full"})
    ->Args({8192, 0})
    ->Args({4096, 0})
    ->Args({8192, 1})
    ->Iterations(2000)
    ->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
