// arena serve --db FILE --domain D: the long-running campaign service.
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/orchestrator/logging.hpp"
#include "arena/orchestrator/service.hpp"
#include "arena/schemas/security.hpp"
#include "commands.hpp"
#include "dds_options.hpp"
#include "signals.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

struct ServeCliOptions {
  orchestrator::ServiceOptions service;
  DdsCliOptions dds;
  std::string log_level = "info";
  std::string suspenders_path;  // --suspenders FILE
};

// The suspenders' limits: the defaults (docs/operations.md), with FILE's
// fields over them. @throws std::invalid_argument naming the file and field.
orchestrator::SuspenderConfig LoadSuspenders(const std::string& path) {
  if (path.empty()) return {};
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("--suspenders " + path + ": cannot read the file");
  std::stringstream text;
  text << in.rdbuf();
  const auto j = nlohmann::json::parse(text.str(), nullptr, false);
  if (j.is_discarded()) throw std::invalid_argument("--suspenders " + path + ": not valid JSON");
  try {
    return orchestrator::ParseSuspenders(j);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument("--suspenders " + path + ": " + e.what());
  }
}

int RunServe(ServeCliOptions opt) {
  // Before any thread exists (the log's flusher, DDS): threads inherit the
  // blocked signals, so only the watcher ever sees SIGTERM.
  std::atomic<orchestrator::Service*> running{nullptr};
  SignalWatcher signals([&running](int sig) {
    spdlog::info("{} received", sig == SIGINT ? "SIGINT" : "SIGTERM");
    if (auto* s = running.load()) s->Stop();
  });
  try {
    opt.service.domain_id = opt.dds.domain;
    opt.service.network = opt.dds.Network();
    opt.service.suspenders = LoadSuspenders(opt.suspenders_path);
    orchestrator::ValidateServiceOptions(opt.service);  // before anything is created
    orchestrator::SetUpServiceLog(opt.service.db_path, opt.log_level);
  } catch (const spdlog::spdlog_ex& e) {
    throw CommandError(kExitStore,
                       std::string("cannot write the log next to the store: ") + e.what());
  }
  dds::CleanZombieSharedMemory();  // what SIGKILLed predecessors and cells left in /dev/shm
  auto service = std::make_unique<orchestrator::Service>(opt.service);
  running = service.get();
  if (signals.received()) service->Stop();  // a signal that came while it was starting
  spdlog::info("serving store {} on DDS domain {}", opt.service.db_path, opt.service.domain_id);
  try {
    service->Run();
  } catch (const db::StoreError& e) {
    spdlog::critical("store failure, stopping: {}", e.what());
    throw StoreCommandError(e);
  }
  const auto c = service->counters();
  spdlog::info("stopped: {} dispatched, {} done, {} retried, {} failed", c.dispatched, c.done,
               c.retried, c.failed);
  spdlog::default_logger()->flush();
  return kExitOk;
}

}  // namespace

void AddServeCommand(CLI::App& app, Action* action) {
  auto opt = std::make_shared<ServeCliOptions>();
  CLI::App* cmd =
      app.add_subcommand("serve", "Run the campaign service: schedule trials onto cells over DDS");
  cmd->footer(
      "Example:\n  arena serve --db lab.db --domain 42 --log-level info\n"
      "  arena serve --db lab.db --domain 42 --security lab-pki/service   (see `arena certs "
      "--help`)\n"
      "Logs go to FILE.log next to the store (rotated, 16 MiB x 6 at most) and to stderr.\n"
      "SIGTERM stops dispatching and lets phases in flight finish (up to --drain s).");
  cmd->add_option("--db", opt->service.db_path, "SQLite store (created if missing)")->required();
  // The service is the process that gets restarted after a crash. A SIGKILLed
  // process leaves its shared-memory ports claimed in /dev/shm, and a successor
  // that reuses its participant id could then miss the cells' discovery
  // traffic; over loopback UDP it cannot. Ground truth at 16 x 250 Hz is far
  // below what loopback carries.
  opt->dds.network.shared_memory = false;
  AddDdsOptions(cmd, &opt->dds, "a 'service' identity directory from `arena certs issue`");
  cmd->add_option("--log-level", opt->log_level, "trace, debug, info, warn, error, critical, off")
      ->capture_default_str();
  cmd->add_option("--max-attempts", opt->service.max_attempts,
                  "Executions per trial before it fails")
      ->capture_default_str();
  cmd->add_option("--quarantine-after", opt->service.quarantine_after,
                  "Consecutive failed phases before a cell is quarantined")
      ->capture_default_str();
  cmd->add_option("--execute-timeout", opt->service.execute_timeout_s,
                  "EXECUTE budget (s) beyond the trial's duration at the cell's speed")
      ->capture_default_str();
  cmd->add_option("--reset-timeout", opt->service.reset_timeout_s, "RESET budget (s)")
      ->capture_default_str();
  cmd->add_option("--drain", opt->service.drain_timeout_s,
                  "On SIGTERM: seconds phases in flight may finish")
      ->capture_default_str();
  cmd->add_option("--predictors", opt->service.predictor_threads, "Predictor threads")
      ->capture_default_str();
  cmd->add_option("--integrity-check-period", opt->service.integrity_check_period_s,
                  "Seconds between the store's quick checks while serving (damage found: exit 3)")
      ->capture_default_str();
  cmd->add_option("--suspenders", opt->suspenders_path,
                  "JSON file of suspender limits over the defaults (docs/operations.md)");
  cmd->add_option("--notify", opt->service.notify_command,
                  "Run this shell command with one JSON event on stdin per event "
                  "(campaign done, cell gone, suspension, ...; docs/operations.md)");
  cmd->add_option("--notify-timeout", opt->service.notify_timeout_s,
                  "Seconds a --notify command may run before its process group is killed")
      ->capture_default_str();
  cmd->add_option("--notify-queue", opt->service.notify_queue,
                  "Events waiting for a slow --notify command before new ones are dropped "
                  "(counted and logged; all stay in the store)")
      ->capture_default_str();
  cmd->add_option("--notify-failure-rate", opt->service.notify_failure_rate,
                  "Failed share of a campaign's finished trials that is an event")
      ->capture_default_str();
  // Hidden: the longest wait of a cell after failed phases (the soak test
  // compresses a week; a lab keeps the default).
  cmd->add_option("--cell-backoff-max", opt->service.cell_backoff_max_s)->group("");
  // Hidden: bounds the store's size to emulate a full disk (fault tests).
  cmd->add_option("--store-max-pages", opt->service.store_max_pages)->group("");
  cmd->callback([opt, action] { *action = [opt] { return RunServe(*opt); }; });
}

}  // namespace arena::cli
