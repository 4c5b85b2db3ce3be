// arena cell --id ID --domain D [--backend NAME] [--backend-settings JSON]
//            [--defects FILE] [--speed X] [--batch N]
//            [--peers H[:P],...] [--discovery-server [ID@]H:P] [--profile-xml F]
//            [--security DIR]
// Runs one simulated cell until SIGINT or SIGTERM (executors/README.md).
#include <signal.h>

#include <condition_variable>
#include <cstdio>
#include <fstream>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "arena/db/export.hpp"
#include "arena/executors/cell.hpp"
#include "arena/schemas/security.hpp"
#include "commands.hpp"
#include "dds_options.hpp"
#include "signals.hpp"

namespace arena::cli {
namespace {

struct CellCliOptions {
  executors::CellOptions cell;
  std::string defects_path;
  std::string backend = "model";  // model | mujoco | exec:COMMAND | replay:DATASET
  std::string backend_settings;   // JSON object of the backend's settings (mujoco)
  DdsCliOptions dds;
  bool verbose = false;
  int parent_pid = 0;  // > 0: stop when that process (arena run) is gone
};

std::string ReadText(const std::string& path, const char* option) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CommandError(kExitBadInput, std::string(option) + ": cannot open '" + path + "'");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

int RunCell(CellCliOptions opt) {
  auto logger = spdlog::stderr_color_mt("cell");
  spdlog::set_default_logger(logger);
  spdlog::set_level(opt.verbose ? spdlog::level::debug : spdlog::level::info);
  try {
    if (!opt.defects_path.empty()) {
      opt.cell.defects = executors::ParseDefectProfile(ReadText(opt.defects_path, "--defects"));
    }
    opt.cell.domain_id = opt.dds.domain;
    opt.cell.network = opt.dds.Network();
    executors::ValidateCellOptions(opt.cell);
  } catch (const executors::DefectError& e) {
    throw CommandError(kExitBadInput, "--defects " + opt.defects_path + ": " + e.what());
  }

  // Signals are blocked before any thread starts (DDS threads inherit the
  // mask) and handled on the watcher's thread: no code runs in a handler.
  std::mutex mu;
  std::condition_variable stopped;
  int stop_signal = 0;
  SignalWatcher signals([&](int sig) {
    std::lock_guard<std::mutex> lock(mu);
    stop_signal = sig;
    stopped.notify_all();
  });
  if (!FollowParent(opt.parent_pid)) {
    spdlog::warn("cell {}: the process that started it ({}) is gone; not starting", opt.cell.id,
                 opt.parent_pid);
    return kExitOk;
  }

  // A predecessor SIGKILLed (a restart after a crash) left its shared memory.
  if (const std::size_t n = dds::CleanZombieSharedMemory(); n > 0)
    spdlog::info("cell {}: removed {} shared-memory files of dead DDS processes", opt.cell.id, n);
  std::unique_ptr<executors::Cell> cell;
  {
    const executors::ModelFidelity fidelity{opt.cell.fidelity.facets, opt.cell.fidelity.points,
                                            opt.cell.fidelity.dt};
    auto backend = executors::MakeBackend(opt.backend, fidelity, opt.backend_settings);
    if (opt.backend.rfind("replay:", 0) == 0) {
      // Every file against the manifest (checksums, sizes, counts, nothing
      // unlisted) before the cell serves a trial from it (after the
      // backend's own reading of it, whose reasons are more specific).
      const std::string dataset = opt.backend.substr(7);
      try {
        (void)db::VerifyExport(dataset);
      } catch (const db::StoreError& e) {
        throw CommandError(kExitBadInput,
                           "--backend replay:" + dataset +
                               ": the dataset does not match its manifest: " + e.what());
      } catch (const std::exception& e) {
        throw CommandError(kExitBadInput,
                           "--backend replay:" + dataset + ": unreadable manifest: " + e.what());
      }
    }
    cell = std::make_unique<executors::Cell>(opt.cell, std::move(backend));
  }
  {
    std::unique_lock<std::mutex> lock(mu);
    stopped.wait(lock, [&] { return stop_signal != 0; });
  }
  spdlog::info("cell {}: {} received, shutting down", opt.cell.id,
               stop_signal == SIGINT ? "SIGINT" : "SIGTERM");
  cell->Stop();
  cell.reset();
  return kExitOk;
}

}  // namespace

void AddCellCommand(CLI::App& app, Action* action) {
  auto opt = std::make_shared<CellCliOptions>();
  CLI::App* cmd =
      app.add_subcommand("cell", "Run a simulated robot cell that serves trials over DDS");
  cmd->footer(
      "Example:\n  arena cell --id c1 --domain 42 --defects examples/defects/noisy.json --speed 0\n"
      "  arena cell --id c1 --domain 42 --backend mujoco\n"
      "  arena cell --id lab1 --domain 42 --backend 'exec:examples/drivers/replay.py DATASET'\n"
      "  arena cell --id c1 --domain 42 --security lab-pki/c1   (see `arena certs --help`)\n"
      "Without --peers or --discovery-server the cell is reachable from this host only.\n"
      "Stops cleanly on SIGINT/SIGTERM (exit 0).");
  cmd->add_option("--id", opt->cell.id, "Cell id, unique in the deployment ([A-Za-z0-9_.-])")
      ->required();
  AddDdsOptions(cmd, &opt->dds, "a 'cell' identity directory from `arena certs issue`");
  cmd->add_option("--backend", opt->backend,
                  "What executes the trials: model (arena's model: self-consistency), mujoco, "
                  "exec:COMMAND (a driver, executors/README.md), replay:DATASET (an export)")
      ->capture_default_str();
  cmd->add_option("--backend-settings", opt->backend_settings,
                  "The backend's settings as a JSON object, e.g. '{\"timestep\": 0.001}' for "
                  "mujoco (simulators/README.md)");
  cmd->add_option("--defects", opt->defects_path, "Defect profile JSON (executors/README.md)");
  cmd->add_option("--speed", opt->cell.speed,
                  "Wall seconds per simulated second: 0 = as fast as possible, 1 = real time")
      ->capture_default_str();
  cmd->add_option("--batch", opt->cell.batch_samples, "Ground-truth samples per message (1..256)")
      ->capture_default_str();
  cmd->add_option("--parent-pid", opt->parent_pid,
                  "Stop when this process exits (arena run passes its own pid)");
  cmd->add_flag("-v,--verbose", opt->verbose, "Debug log (QoS in effect, discovery)");
  cmd->callback([opt, action] { *action = [opt] { return RunCell(*opt); }; });
}

}  // namespace arena::cli
