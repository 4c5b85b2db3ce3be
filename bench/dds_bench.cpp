// Ground-truth streaming over the shared DDS set-up (local-only transports:
// shared memory + UDPv4 on 127.0.0.1), one reader participant (the service)
// and N writer participants (cells), each in its own thread.
//
//   BM_GroundTruthFlatOut/cells   every cell writes as fast as the reliable,
//                                 bounded stream lets it; samples/s with the
//                                 loss (must be 0) and order checked.
//   BM_GroundTruthPaced/cells/batch  every cell streams 250 Hz in real time
//                                 (batch samples per message) for 3 s;
//                                 p50/p99 latency (write -> taken by the
//                                 reader thread) and loss.
// Target (issue 4): 16 cells x 250 Hz, zero loss, p99 < 5 ms.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

#include <benchmark/benchmark.h>
#include <unistd.h>

#include "arena/schemas/arena.h"
#include "arena/schemas/dds.hpp"

namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::system_clock;

std::uint64_t NowNs() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count());
}

int Domain() { return 201 + static_cast<int>(getpid() % 30); }

arena::msg::GroundTruth MakeBatch(std::uint64_t trial, std::uint32_t index, int samples) {
  arena::msg::GroundTruth g;
  g.trial_id(trial);
  g.attempt(1);
  g.cell_id("bench");
  g.batch(index);
  g.first_sample(index * static_cast<std::uint32_t>(samples));
  g.samples().resize(static_cast<size_t>(samples));
  for (int k = 0; k < samples; ++k) {
    auto& s = g.samples()[static_cast<size_t>(k)];
    s.t((index * samples + k) / 250.0);
    s.object_pose() = {0.001 * k, 0, 0.01, 1, 0, 0, 0};
    s.pusher_pose() = {0, 0, -0.05, 1, 0, 0, 0};
    s.contacts().resize(3);  // two fingers and the pusher: a typical scene
    s.observed_valid(true);
    s.observed_object_pose() = {0.001 * k, 0, 0.01, 1, 0, 0, 0};
    s.observed_finger_wrenches().resize(12);
  }
  return g;
}

struct Result {
  double seconds = 0;
  std::uint64_t expected = 0, received = 0, out_of_order = 0;
  std::vector<double> latency_ms;
};

// `cells` writer participants (fresh for every configuration) each send
// `batches` batches of `samples` samples, one every `period` (0 = flat out).
Result Stream(int cells, int batches, int samples, std::chrono::microseconds period) {
  arena::dds::ParticipantOptions ro;
  ro.domain_id = Domain();
  ro.name = "arena.bench.service";
  ro.network.shared_memory = std::getenv("ARENA_BENCH_NO_SHM") == nullptr;
  arena::dds::Participant service(ro);
  arena::dds::Reader<arena::msg::GroundTruth> reader(service);
  std::vector<std::unique_ptr<arena::dds::Participant>> parts;
  std::vector<std::unique_ptr<arena::dds::Writer<arena::msg::GroundTruth>>> writers;
  for (int c = 0; c < cells; ++c) {
    arena::dds::ParticipantOptions o = ro;
    o.name = "arena.cell.bench" + std::to_string(c);
    parts.push_back(std::make_unique<arena::dds::Participant>(o));
    writers.push_back(std::make_unique<arena::dds::Writer<arena::msg::GroundTruth>>(*parts.back()));
  }
  for (auto& w : writers) w->WaitForMatched(1, 10s);
  reader.WaitForMatched(cells, 10s);
  Result r;
  r.expected = static_cast<std::uint64_t>(cells) * batches * samples;
  std::atomic<bool> done{false};
  std::thread consumer([&] {
    std::vector<std::uint32_t> next(static_cast<size_t>(cells), 0);
    const auto give_up = std::chrono::steady_clock::now() + 15s;
    while (r.received < r.expected && std::chrono::steady_clock::now() < give_up) {
      auto g = reader.Take(100ms);
      if (!g) continue;
      const std::uint64_t now = NowNs();
      r.latency_ms.push_back((now - g->sent_unix_ns()) * 1e-6);
      auto& n = next[static_cast<size_t>(g->trial_id())];
      if (g->first_sample() != n) {
        ++r.out_of_order;
        
      }
      n = g->first_sample() + static_cast<std::uint32_t>(g->samples().size());
      r.received += g->samples().size();
    }
    if (r.received < r.expected) {
      for (size_t c = 0; c < next.size(); ++c) std::fprintf(stderr, "cell %zu: next sample %u\n", c, next[c]);
    }
    done = true;
  });
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> producers;
  for (int c = 0; c < cells; ++c) {
    producers.emplace_back([&, c] {
      auto next_due = std::chrono::steady_clock::now();
      for (int b = 0; b < batches; ++b) {
        auto g = MakeBatch(static_cast<std::uint64_t>(c), static_cast<std::uint32_t>(b), samples);
        if (period.count() > 0) {
          next_due += period;
          std::this_thread::sleep_until(next_due);
        }
        g.sent_unix_ns(NowNs());
        int failures = 0;
        while (!writers[static_cast<size_t>(c)]->Write(g)) {
          if (++failures % 5 == 1) std::fprintf(stderr, "cell %d batch %d: write failed %d times\n", c, b, failures);
          if (done) break;
        }
      }
    });
  }
  for (auto& p : producers) p.join();
  consumer.join();

  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * (v.size() - 1))];
}

void Report(benchmark::State& state, const Result& r) {
  state.counters["samples_per_s"] = r.received / r.seconds;
  state.counters["lost"] = static_cast<double>(r.expected - std::min(r.expected, r.received));
  state.counters["out_of_order"] = static_cast<double>(r.out_of_order);
  state.counters["p50_ms"] = Percentile(r.latency_ms, 0.50);
  state.counters["p99_ms"] = Percentile(r.latency_ms, 0.99);
  state.counters["max_ms"] = Percentile(r.latency_ms, 1.0);
}

void BM_GroundTruthPaced(benchmark::State& state) {
  const int cells = static_cast<int>(state.range(0));
  const int batch = static_cast<int>(state.range(1));
  const int batches = 3 * 250 / batch;  // 3 s
  for (auto _ : state) {
    Report(state, Stream(cells, batches, batch, std::chrono::microseconds(4000 * batch)));
  }
}
BENCHMARK(BM_GroundTruthPaced)
    ->Args({1, 25})
    ->Args({16, 25})
    ->Args({16, 1})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();


void BM_GroundTruthFlatOut(benchmark::State& state) {
  const int cells = static_cast<int>(state.range(0));
  for (auto _ : state) {
    // 100 000 samples per cell, 25 per batch.
    Report(state, Stream(cells, 4000 / std::max(1, cells / 4), 25, 0us));
  }
}
BENCHMARK(BM_GroundTruthFlatOut)->Arg(1)->Arg(16)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
