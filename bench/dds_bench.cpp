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
#include <functional>
#include <mutex>
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
  std::string Controller() const { return dir_ + "/controller"; }
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
    o.role = arena::dds::Role::kController;
    o.name = "controller";
    arena::dds::IssueIdentity(dir_, o);
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
  std::uint64_t expected = 0, received = 0, out_of_order = 0;  // the reliable log
  std::vector<double> latency_ms;                  // log batches; live rows: live samples
  std::uint64_t live_sent = 0, live_received = 0;  // live rows
  std::vector<double> loop_ms;  // control rows: live sample written -> its command at the cell
};
constexpr int kHead = 7;  // doubles before the vectors in the child's pipe

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
  std::mutex write_mutex;
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
        const auto write_start = std::chrono::steady_clock::now();
        while (!writers[static_cast<size_t>(c)]->Write(g)) {
          if (++failures % 5 == 1)
            std::fprintf(stderr, "cell %d batch %d: write failed %d times\n", c, b, failures);
          if (done) break;
        }
        // The profile of the tail (bench/README.md): time inside Write(),
        // which includes the acknowledgement wait of the bounded log.
        const double write_ms = std::chrono::duration<double, std::milli>(
                                    std::chrono::steady_clock::now() - write_start)
                                    .count();
        std::lock_guard<std::mutex> lock(write_mutex);
        r.loop_ms.push_back(write_ms);
      }
    });
  }
  for (auto& p : producers) p.join();
  consumer.join();

  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

arena::msg::LiveState MakeLive(int cell, std::uint32_t sample, bool closed_loop) {
  arena::msg::LiveState m;
  m.cell_id("bench" + std::to_string(cell));
  m.trial_id(1);
  m.attempt(1);
  m.sample(sample);
  m.closed_loop(closed_loop);
  m.controller(closed_loop ? "bench" : "");
  auto& s = m.state();
  s.t(sample / 250.0);
  s.object_pose() = {0.001, 0, 0.01, 1, 0, 0, 0};
  s.pusher_pose() = {0, 0, -0.05, 1, 0, 0, 0};
  s.contacts().resize(3);
  s.observed_valid(true);
  s.observed_object_pose() = {0.001, 0, 0.01, 1, 0, 0, 0};
  s.observed_finger_wrenches().resize(12);
  return m;
}

// The live topic beside the reliable log (issue 19): `cells` cells sample at
// 250 Hz for `seconds`; every sample goes out on LiveState, every 25th
// sample a batch of 25 on GroundTruth. control = false: the service reads
// both (live latency, log loss). control = true: a controller participant
// answers every live sample with a PusherCommand and each cell waits for the
// answer to its sample (up to one period), as a closed-loop cell does; the
// loop time is live write -> the answer taken by the cell's thread.
Result LiveHere(int cells, double seconds, bool secure, bool control) {
  using namespace arena;
  dds::ParticipantOptions ro;
  ro.domain_id = Domain();
  ro.name = "arena.bench.service";
  ro.network.shared_memory = std::getenv("ARENA_BENCH_NO_SHM") == nullptr;
  if (secure) ro.network.security_dir = BenchLab::Get().Service();
  dds::Participant service(ro);
  dds::Reader<msg::GroundTruth> log_reader(service);
  std::unique_ptr<dds::Reader<msg::LiveState>> live_reader;
  if (!control) live_reader = std::make_unique<dds::Reader<msg::LiveState>>(service);

  std::unique_ptr<dds::Participant> ctl;
  std::unique_ptr<dds::Reader<msg::LiveState>> ctl_in;
  std::unique_ptr<dds::Writer<msg::PusherCommand>> ctl_out;
  if (control) {
    dds::ParticipantOptions o = ro;
    o.name = "arena.controller.bench";
    if (secure) o.network.security_dir = BenchLab::Get().Controller();
    ctl = std::make_unique<dds::Participant>(o);
    ctl_in = std::make_unique<dds::Reader<msg::LiveState>>(*ctl, dds::ReaderOptions{false});
    ctl_out = std::make_unique<dds::Writer<msg::PusherCommand>>(*ctl);
  }
  struct CellSide {
    std::unique_ptr<dds::Participant> participant;
    std::unique_ptr<dds::Writer<msg::GroundTruth>> log;
    std::unique_ptr<dds::Writer<msg::LiveState>> live;
    std::unique_ptr<dds::Reader<msg::PusherCommand>> commands;
  };
  std::vector<CellSide> side(static_cast<size_t>(cells));
  for (int c = 0; c < cells; ++c) {
    dds::ParticipantOptions o = ro;
    o.name = "arena.cell.bench" + std::to_string(c);
    if (secure) o.network.security_dir = BenchLab::Get().Cell(c);
    auto& cs = side[static_cast<size_t>(c)];
    cs.participant = std::make_unique<dds::Participant>(o);
    cs.log = std::make_unique<dds::Writer<msg::GroundTruth>>(*cs.participant);
    cs.live = std::make_unique<dds::Writer<msg::LiveState>>(*cs.participant);
    if (control)
      cs.commands = std::make_unique<dds::Reader<msg::PusherCommand>>(
          *cs.participant, dds::ReaderOptions{false, "bench" + std::to_string(c)});
  }
  for (auto& cs : side) {
    cs.log->WaitForMatched(1, 30s);
    cs.live->WaitForMatched(1, 30s);
    if (control) cs.commands->WaitForMatched(1, 30s);
  }
  log_reader.WaitForMatched(cells, 30s);
  if (live_reader) live_reader->WaitForMatched(cells, 30s);
  if (control) {
    ctl_in->WaitForMatched(cells, 30s);
    ctl_out->WaitForMatched(cells, 30s);
  }
  const int samples = static_cast<int>(seconds * 250);
  const int batches = samples / 25;
  Result r;
  r.expected = static_cast<std::uint64_t>(cells) * batches * 25;
  std::atomic<bool> done{false};
  std::mutex loop_mutex;
  std::thread log_consumer([&] {
    std::vector<std::uint32_t> next(static_cast<size_t>(cells), 0);
    const auto give_up =
        std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds) + 15s;
    while (r.received < r.expected && std::chrono::steady_clock::now() < give_up) {
      auto g = log_reader.Take(100ms);
      if (!g) continue;
      auto& n = next[static_cast<size_t>(g->trial_id())];
      if (g->first_sample() != n) ++r.out_of_order;
      n = g->first_sample() + static_cast<std::uint32_t>(g->samples().size());
      r.received += g->samples().size();
    }
  });
  std::thread live_consumer([&] {
    while (!done) {
      if (live_reader) {
        auto m = live_reader->Take(50ms);
        if (!m) continue;
        r.latency_ms.push_back((NowNs() - m->sent_unix_ns()) * 1e-6);
        ++r.live_received;
      } else {
        auto m = ctl_in->Take(50ms);
        if (!m) continue;
        ++r.live_received;
        msg::PusherCommand c;
        c.cell_id(m->cell_id());
        c.trial_id(m->trial_id());
        c.attempt(m->attempt());
        c.answers_sample(m->sample());
        c.controller("bench");
        c.velocity() = {0.01, 0, 0};
        c.state_sent_unix_ns(m->sent_unix_ns());
        c.sent_unix_ns(NowNs());
        ctl_out->Write(c);
      }
    }
  });
  std::atomic<std::uint64_t> live_sent{0};
  std::atomic<std::uint64_t> commands_seen{0};
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> producers;
  for (int c = 0; c < cells; ++c) {
    producers.emplace_back([&, c] {
      auto& cs = side[static_cast<size_t>(c)];
      const std::string id = "bench" + std::to_string(c);
      std::vector<double> loops;
      auto next_due = std::chrono::steady_clock::now();
      for (int b = 0; b < batches; ++b) {
        for (int k = 0; k < 25; ++k) {
          const auto sample = static_cast<std::uint32_t>(b * 25 + k);
          next_due += 4ms;
          std::this_thread::sleep_until(next_due);
          auto m = MakeLive(c, sample, control);
          m.sent_unix_ns(NowNs());
          cs.live->Write(m);
          ++live_sent;
          if (!control) continue;
          // Wait for the answer to this sample, one period at most.
          const auto until = next_due + 4ms;
          while (std::chrono::steady_clock::now() < until) {
            auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                until - std::chrono::steady_clock::now());
            auto cmd = cs.commands->Take(std::max(left, 1ms));
            if (cmd) ++commands_seen;
            if (!cmd || cmd->cell_id() != id || cmd->answers_sample() != sample) continue;
            loops.push_back((NowNs() - cmd->state_sent_unix_ns()) * 1e-6);
            break;
          }
        }
        auto g = MakeBatch(static_cast<std::uint64_t>(c), static_cast<std::uint32_t>(b), 25);
        g.sent_unix_ns(NowNs());
        while (!cs.log->Write(g)) {
        }
      }
      std::lock_guard<std::mutex> lock(loop_mutex);
      r.loop_ms.insert(r.loop_ms.end(), loops.begin(), loops.end());
    });
  }
  for (auto& p : producers) p.join();
  log_consumer.join();
  std::this_thread::sleep_for(100ms);
  done = true;
  live_consumer.join();
  r.live_sent = live_sent;
  if (control)
    std::fprintf(
        stderr,
        "control: %llu live sent, %llu taken by the controller, %llu commands taken by cells\n",
        static_cast<unsigned long long>(live_sent.load()),
        static_cast<unsigned long long>(r.live_received),
        static_cast<unsigned long long>(commands_seen.load()));
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

// StreamHere in a child process, as separate processes would run it. Fast
// DDS gives every participant of a process a new participant id (well-known
// ports), and arena's local discovery reaches ids 0..kPeerParticipantRange-1
// only: the ~140 participants of all configurations in one process would not
// find each other any more. The child writes the Result into a pipe.
Result RunInChild(const std::function<Result()>& run, bool secure) {
  if (secure) BenchLab::Get();  // made once, before any fork
  int fds[2];
  if (pipe(fds) != 0) {
    std::perror("pipe");
    std::exit(1);
  }
  const pid_t child = fork();
  if (child == 0) {
    close(fds[0]);
    const Result r = run();
    const double head[kHead] = {r.seconds,
                                static_cast<double>(r.expected),
                                static_cast<double>(r.received),
                                static_cast<double>(r.out_of_order),
                                static_cast<double>(r.live_sent),
                                static_cast<double>(r.live_received),
                                static_cast<double>(r.loop_ms.size())};
    std::string bytes(reinterpret_cast<const char*>(head), sizeof head);
    bytes.append(reinterpret_cast<const char*>(r.loop_ms.data()),
                 r.loop_ms.size() * sizeof(double));
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
  if (bytes.size() < kHead * sizeof(double)) {
    std::fprintf(stderr, "bench_dds: the streaming child failed (status %d)\n", status);
    return r;
  }
  double head[kHead];
  std::memcpy(head, bytes.data(), sizeof head);
  r.seconds = head[0];
  r.expected = static_cast<std::uint64_t>(head[1]);
  r.received = static_cast<std::uint64_t>(head[2]);
  r.out_of_order = static_cast<std::uint64_t>(head[3]);
  r.live_sent = static_cast<std::uint64_t>(head[4]);
  r.live_received = static_cast<std::uint64_t>(head[5]);
  const auto loops = static_cast<std::size_t>(head[6]);
  r.loop_ms.resize(loops);
  std::memcpy(r.loop_ms.data(), bytes.data() + sizeof head, loops * sizeof(double));
  const std::size_t rest = bytes.size() - sizeof head - loops * sizeof(double);
  r.latency_ms.resize(rest / sizeof(double));
  std::memcpy(r.latency_ms.data(), bytes.data() + sizeof head + loops * sizeof(double),
              r.latency_ms.size() * sizeof(double));
  return r;
}

Result Stream(int cells, int batches, int samples, std::chrono::microseconds period, bool secure) {
  return RunInChild([=] { return StreamHere(cells, batches, samples, period, secure); }, secure);
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
    const Result r = Stream(cells, batches, batch, std::chrono::microseconds(4000 * batch), secure);
    Report(state, r, secure);
    // Where the tail comes from: the writer blocked inside Write() (the
    // acknowledgement window of the reliable log) -- its p99 and how many
    // writes blocked more than 1 ms.
    state.counters["write_p99_ms"] = Percentile(r.loop_ms, 0.99);
    state.counters["writes_over_1ms_pct"] =
        r.loop_ms.empty()
            ? 0
            : 100.0 * std::count_if(r.loop_ms.begin(), r.loop_ms.end(), [](double ms) {
                return ms > 1.0;
              }) / r.loop_ms.size();
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

void BM_LiveState(benchmark::State& state) {
  const int cells = static_cast<int>(state.range(0));
  const bool secure = state.range(1) != 0;
  for (auto _ : state) {
    const Result r = RunInChild([=] { return LiveHere(cells, 3.0, secure, false); }, secure);
    Report(state, r, secure);
    state.counters["live_received_pct"] =
        r.live_sent > 0 ? 100.0 * static_cast<double>(r.live_received) / r.live_sent : 0;
  }
}
BENCHMARK(BM_LiveState)
    ->ArgNames({"cells", "secure"})
    ->Args({16, 0})
    ->Args({16, 1})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

void BM_ControlLoop(benchmark::State& state) {
  const int cells = static_cast<int>(state.range(0));
  const bool secure = state.range(1) != 0;
  for (auto _ : state) {
    Result r = RunInChild([=] { return LiveHere(cells, 3.0, secure, true); }, secure);
    const std::size_t answered = r.loop_ms.size();
    Report(state, r, secure);
    // p50/p99 of the loop (live sample -> command at the cell), not of the log.
    state.counters["p50_ms"] = Percentile(r.loop_ms, 0.50);
    state.counters["p99_ms"] = Percentile(r.loop_ms, 0.99);
    state.counters["max_ms"] = Percentile(r.loop_ms, 1.0);
    state.counters["answered_pct"] =
        r.live_sent > 0 ? 100.0 * static_cast<double>(answered) / r.live_sent : 0;
  }
}
BENCHMARK(BM_ControlLoop)
    ->ArgNames({"cells", "secure"})
    ->Args({16, 0})
    ->Args({16, 1})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
