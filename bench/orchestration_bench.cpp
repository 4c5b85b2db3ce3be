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

extern char** environ;

namespace {

using namespace arena;
namespace fs = std::filesystem;

// A child `arena cell` process, killed when this goes.
class CellProcess {
 public:
  CellProcess(const std::string& id, int domain, const fs::path& log) {
    std::vector<std::string> args = {ARENA_BINARY,           "cell",    "--id", id, "--domain",
                                     std::to_string(domain), "--speed", "0"};
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

// Arg 0: number of cells. 12 conditions x 10 replicates = 120 trials per campaign.
void BM_CampaignEndToEnd(benchmark::State& state) {
  spdlog::set_level(spdlog::level::warn);
  const int cells = static_cast<int>(state.range(0));
  const fs::path dir = fs::temp_directory_path() / ("arena_orch_bench_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const int domain = 120 + getpid() % 100;
  std::vector<std::unique_ptr<CellProcess>> processes;
  for (int k = 0; k < cells; ++k) {
    processes.push_back(std::make_unique<CellProcess>(
        "bench" + std::to_string(k + 1), domain, dir / ("cell" + std::to_string(k + 1) + ".log")));
  }
  const orchestrator::Campaign campaign =
      orchestrator::ParseCampaign(SmokeCampaign(10), ARENA_SOURCE_DIR "/examples/campaigns");

  std::vector<double> overhead, busy, execute, reset;
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
    so.network.shared_memory = false;  // as `arena serve` and `arena run`: UDP on loopback
    orchestrator::Service service(so);
    service.OnTrialTiming([&](const orchestrator::TrialTiming& t) {
      overhead.push_back(t.overhead_s);
      busy.push_back(t.cell_busy_s);
      execute.push_back(t.execute_s);
      reset.push_back(t.reset_s);
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
  state.counters["busy_p50_ms"] = Quantile(busy, 0.5) * 1e3;
  state.counters["execute_p50_ms"] = Quantile(execute, 0.5) * 1e3;
  state.counters["reset_p50_ms"] = Quantile(reset, 0.5) * 1e3;
  state.counters["cell_rss_growth_kib_per_1k_trials"] =
      later_trials > 0 ? 1000.0 * static_cast<double>(rss_growth) / later_trials : 0;
}
BENCHMARK(BM_CampaignEndToEnd)
    ->Arg(1)
    ->Arg(2)
    ->Iterations(5)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
