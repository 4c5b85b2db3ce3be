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
//   .../secure:1                  the same with DDS-Security on (issue 8):
//                                 every participant holds an identity of one
//                                 lab made at start-up (schemas/.../security.hpp:
//                                 PKI-DH, access control, RTPS messages signed,
//                                 payloads AES-GCM encrypted); secure:0 is
//                                 the open domain, measured in the same run.
// Target (issue 4): 16 cells x 250 Hz, zero loss, p99 < 5 ms.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <benchmark/benchmark.h>
#include <sys/wait.h>
#include <unistd.h>

#include "arena/schemas/arena.h"
#include "arena/schemas/dds.hpp"
#include "arena/schemas/security.hpp"

namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::system_clock;

std::uint64_t NowNs() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
          .count());
}

int Domain() { return 201 + static_cast<int>(getpid() % 30); }

constexpr int kMaxCells = 16;

// One lab for the whole run: a service identity and kMaxCells cell
// identities, in a temporary directory removed at exit.
class BenchLab {
 public:
  static const BenchLab& Get() {
    static BenchLab lab;
    return lab;
  }
  std::string Service() const { return dir_ + "/service"; }
  std::string Cell(int c) const { return dir_ + "/bench" + std::to_string(c); }
  ~BenchLab() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

 private:
  BenchLab() {
    char tmpl[] = "/tmp/arena-bench-lab-XXXXXX";
    dir_ = mkdtemp(tmpl);
    arena::dds::InitLab(dir_, {});
    arena::dds::IdentityOptions o;
    o.role = arena::dds::Role::kService;
    o.name = "service";
    arena::dds::IssueIdentity(dir_, o);
    o.role = arena::dds::Role::kCell;
    for (int c = 0; c < kMaxCells; ++c) {
      o.name = "bench" + std::to_string(c);
      arena::dds::IssueIdentity(dir_, o);
    }
  }
  std::string dir_;
};

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
// secure: every participant with its lab identity (BenchLab).
Result StreamHere(int cells, int batches, int samples, std::chrono::microseconds period,
                  bool secure) {
  arena::dds::ParticipantOptions ro;
  ro.domain_id = Domain();
  ro.name = "arena.bench.service";
  ro.network.shared_memory = std::getenv("ARENA_BENCH_NO_SHM") == nullptr;
  if (secure) ro.network.security_dir = BenchLab::Get().Service();
  arena::dds::Participant service(ro);
  arena::dds::Reader<arena::msg::GroundTruth> reader(service);
  std::vector<std::unique_ptr<arena::dds::Participant>> parts;
  std::vector<std::unique_ptr<arena::dds::Writer<arena::msg::GroundTruth>>> writers;
  for (int c = 0; c < cells; ++c) {
    arena::dds::ParticipantOptions o = ro;
    o.name = "arena.cell.bench" + std::to_string(c);
    if (secure) o.network.security_dir = BenchLab::Get().Cell(c);
    parts.push_back(std::make_unique<arena::dds::Participant>(o));
    writers.push_back(std::make_unique<arena::dds::Writer<arena::msg::GroundTruth>>(*parts.back()));
  }
  // Secure: every pair of participants authenticates first (PKI-DH).
  for (auto& w : writers) w->WaitForMatched(1, 30s);
  reader.WaitForMatched(cells, 30s);
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
      for (size_t c = 0; c < next.size(); ++c)
        std::fprintf(stderr, "cell %zu: next sample %u\n", c, next[c]);
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
          if (++failures % 5 == 1)
            std::fprintf(stderr, "cell %d batch %d: write failed %d times\n", c, b, failures);
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

// StreamHere in a child process, as separate processes would run it. Fast
// DDS gives every participant of a process a new participant id (well-known
// ports), and arena's local discovery reaches ids 0..kPeerParticipantRange-1
// only: the ~140 participants of all configurations in one process would not
// find each other any more. The child writes the Result into a pipe.
Result Stream(int cells, int batches, int samples, std::chrono::microseconds period, bool secure) {
  if (secure) BenchLab::Get();  // made once, before any fork
  int fds[2];
  if (pipe(fds) != 0) {
    std::perror("pipe");
    std::exit(1);
  }
  const pid_t child = fork();
  if (child == 0) {
    close(fds[0]);
    const Result r = StreamHere(cells, batches, samples, period, secure);
    const double head[4] = {r.seconds, static_cast<double>(r.expected),
                            static_cast<double>(r.received), static_cast<double>(r.out_of_order)};
    std::string bytes(reinterpret_cast<const char*>(head), sizeof head);
    bytes.append(reinterpret_cast<const char*>(r.latency_ms.data()),
                 r.latency_ms.size() * sizeof(double));
    for (std::size_t done = 0; done < bytes.size();) {
      const ssize_t n = write(fds[1], bytes.data() + done, bytes.size() - done);
      if (n <= 0) break;
      done += static_cast<std::size_t>(n);
    }
    close(fds[1]);
    _exit(0);  // no static destructors: the lab belongs to the parent
  }
  close(fds[1]);
  std::string bytes;
  char buf[65536];
  for (ssize_t n; (n = read(fds[0], buf, sizeof buf)) > 0;)
    bytes.append(buf, static_cast<std::size_t>(n));
  close(fds[0]);
  int status = 0;
  waitpid(child, &status, 0);
  Result r;
  if (bytes.size() < 4 * sizeof(double)) {
    std::fprintf(stderr, "bench_dds: the streaming child failed (status %d)\n", status);
    return r;
  }
  double head[4];
  std::memcpy(head, bytes.data(), sizeof head);
  r.seconds = head[0];
  r.expected = static_cast<std::uint64_t>(head[1]);
  r.received = static_cast<std::uint64_t>(head[2]);
  r.out_of_order = static_cast<std::uint64_t>(head[3]);
  r.latency_ms.resize((bytes.size() - sizeof head) / sizeof(double));
  std::memcpy(r.latency_ms.data(), bytes.data() + sizeof head,
              r.latency_ms.size() * sizeof(double));
  return r;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * (v.size() - 1))];
}

void Report(benchmark::State& state, const Result& r, bool secure) {
  state.SetLabel(secure ? "secure" : "open");
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
  const bool secure = state.range(2) != 0;
  const int batches = 3 * 250 / batch;  // 3 s
  for (auto _ : state) {
    Report(state, Stream(cells, batches, batch, std::chrono::microseconds(4000 * batch), secure),
           secure);
  }
}
BENCHMARK(BM_GroundTruthPaced)
    ->ArgNames({"cells", "batch", "secure"})
    ->Args({1, 25, 0})
    ->Args({16, 25, 0})
    ->Args({16, 1, 0})
    ->Args({1, 25, 1})
    ->Args({16, 25, 1})
    ->Args({16, 1, 1})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

void BM_GroundTruthFlatOut(benchmark::State& state) {
  const int cells = static_cast<int>(state.range(0));
  const bool secure = state.range(1) != 0;
  for (auto _ : state) {
    // 100 000 samples per cell, 25 per batch.
    Report(state, Stream(cells, 4000 / std::max(1, cells / 4), 25, 0us, secure), secure);
  }
}
BENCHMARK(BM_GroundTruthFlatOut)
    ->ArgNames({"cells", "secure"})
    ->Args({1, 0})
    ->Args({16, 0})
    ->Args({1, 1})
    ->Args({16, 1})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
