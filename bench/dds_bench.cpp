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
//   BM_LiveState, BM_ControlLoop  the live topic and the closed loop
//                                 (issue 19); cell_processes:1 runs every
//                                 cell as a process of its own (as `arena
//                                 cell`s are), 0 as threads of one process.
//                                 Secured rows start once every participant
//                                 authenticated every other (warm-up).
// Target (issue 4): 16 cells x 250 Hz, zero loss, p99 < 5 ms.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <benchmark/benchmark.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "arena/executors/controller.hpp"
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

// A domain id no other arena process on this host holds (a test suite, an
// `arena run`, another bench): claimed host-wide for the bench's life.
int ClaimedDomain() {
  static std::optional<arena::dds::HostDomainClaim> claim;
  const int start = static_cast<int>(getpid() % 30);
  for (int k = 0; k < 30 && !claim; ++k)
    claim = arena::dds::HostDomainClaim::TryClaim(201 + (start + k) % 30);
  return claim ? claim->domain_id() : 201 + start;
}

int Domain() { return ClaimedDomain(); }

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
  // A controller's identity is issued for its name (the host's "bench").
  std::string Controller() const { return dir_ + "/bench"; }
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
    o.name = "bench";
    arena::dds::IssueIdentity(dir_, o);
  }
  std::string dir_;
};

// Every bench participant's options, once: the domain, shared memory unless
// ARENA_BENCH_NO_SHM is set (as the lab runs it), and an identity directory
// ("" = an open domain).
arena::dds::NetworkOptions BenchNetwork(const std::string& identity) {
  arena::dds::NetworkOptions n;
  n.shared_memory = std::getenv("ARENA_BENCH_NO_SHM") == nullptr;
  n.security_dir = identity;
  return n;
}
arena::dds::ParticipantOptions BenchParticipant(int domain, std::string name,
                                                const std::string& identity) {
  arena::dds::ParticipantOptions o;
  o.domain_id = domain;
  o.name = std::move(name);
  o.network = BenchNetwork(identity);
  return o;
}

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
  std::map<std::string, double> extra;  // further counters, reported as they are
};
constexpr int kHead = 7;  // doubles before the vectors in the child's pipe

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * (v.size() - 1))];
}

// The warm-up of every secured row: waits (at most 60 s) until each of
// `parts` has authenticated `expected` peers, so that no PKI-DH handshake
// (ECDSA, ECDH, signed permissions: 2 * 136 at 16 cells) still runs beside
// the measurement. The service's matches alone do not say that: the cells
// authenticate each other too, and did so into the first second of the
// live row (bench/README.md, 2026-11-24). @returns the seconds waited.
double WaitForHandshakes(const std::vector<arena::dds::Participant*>& parts, int expected) {
  const auto start = std::chrono::steady_clock::now();
  const auto deadline = start + 60s;
  for (auto* p : parts) {
    const auto left = deadline - std::chrono::steady_clock::now();
    if (!p->WaitForAuthenticated(expected,
                                 std::chrono::duration_cast<arena::dds::Millis>(
                                     std::max<std::chrono::steady_clock::duration>(left, 0s)))) {
      std::fprintf(stderr, "bench_dds: %s authenticated %d of %d peers after 60 s\n",
                   p->name().c_str(), p->AuthenticatedPeers(), expected);
    }
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Where in the run the tail lies: p99 of the samples sent in each 0.5 s
// window (stderr), from (sent ns, latency ms) pairs.
void PrintTailOverTime(const char* what, std::vector<std::pair<std::uint64_t, double>> trace) {
  if (trace.empty()) return;
  // For `perf record -k CLOCK_MONOTONIC` + `perf report --time`: the
  // measurement's end on that clock (its start: the end minus the run).
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  std::fprintf(stderr, "%s ends at monotonic %ld.%06ld (system %llu ns)\n", what,
               static_cast<long>(now.tv_sec), now.tv_nsec / 1000,
               static_cast<unsigned long long>(NowNs()));
  std::sort(trace.begin(), trace.end());
  const std::uint64_t t0 = trace.front().first;
  std::fprintf(stderr, "%s p99 per 0.5 s:", what);
  std::vector<double> window;
  std::uint64_t end = t0 + 500'000'000;
  for (std::size_t i = 0; i <= trace.size(); ++i) {
    if (i == trace.size() || trace[i].first >= end) {
      std::fprintf(stderr, " %.2f(n=%zu)", Percentile(window, 0.99), window.size());
      window.clear();
      end += 500'000'000;
      if (i == trace.size()) break;
    }
    window.push_back(trace[i].second);
  }
  std::fprintf(stderr, "\n");
}

// `cells` writer participants (fresh for every configuration) each send
// `batches` batches of `samples` samples, one every `period` (0 = flat out).
// secure: every participant with its lab identity (BenchLab).
Result StreamHere(int cells, int batches, int samples, std::chrono::microseconds period,
                  bool secure) {
  const arena::dds::ParticipantOptions ro =
      BenchParticipant(Domain(), "arena.bench.service", secure ? BenchLab::Get().Service() : "");
  arena::dds::Participant service(ro);
  arena::dds::Reader<arena::msg::GroundTruth> reader(service);
  std::vector<std::unique_ptr<arena::dds::Participant>> parts;
  std::vector<std::unique_ptr<arena::dds::Writer<arena::msg::GroundTruth>>> writers;
  for (int c = 0; c < cells; ++c) {
    const arena::dds::ParticipantOptions o =
        BenchParticipant(ro.domain_id, "arena.cell.bench" + std::to_string(c),
                         secure ? BenchLab::Get().Cell(c) : "");
    parts.push_back(std::make_unique<arena::dds::Participant>(o));
    writers.push_back(std::make_unique<arena::dds::Writer<arena::msg::GroundTruth>>(*parts.back()));
  }
  // Secure: every pair of participants authenticates first (PKI-DH).
  for (auto& w : writers) w->WaitForMatched(1, 30s);
  reader.WaitForMatched(cells, 30s);
  std::vector<arena::dds::Participant*> all{&service};
  for (auto& p : parts) all.push_back(p.get());
  WaitForHandshakes(all, secure ? cells : 0);
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
  s.object_pose() = {0.001 * cell, 0, 0.01, 1, 0, 0, 0};  // x: the cell (ControlHere's trace)
  s.pusher_pose() = {0, 0, -0.05, 1, 0, 0, 0};
  s.contacts().resize(3);
  s.observed_valid(true);
  s.observed_object_pose() = {0.001, 0, 0.01, 1, 0, 0, 0};
  s.observed_finger_wrenches().resize(12);
  return m;
}

// The service's side of the log: takes every batch, counts samples and
// batches out of order.
void ConsumeLog(arena::dds::Reader<arena::msg::GroundTruth>& reader, int cells, double seconds,
                Result* r) {
  std::vector<std::uint32_t> next(static_cast<size_t>(cells), 0);
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds) + 15s;
  while (r->received < r->expected && std::chrono::steady_clock::now() < give_up) {
    auto g = reader.Take(100ms);
    if (!g) continue;
    auto& n = next[static_cast<size_t>(g->trial_id())];
    if (g->first_sample() != n) ++r->out_of_order;
    n = g->first_sample() + static_cast<std::uint32_t>(g->samples().size());
    r->received += g->samples().size();
  }
}

void WriteBatch(arena::dds::Writer<arena::msg::GroundTruth>& log, int cell, int index) {
  auto g = MakeBatch(static_cast<std::uint64_t>(cell), static_cast<std::uint32_t>(index), 25);
  g.sent_unix_ns(NowNs());
  while (!log.Write(g)) {
  }
}

// Memory shared with the cells when they run as processes of their own
// (mapped before fork; zeroed). Freed at the end of the configuration's
// child process.
template <class T>
T* SharedArray(std::size_t n) {
  void* p = mmap(nullptr, sizeof(T) * n, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) {
    std::perror("mmap");
    std::exit(1);
  }
  return new (p) T[n]();
}

// What the live and loop rows' cells and their service side share: the
// start signal, each cell's handshakes, and per sample the loop's trace.
struct CellSync {
  std::atomic<int> matched[kMaxCells];
  std::atomic<int> authenticated[kMaxCells];
  std::atomic<std::int64_t> start_ns;  // steady_clock; 0 = not yet
  std::atomic<int> finished;
  std::atomic<bool> quit;
  std::atomic<std::uint64_t> live_sent;
  // Loop rows: the cells' command readers and, as processes, their CPU.
  std::atomic<std::uint64_t> cmd_other_cell, cmd_superseded, cmd_lost;
  std::atomic<std::uint64_t> cpu_us, ctx_switches;
};

// One cell of the live and loop rows (a thread of the configuration's
// process, or a process of its own: cell_processes).
struct CellPlan {
  int cells = 16;
  int domain = 0;
  bool secure = false;
  bool closed_loop = false;  // the loop rows: waits for each command
  bool cell_filter = true;   // loop: PusherCommand through the DDS cell filter
  bool spread = false;       // loop: cell c's clock c/cells of a period late
  int batches = 30;          // of 25 samples
  std::string controller_params;
  // Loop trace, [cell * samples + sample], ns (0 = never).
  std::uint64_t* sent = nullptr;
  std::uint64_t* taken = nullptr;
  char* in_time = nullptr;
};

std::chrono::steady_clock::time_point SteadyFromNs(std::int64_t ns) {
  return std::chrono::steady_clock::time_point(std::chrono::nanoseconds(ns));
}

double CpuSeconds(const rusage& u) {
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + (u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

void RunCell(int c, const CellPlan& plan, CellSync* sync, bool own_process) {
  using namespace arena;
  const dds::ParticipantOptions o =
      BenchParticipant(plan.domain, "arena.cell.bench" + std::to_string(c),
                       plan.secure ? BenchLab::Get().Cell(c) : "");
  dds::Participant participant(o);
  dds::Writer<msg::GroundTruth> log(participant);
  dds::Writer<msg::LiveState> live(participant);
  std::unique_ptr<dds::Reader<msg::PusherCommand>> commands;
  const std::string id = "bench" + std::to_string(c);
  if (plan.closed_loop) {
    dds::ReaderOptions ro_cmd{false, id};
    ro_cmd.cell_filter_in_dds = plan.cell_filter;
    ro_cmd.controller = "bench";  // the controller's own topic, as a cell reads it
    commands = std::make_unique<dds::Reader<msg::PusherCommand>>(participant, ro_cmd);
  }
  log.WaitForMatched(1, 30s);
  live.WaitForMatched(1, 30s);
  if (commands) commands->WaitForMatched(1, 30s);
  sync->matched[c] = 1;
  const auto give_up = std::chrono::steady_clock::now() + 120s;
  while (sync->start_ns == 0 && !sync->quit && std::chrono::steady_clock::now() < give_up) {
    sync->authenticated[c] = participant.AuthenticatedPeers();
    std::this_thread::sleep_for(2ms);
  }
  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  const auto samples = static_cast<std::size_t>(plan.batches) * 25;
  auto next_due = SteadyFromNs(sync->start_ns) +
                  (plan.spread ? std::chrono::microseconds(4000 * c / plan.cells) : 0us);
  for (int b = 0; b < plan.batches && sync->start_ns != 0; ++b) {
    for (int k = 0; k < 25; ++k) {
      const auto sample = static_cast<std::uint32_t>(b * 25 + k);
      next_due += 4ms;
      std::this_thread::sleep_until(next_due);
      auto m = MakeLive(c, sample, plan.closed_loop);
      if (plan.closed_loop) m.controller_params(plan.controller_params);
      m.sent_unix_ns(NowNs());
      live.Write(m);
      ++sync->live_sent;
      if (!plan.closed_loop) continue;
      const std::size_t at = static_cast<std::size_t>(c) * samples;
      plan.sent[at + sample] = m.sent_unix_ns();
      // The answer to this sample, until the next sample is due; an older
      // sample's late answer is recorded as late.
      const auto until = next_due + 4ms;
      for (auto now = std::chrono::steady_clock::now(); now < until;
           now = std::chrono::steady_clock::now()) {
        auto cmd = commands->Take(until - now);
        if (!cmd || cmd->cell_id() != id || cmd->answers_sample() > sample) continue;
        auto& t = plan.taken[at + cmd->answers_sample()];
        if (t == 0) t = NowNs();
        if (cmd->answers_sample() == sample) {
          plan.in_time[at + sample] = 1;
          break;
        }
      }
    }
    WriteBatch(log, c, b);
  }
  sync->authenticated[c] = participant.AuthenticatedPeers();
  if (own_process) {  // the configuration's process counts its own threads
    rusage after{};
    getrusage(RUSAGE_SELF, &after);
    sync->cpu_us += static_cast<std::uint64_t>((CpuSeconds(after) - CpuSeconds(before)) * 1e6);
    sync->ctx_switches += static_cast<std::uint64_t>(after.ru_nvcsw + after.ru_nivcsw -
                                                     before.ru_nvcsw - before.ru_nivcsw);
  }
  if (commands) {
    const auto k = commands->counters();
    sync->cmd_other_cell += k.other_cell;
    sync->cmd_superseded += k.superseded;
    sync->cmd_lost += k.lost;
  }
  ++sync->finished;
  // Stay on the domain until every cell is done: a participant that leaves
  // sets off discovery work in all the others.
  while (!sync->quit && std::chrono::steady_clock::now() < give_up + 60s)
    std::this_thread::sleep_for(5ms);
}

// The cells of a live or loop row: threads of this process, or (as `arena
// cell`s are) one process each, forked before this process touches DDS.
// Fast DDS and OpenSSL keep process-wide state (OpenSSL 3.0 takes global
// write locks on every EVP_PKEY and RAND_bytes call), so 16 cells in one
// process contend where 16 processes do not (bench/README.md, 2026-11-24).
class Cells {
 public:
  Cells(const CellPlan& plan, CellSync* sync, bool processes) : plan_(plan), sync_(sync) {
    for (int c = 0; c < plan.cells; ++c) {
      if (!processes) {
        threads_.emplace_back([this, c] { RunCell(c, plan_, sync_, false); });
        continue;
      }
      const pid_t pid = fork();
      if (pid == 0) {
        RunCell(c, plan_, sync_, true);
        _exit(0);
      }
      if (pid < 0) {
        std::perror("fork");
        std::exit(1);
      }
      pids_.push_back(pid);
    }
  }
  // Waits (bounded) until every cell matched its readers and authenticated
  // `peers` participants, and the service side's own participants did too;
  // then starts every cell's clock 50 ms later. @returns seconds waited.
  double WaitAndStart(const std::vector<arena::dds::Participant*>& here, int peers) {
    const auto start = std::chrono::steady_clock::now();
    const auto deadline = start + 60s;
    auto ready = [&] {
      for (int c = 0; c < plan_.cells; ++c)
        if (sync_->matched[c] == 0 || sync_->authenticated[c] < peers) return false;
      for (auto* p : here)
        if (p->AuthenticatedPeers() < peers) return false;
      return true;
    };
    while (!ready() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(5ms);
    if (!ready()) std::fprintf(stderr, "bench_dds: cells not ready after 60 s, starting anyway\n");
    const double waited =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    start_ = std::chrono::steady_clock::now() + 50ms;
    sync_->start_ns =
        std::chrono::duration_cast<std::chrono::nanoseconds>(start_.time_since_epoch()).count();
    return waited;
  }
  std::chrono::steady_clock::time_point start() const { return start_; }
  // Handshakes still missing, counted on every participant's side.
  int MissingHandshakes(const std::vector<arena::dds::Participant*>& here, int peers) const {
    int missing = 0;
    for (int c = 0; c < plan_.cells; ++c) missing += std::max(0, peers - sync_->authenticated[c]);
    for (auto* p : here) missing += std::max(0, peers - p->AuthenticatedPeers());
    return missing;
  }
  void WaitFinished(std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (sync_->finished < plan_.cells && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(2ms);
  }
  ~Cells() {
    sync_->quit = true;
    for (auto& t : threads_) t.join();
    for (pid_t pid : pids_) {
      int status = 0;
      waitpid(pid, &status, 0);
    }
  }

 private:
  const CellPlan plan_;
  CellSync* sync_;
  std::vector<std::thread> threads_;
  std::vector<pid_t> pids_;
  std::chrono::steady_clock::time_point start_{};
};

// The live topic beside the reliable log (issue 19): `cells` cells sample at
// 250 Hz for `seconds`; every sample goes out on LiveState, every 25th
// sample a batch of 25 on GroundTruth; the service reads both (live latency,
// log loss). Measured after every handshake of the domain is done (warm-up).
Result LiveHere(int cells, double seconds, bool secure, bool cell_processes) {
  using namespace arena;
  CellPlan plan;
  plan.cells = cells;
  plan.domain = Domain();
  plan.secure = secure;
  plan.batches = static_cast<int>(seconds * 250) / 25;
  if (secure) BenchLab::Get();
  auto* sync = SharedArray<CellSync>(1);
  Cells cell_side(plan, sync, cell_processes);  // forks first: no DDS here yet

  const dds::ParticipantOptions ro =
      BenchParticipant(plan.domain, "arena.bench.service", secure ? BenchLab::Get().Service() : "");
  dds::Participant service(ro);
  dds::Reader<msg::GroundTruth> log_reader(service);
  dds::Reader<msg::LiveState> live_reader(service);
  log_reader.WaitForMatched(cells, 30s);
  live_reader.WaitForMatched(cells, 30s);
  const int peers = secure ? cells : 0;
  Result r;
  r.expected = static_cast<std::uint64_t>(cells) * plan.batches * 25;
  std::atomic<bool> done{false};
  std::vector<std::pair<std::uint64_t, double>> trace;
  const bool print_trace = std::getenv("ARENA_BENCH_TRACE") != nullptr;
  r.extra["warmup_s"] = cell_side.WaitAndStart({&service}, peers);
  r.extra["handshakes_missing_at_start"] = cell_side.MissingHandshakes({&service}, peers);
  std::thread log_consumer([&] { ConsumeLog(log_reader, cells, seconds + 0.1, &r); });
  std::thread live_consumer([&] {
    while (!done) {
      auto m = live_reader.Take(50ms);
      if (!m) continue;
      const double ms = (NowNs() - m->sent_unix_ns()) * 1e-6;
      r.latency_ms.push_back(ms);
      trace.emplace_back(m->sent_unix_ns(), ms);
      if (print_trace)
        std::fprintf(stderr, "T %s %u %llu %.3f\n", m->cell_id().c_str(), m->sample(),
                     static_cast<unsigned long long>(m->sent_unix_ns()), ms);
      ++r.live_received;
    }
  });
  cell_side.WaitFinished(std::chrono::seconds(static_cast<int>(seconds) + 30));
  r.extra["handshakes_missing_at_end"] = cell_side.MissingHandshakes({&service}, peers);
  log_consumer.join();
  std::this_thread::sleep_for(100ms);
  done = true;
  live_consumer.join();
  r.live_sent = sync->live_sent;
  const auto counters = live_reader.counters();
  r.extra["live_superseded"] = static_cast<double>(counters.superseded);
  r.extra["live_lost"] = static_cast<double>(counters.lost);
  PrintTailOverTime(secure ? "live (secure)" : "live (open)", std::move(trace));
  r.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - cell_side.start()).count();
  return r;
}

// The control loop (issue 19), with arena's own controller host
// (executors::RunController, as `arena controller` runs it) answering every
// live sample of `cells` cells at 250 Hz; each cell waits for the answer to
// its sample until its next sample is due (one period), as a wall-clock
// closed-loop cell does, and writes the log beside it. Every sample is
// traced through the stages: cell writes the live sample -> the controller's
// law sees it -> the cell takes the command answering it. cell_filter: the
// cells read PusherCommand through the DDS content filter on their cell id
// (writer-side: a command crosses to its cell only); false: the listener
// alone drops other cells' commands (every command crosses to every cell, as
// before the filter).
// spread: cell c samples at c/cells of a period after cell 0, as cells
// started independently do (on average); otherwise all cells sample on the
// same tick, the worst case for the one controller answering them.
// cell_processes: every cell a process of its own (as `arena cell`s are);
// the controller and the service's log reader share this one.
Result ControlHere(int cells, double seconds, bool secure, bool cell_filter, bool spread,
                   bool cell_processes) {
  using namespace arena;
  CellPlan plan;
  plan.cells = cells;
  plan.domain = Domain();
  plan.secure = secure;
  plan.closed_loop = true;
  plan.cell_filter = cell_filter;
  plan.spread = spread;
  plan.batches = static_cast<int>(seconds * 250) / 25;
  const auto n = static_cast<std::size_t>(plan.batches) * 25;
  const std::size_t all_samples = static_cast<std::size_t>(cells) * n;
  plan.sent = SharedArray<std::uint64_t>(all_samples);
  plan.taken = SharedArray<std::uint64_t>(all_samples);
  plan.in_time = SharedArray<char>(all_samples);
  // When the law saw each sample (this process), [cell][sample] ns.
  std::vector<std::vector<std::uint64_t>> law(cells, std::vector<std::uint64_t>(n, 0));
  executors::ControlContext context;
  context.spec.name = "bench";
  plan.controller_params = executors::ControlContextToJson(context);
  if (secure) BenchLab::Get();
  auto* sync = SharedArray<CellSync>(1);
  Cells cell_side(plan, sync, cell_processes);  // forks first: no DDS here yet

  // The law records when it saw a sample (the cell is encoded in the
  // object's x, MakeLive) and commands a constant push.
  class TracedLaw : public executors::Controller {
   public:
    explicit TracedLaw(std::vector<std::vector<std::uint64_t>>* law) : law_(law) {}
    mechanics::PusherMotion Command(const executors::ControlInput& in) override {
      const auto cell = static_cast<size_t>(std::lround(in.truth.position.x() * 1000));
      if (cell < law_->size() && in.sample < (*law_)[cell].size())
        (*law_)[cell][in.sample] = NowNs();
      mechanics::PusherMotion m;
      m.velocity = {0.01, 0, 0};
      return m;
    }

   private:
    std::vector<std::vector<std::uint64_t>>* law_;
  };
  executors::ControllerHostOptions host;
  host.name = "bench";
  host.domain_id = plan.domain;
  host.network = BenchNetwork(secure ? BenchLab::Get().Controller() : "");
  std::atomic<bool> stop_controller{false};
  executors::ControllerCounters controller_counters;
  std::thread controller([&] {
    controller_counters = executors::RunController(
        host, [&](const executors::ControlContext&) { return std::make_unique<TracedLaw>(&law); },
        &stop_controller);
  });

  const dds::ParticipantOptions ro =
      BenchParticipant(plan.domain, "arena.bench.service", secure ? BenchLab::Get().Service() : "");
  dds::Participant service(ro);
  dds::Reader<msg::GroundTruth> log_reader(service);
  log_reader.WaitForMatched(cells, 30s);
  const int peers = secure ? cells + 1 : 0;  // the others and the controller

  Result r;
  r.expected = static_cast<std::uint64_t>(cells) * plan.batches * 25;
  r.extra["warmup_s"] = cell_side.WaitAndStart({&service}, peers);
  r.extra["handshakes_missing_at_start"] = cell_side.MissingHandshakes({&service}, peers);
  std::thread log_consumer([&] { ConsumeLog(log_reader, cells, seconds + 0.1, &r); });
  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  cell_side.WaitFinished(std::chrono::seconds(static_cast<int>(seconds) + 30));
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - cell_side.start()).count();
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  r.extra["handshakes_missing_at_end"] = cell_side.MissingHandshakes({&service}, peers);
  log_consumer.join();
  stop_controller = true;
  controller.join();
  r.seconds = wall;

  // The loop, its stages and what was lost where.
  std::uint64_t answered = 0, late = 0, at_law = 0;
  std::vector<double> all_ms;  // every sample: its loop time, +inf when never answered in time
  std::vector<double> in_ms, out_ms;
  std::vector<std::pair<std::uint64_t, double>> trace;
  for (int c = 0; c < cells; ++c) {
    for (size_t k = 0; k < n; ++k) {
      const std::size_t at = static_cast<std::size_t>(c) * n + k;
      const std::uint64_t sent = plan.sent[at], taken = plan.taken[at];
      if (sent == 0) continue;
      ++r.live_sent;
      if (law[c][k] != 0) ++at_law;
      if (plan.in_time[at]) {
        ++answered;
        const double ms = (taken - sent) * 1e-6;
        r.loop_ms.push_back(ms);
        all_ms.push_back(ms);
        trace.emplace_back(sent, ms);
        if (law[c][k] != 0) {
          in_ms.push_back((law[c][k] - sent) * 1e-6);
          out_ms.push_back((taken - law[c][k]) * 1e-6);
        }
      } else {
        all_ms.push_back(std::numeric_limits<double>::infinity());
        trace.emplace_back(sent, std::numeric_limits<double>::infinity());
        if (taken != 0) ++late;
      }
    }
  }
  PrintTailOverTime(secure ? "loop (secure)" : "loop (open)", std::move(trace));
  r.live_received = at_law;
  r.extra["answered"] = static_cast<double>(answered);
  r.extra["late"] = static_cast<double>(late);
  r.extra["p99_all_ms"] = Percentile(all_ms, 0.99);
  r.extra["stage_in_p50_ms"] = Percentile(in_ms, 0.50);
  r.extra["stage_in_p99_ms"] = Percentile(in_ms, 0.99);
  r.extra["stage_out_p50_ms"] = Percentile(out_ms, 0.50);
  r.extra["stage_out_p99_ms"] = Percentile(out_ms, 0.99);
  r.extra["ctl_superseded"] = static_cast<double>(controller_counters.live.superseded);
  r.extra["ctl_lost"] = static_cast<double>(controller_counters.live.lost);
  r.extra["cmd_other_cell"] = static_cast<double>(sync->cmd_other_cell);
  r.extra["cmd_superseded"] = static_cast<double>(sync->cmd_superseded);
  // CPU of this process over the run, plus the cells' own when they are
  // processes (their threads are this process's otherwise).
  r.extra["cpu_cores"] =
      (CpuSeconds(after) - CpuSeconds(before) + sync->cpu_us * 1e-6) / std::max(wall, 1e-9);
  r.extra["ctx_switches_per_sample"] =
      static_cast<double>(after.ru_nvcsw + after.ru_nivcsw - before.ru_nvcsw - before.ru_nivcsw +
                          sync->ctx_switches) /
      std::max<std::uint64_t>(1, r.live_sent);
  std::fprintf(stderr,
               "control (%s, %s, cells as %s): %llu live sent, %llu seen by the law, %llu "
               "answered within the period, %llu late; controller's reader: %llu superseded, %llu "
               "lost; cells' readers: %llu commands for other cells, %llu superseded, %llu "
               "sequence gaps (other cells' commands the writer filtered out count here)\n",
               secure ? "secure" : "open", cell_filter ? "DDS cell filter" : "listener filter",
               cell_processes ? "processes" : "threads",
               static_cast<unsigned long long>(r.live_sent),
               static_cast<unsigned long long>(at_law), static_cast<unsigned long long>(answered),
               static_cast<unsigned long long>(late),
               static_cast<unsigned long long>(controller_counters.live.superseded),
               static_cast<unsigned long long>(controller_counters.live.lost),
               static_cast<unsigned long long>(sync->cmd_other_cell.load()),
               static_cast<unsigned long long>(sync->cmd_superseded.load()),
               static_cast<unsigned long long>(sync->cmd_lost.load()));
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
    // Then the extra counters, "name=value\n" each, after a NUL.
    bytes.push_back('\0');
    for (const auto& [name, value] : r.extra) {
      char number[64];
      std::snprintf(number, sizeof number, "%.9g", value);
      bytes += name + "=" + number + "\n";
    }
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
  const std::size_t text = bytes.rfind('\0');  // the extra counters follow it
  for (std::size_t at = text + 1; at < bytes.size();) {
    const std::size_t eol = bytes.find('\n', at);
    const std::string line = bytes.substr(at, eol - at);
    const std::size_t eq = line.find('=');
    if (eq != std::string::npos)
      r.extra[line.substr(0, eq)] = std::strtod(line.c_str() + eq + 1, nullptr);
    if (eol == std::string::npos) break;
    at = eol + 1;
  }
  const std::size_t rest = text - sizeof head - loops * sizeof(double);
  r.latency_ms.resize(rest / sizeof(double));
  std::memcpy(r.latency_ms.data(), bytes.data() + sizeof head + loops * sizeof(double),
              r.latency_ms.size() * sizeof(double));
  return r;
}

Result Stream(int cells, int batches, int samples, std::chrono::microseconds period, bool secure) {
  return RunInChild([=] { return StreamHere(cells, batches, samples, period, secure); }, secure);
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
    const bool processes = state.range(2) != 0;
    const Result r = RunInChild([=] { return LiveHere(cells, 3.0, secure, processes); }, secure);
    Report(state, r, secure);
    state.counters["live_received_pct"] =
        r.live_sent > 0 ? 100.0 * static_cast<double>(r.live_received) / r.live_sent : 0;
    for (const auto& [name, value] : r.extra) state.counters[name] = value;
  }
}
BENCHMARK(BM_LiveState)
    ->ArgNames({"cells", "secure", "cell_processes"})
    ->Args({16, 0, 1})
    ->Args({16, 1, 1})
    ->Args({16, 0, 0})
    ->Args({16, 1, 0})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// p50/p99/max: the loop (live sample written -> the command answering it
// taken by the cell) over the samples answered within their period;
// answered_pct: those samples' share of all samples sent (the rest were never
// answered or answered late: `late`); p99_all_ms: the p99 over all samples
// with an unanswered one counted as infinitely late (inf: more than 1 % were
// not answered in time). stage_in: live sample written -> the controller's
// law saw it (delivery + the controller's queue); stage_out: law -> the cell
// took the command (encode, send, delivery, the cell's wake-up). lost = the
// reliable log's loss beside the loop. phase_spread: the cells' 250 Hz clocks
// offset by 1/16 period each (0: all on the same tick, the worst case).
void BM_ControlLoop(benchmark::State& state) {
  const int cells = static_cast<int>(state.range(0));
  const bool secure = state.range(1) != 0;
  const bool cell_filter = state.range(2) != 0;
  const bool spread = state.range(3) != 0;
  const bool processes = state.range(4) != 0;
  for (auto _ : state) {
    Result r = RunInChild(
        [=] { return ControlHere(cells, 3.0, secure, cell_filter, spread, processes); }, secure);
    Report(state, r, secure);
    state.counters["p50_ms"] = Percentile(r.loop_ms, 0.50);
    state.counters["p99_ms"] = Percentile(r.loop_ms, 0.99);
    state.counters["max_ms"] = Percentile(r.loop_ms, 1.0);
    state.counters["answered_pct"] =
        r.live_sent > 0 ? 100.0 * static_cast<double>(r.loop_ms.size()) / r.live_sent : 0;
    state.counters["law_saw_pct"] =
        r.live_sent > 0 ? 100.0 * static_cast<double>(r.live_received) / r.live_sent : 0;
    for (const auto& [name, value] : r.extra) state.counters[name] = value;
  }
}
BENCHMARK(BM_ControlLoop)
    ->ArgNames({"cells", "secure", "cell_filter", "phase_spread", "cell_processes"})
    ->Args({16, 0, 0, 0, 1})
    ->Args({16, 0, 1, 0, 1})
    ->Args({16, 0, 1, 1, 1})
    ->Args({16, 1, 0, 0, 1})
    ->Args({16, 1, 1, 0, 1})
    ->Args({16, 1, 1, 1, 1})
    ->Args({16, 0, 1, 0, 0})
    ->Args({16, 1, 1, 0, 0})
    ->Args({16, 1, 1, 1, 0})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
