// Orchestration overhead per trial (issue 5: <= 2 ms median with simulated
// cells at --speed 0) and trials/hour end to end.
//
// Each iteration runs one whole campaign: a fresh SQLite store, the smoke
// campaign with more replicates, the real Service in this process and N real
// `arena cell --speed 0` processes on a private DDS domain (UDP loopback, as
// `arena run`). The service reports, per clean trial, how long the cell was
// busy with it (claim -> RESET_DONE taken) and how long the cell itself spent
// in EXECUTE and RESET; the difference is arena's own time: store
// transactions, DDS hops, polling (orchestrator::TrialTiming).
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <benchmark/benchmark.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/service.hpp"
#include "arena/orchestrator/submit.hpp"
#include "arena/schemas/dds.hpp"

extern char** environ;

namespace {

using namespace arena;
namespace fs = std::filesystem;

// A child `arena cell` process, killed when this goes; it also stops when
// the bench dies without running this destructor (--parent-pid): a stray
// cell left on a domain would answer whoever uses that domain next.
class CellProcess {
 public:
  CellProcess(const std::string& id, int domain, const fs::path& log) {
    std::vector<std::string> args = {ARENA_BINARY,   "cell",
                                     "--id",         id,
                                     "--domain",     std::to_string(domain),
                                     "--speed",      "0",
                                     "--parent-pid", std::to_string(getpid())};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, 1, 2);
    const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) throw std::runtime_error("cannot start " + std::string(ARENA_BINARY));
  }
  ~CellProcess() {
    if (pid_ <= 0) return;
    kill(pid_, SIGTERM);
    for (int i = 0; i < 50; ++i) {  // up to 5 s, then SIGKILL
      if (waitpid(pid_, nullptr, WNOHANG) == pid_) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
  }
  // Resident memory (KiB) from /proc, 0 when unreadable.
  long RssKiB() const {
    std::ifstream status("/proc/" + std::to_string(pid_) + "/status");
    std::string line;
    while (std::getline(status, line)) {
      if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
    }
    return 0;
  }
  CellProcess(const CellProcess&) = delete;
  CellProcess& operator=(const CellProcess&) = delete;

 private:
  pid_t pid_ = -1;
};

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

std::string SmokeCampaign(int replicates) {
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/smoke.json");
  nlohmann::json spec = nlohmann::json::parse(in);
  spec["replicates"] = replicates;
  return spec.dump();
}

// A domain id no other arena process on this host holds (a test suite, an
// `arena run`, another bench): claimed host-wide for the bench's life.
int ClaimedDomain() {
  static std::optional<dds::HostDomainClaim> claim;
  const int start = static_cast<int>(getpid() % 100);
  for (int k = 0; k < 100 && !claim; ++k)
    claim = dds::HostDomainClaim::TryClaim(120 + (start + k) % 100);
  return claim ? claim->domain_id() : 120 + start;
}

// Arg 0: number of cells. 12 conditions x 10 replicates = 120 trials per campaign.
// `shared_memory`: the service's participant uses Fast DDS's shared-memory
// transport beside UDP (the cells always do); false as `arena serve` runs it.
void CampaignEndToEnd(benchmark::State& state, bool shared_memory, bool queue_next = true) {
  spdlog::set_level(spdlog::level::warn);
  const int cells = static_cast<int>(state.range(0));
  const fs::path dir = fs::temp_directory_path() / ("arena_orch_bench_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const int domain = ClaimedDomain();
  std::vector<std::unique_ptr<CellProcess>> processes;
  for (int k = 0; k < cells; ++k) {
    processes.push_back(std::make_unique<CellProcess>(
        "bench" + std::to_string(k + 1), domain, dir / ("cell" + std::to_string(k + 1) + ".log")));
  }
  const orchestrator::Campaign campaign =
      orchestrator::ParseCampaign(SmokeCampaign(10), ARENA_SOURCE_DIR "/examples/campaigns");

  std::vector<double> overhead, busy, execute, reset, service_part, wire_part;
  std::vector<double> leg_claim, leg_execute, leg_stream, leg_reset;  // TrialTiming's legs
  double trials = 0, wall = 0;
  long rss_after_first = 0;  // the first campaign warms the cell up (pools, caches)
  int run = 0;
  for (auto _ : state) {
    const fs::path db = dir / ("run" + std::to_string(run++) + ".db");
    std::int64_t id = 0;
    {
      auto store = db::Store::Open(db.string());
      id = orchestrator::SubmitCampaign(*store, campaign);
    }
    orchestrator::ServiceOptions so;
    so.db_path = db.string();
    so.domain_id = domain;
    so.exit_when_done = true;
    so.only_campaign = id;
    so.network.shared_memory = shared_memory;  // false as `arena serve`, `arena run`: UDP
    so.queue_next_execute = queue_next;
    orchestrator::Service service(so);
    service.OnTrialTiming([&](const orchestrator::TrialTiming& t) {
      overhead.push_back(t.overhead_s);
      busy.push_back(t.cell_busy_s);
      execute.push_back(t.execute_s);
      reset.push_back(t.reset_s);
      service_part.push_back(t.service_s);
      wire_part.push_back(t.overhead_s - t.service_s);
      leg_claim.push_back(t.claim_to_execute_s);
      leg_execute.push_back(t.execute_round_trip_s);
      leg_stream.push_back(t.stream_to_reset_s);
      leg_reset.push_back(t.reset_round_trip_s);
    });
    // The clock starts when the service runs: cell discovery is part of a campaign's wall time.
    const auto start = std::chrono::steady_clock::now();
    service.Run();
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const auto c = service.counters();
    trials += static_cast<double>(c.done);
    if (run == 1) rss_after_first = processes[0]->RssKiB();
    if (c.done + c.failed != static_cast<std::int64_t>(campaign.conditions * campaign.replicates)) {
      state.SkipWithError("campaign did not finish every trial");
      break;
    }
  }
  // A 24/7 cell must not grow with the trials it has run.
  const double later_trials = trials * (run - 1) / std::max(run, 1);
  const long rss_growth = processes[0]->RssKiB() - rss_after_first;
  processes.clear();
  std::error_code ec;
  fs::remove_all(dir, ec);

  state.counters["trials"] = trials;
  state.counters["trials_per_hour"] = wall > 0 ? 3600.0 * trials / wall : 0;
  state.counters["overhead_p50_ms"] = Quantile(overhead, 0.5) * 1e3;
  state.counters["overhead_p95_ms"] = Quantile(overhead, 0.95) * 1e3;
  // The mean is the cells' whole time outside their phases per trial: a
  // queued trial (issue 27) moves time between a trial and the next (the
  // head start), which spreads the quantiles but not the sum.
  double overhead_sum = 0;
  for (const double o : overhead) overhead_sum += o;
  state.counters["overhead_mean_ms"] =
      overhead.empty() ? 0 : overhead_sum / static_cast<double>(overhead.size()) * 1e3;
  // The overhead's two parts: the service's own work on the path, and the wire
  // (DDS hops, the cell outside its phases, the service loop's waits).
  state.counters["service_p50_ms"] = Quantile(service_part, 0.5) * 1e3;
  state.counters["wire_p50_ms"] = Quantile(wire_part, 0.5) * 1e3;
  // The overhead's four legs (TrialTiming), medians in microseconds: where it goes.
  state.counters["leg_claim_us"] = Quantile(leg_claim, 0.5) * 1e6;
  state.counters["leg_execute_us"] = Quantile(leg_execute, 0.5) * 1e6;
  state.counters["leg_stream_reset_us"] = Quantile(leg_stream, 0.5) * 1e6;
  state.counters["leg_reset_us"] = Quantile(leg_reset, 0.5) * 1e6;
  state.counters["busy_p50_ms"] = Quantile(busy, 0.5) * 1e3;
  state.counters["execute_p50_ms"] = Quantile(execute, 0.5) * 1e3;
  state.counters["reset_p50_ms"] = Quantile(reset, 0.5) * 1e3;
  state.counters["cell_rss_growth_kib_per_1k_trials"] =
      later_trials > 0 ? 1000.0 * static_cast<double>(rss_growth) / later_trials : 0;
}
void BM_CampaignEndToEnd(benchmark::State& state) { CampaignEndToEnd(state, false); }
BENCHMARK(BM_CampaignEndToEnd)
    ->Arg(1)
    ->Arg(2)
    ->Iterations(5)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// The same without the next trial queued behind each reset (issue 27): each
// EXECUTE claimed and sent only once the service took the cell's RESET_DONE,
// as before the queue; what the queue saves, measured in one binary.
void BM_CampaignEndToEndUnqueued(benchmark::State& state) { CampaignEndToEnd(state, false, false); }
BENCHMARK(BM_CampaignEndToEndUnqueued)
    ->Arg(1)
    ->Arg(2)
    ->Iterations(5)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// The same with the service on shared memory too (issue 27: the wire's share
// of the overhead; `arena serve` keeps it off, see cli/src/cmd_serve.cpp).
void BM_CampaignEndToEndSharedMemory(benchmark::State& state) { CampaignEndToEnd(state, true); }
BENCHMARK(BM_CampaignEndToEndSharedMemory)
    ->Arg(1)
    ->Iterations(5)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// Resident memory (KiB) of this process (the service runs in it).
long SelfRssKiB() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
  }
  return 0;
}

// A 24/7 run in one campaign (issue 27): `trials` trials on `cells` cells,
// the service's and each cell's resident memory and the overhead of the
// last 1,000 trials printed at every 1,000 done, then the growth per 1,000
// trials after the first 2,000 (warm-up: pools, caches, the store's pages).
int Soak(int trials, int cells) {
  spdlog::set_level(spdlog::level::warn);
  const fs::path dir = fs::temp_directory_path() / ("arena_orch_soak_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const int domain = 120 + getpid() % 100;
  std::vector<std::unique_ptr<CellProcess>> processes;
  for (int k = 0; k < cells; ++k) {
    processes.push_back(std::make_unique<CellProcess>(
        "soak" + std::to_string(k + 1), domain, dir / ("cell" + std::to_string(k + 1) + ".log")));
  }
  nlohmann::json spec = nlohmann::json::parse(SmokeCampaign(1));
  const int conditions = 12;  // smoke.json's
  spec["replicates"] = (trials + conditions - 1) / conditions;
  const orchestrator::Campaign campaign =
      orchestrator::ParseCampaign(spec.dump(), ARENA_SOURCE_DIR "/examples/campaigns");
  const fs::path db = dir / "soak.db";
  std::int64_t id = 0;
  {
    auto store = db::Store::Open(db.string());
    id = orchestrator::SubmitCampaign(*store, campaign);
  }
  orchestrator::ServiceOptions so;
  so.db_path = db.string();
  so.domain_id = domain;
  so.exit_when_done = true;
  so.only_campaign = id;
  so.network.shared_memory = false;
  orchestrator::Service service(so);
  std::vector<double> overhead;
  service.OnTrialTiming(
      [&](const orchestrator::TrialTiming& t) { overhead.push_back(t.overhead_s); });
  struct Row {
    std::int64_t done;
    double wall_s;
    long service_kib;
    std::vector<long> cell_kib;
    double p50_ms, p95_ms;
  };
  std::vector<Row> rows;
  const auto start = std::chrono::steady_clock::now();
  std::size_t timed = 0;
  service.OnTick([&](const orchestrator::ServiceCounters& c) {
    if (c.done < static_cast<std::int64_t>(rows.size() + 1) * 1000) return;
    Row r{c.done,
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
          SelfRssKiB(),
          {},
          0,
          0};
    for (const auto& p : processes) r.cell_kib.push_back(p->RssKiB());
    std::vector<double> last(overhead.begin() + static_cast<std::ptrdiff_t>(timed), overhead.end());
    timed = overhead.size();
    r.p50_ms = Quantile(last, 0.5) * 1e3;
    r.p95_ms = Quantile(last, 0.95) * 1e3;
    rows.push_back(std::move(r));
  });
  service.Run();
  const auto c = service.counters();
  std::printf("| trials done | wall s | overhead p50 ms | overhead p95 ms | service RSS MiB |");
  for (int k = 0; k < cells; ++k) std::printf(" cell %d RSS MiB |", k + 1);
  std::printf("\n|---|---|---|---|---|");
  for (int k = 0; k < cells; ++k) std::printf("---|");
  std::printf("\n");
  for (const auto& r : rows) {
    std::printf("| %lld | %.0f | %.2f | %.1f | %.1f |", static_cast<long long>(r.done), r.wall_s,
                r.p50_ms, r.p95_ms, r.service_kib / 1024.0);
    for (long k : r.cell_kib) std::printf(" %.1f |", k / 1024.0);
    std::printf("\n");
  }
  std::printf("\n%lld done, %lld failed of %d planned\n", static_cast<long long>(c.done),
              static_cast<long long>(c.failed), conditions * spec["replicates"].get<int>());
  // Growth after warm-up: from the row at 2,000 to the last.
  if (rows.size() >= 3) {
    const Row& a = rows[1];
    const Row& b = rows.back();
    const double per_k = 1000.0 / static_cast<double>(b.done - a.done);
    std::printf("growth per 1,000 trials after %lld: service %.3f MiB",
                static_cast<long long>(a.done), (b.service_kib - a.service_kib) / 1024.0 * per_k);
    for (std::size_t k = 0; k < b.cell_kib.size(); ++k)
      std::printf(", cell %zu %.3f MiB", k + 1, (b.cell_kib[k] - a.cell_kib[k]) / 1024.0 * per_k);
    std::printf("\n");
  }
  processes.clear();
  std::error_code ec;
  fs::remove_all(dir, ec);
  return c.done + c.failed == conditions * spec["replicates"].get<int>() ? 0 : 1;
}

}  // namespace

// `--soak_trials=N [--soak_cells=K]`: the 24/7 memory run (Soak) instead of
// the timers; every other flag goes to Google Benchmark.
int main(int argc, char** argv) {
  int soak_trials = 0, soak_cells = 1;
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i];
    try {
      if (a.rfind("--soak_trials=", 0) == 0) {
        soak_trials = std::stoi(a.substr(14));
        continue;
      }
      if (a.rfind("--soak_cells=", 0) == 0) {
        soak_cells = std::stoi(a.substr(13));
        continue;
      }
    } catch (const std::exception&) {
      std::fprintf(stderr, "%s: must be a whole number\n", a.c_str());
      return 2;
    }
    { rest.push_back(argv[i]); }
  }
  if (soak_trials > 0) {
    if (soak_cells < 1 || soak_cells > 16) {
      std::fprintf(stderr, "--soak_cells: must be 1..16, got %d\n", soak_cells);
      return 2;
    }
    return Soak(soak_trials, soak_cells);
  }
  int n = static_cast<int>(rest.size());
  benchmark::Initialize(&n, rest.data());
  if (benchmark::ReportUnrecognizedArguments(n, rest.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
