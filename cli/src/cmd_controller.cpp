// arena controller --name NAME --domain D [--law LAW] [--security DIR] ...
// Hosts a closed-loop controller of arena's own library (executors/
// controller.hpp): answers every LiveState sample of a closed-loop trial whose
// scene names NAME with a PusherCommand, until SIGINT or SIGTERM.
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <memory>
#include <string>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "arena/executors/controller.hpp"
#include "arena/schemas/security.hpp"
#include "commands.hpp"
#include "dds_options.hpp"
#include "signals.hpp"

namespace arena::cli {
namespace {

struct ControllerCliOptions {
  executors::ControllerHostOptions host;
  std::string law;  // empty: the name is the law
  DdsCliOptions dds;
  bool verbose = false;
  int parent_pid = 0;
};

std::string LawList() {
  std::string list;
  for (const auto& l : executors::LibraryLaws()) list += (list.empty() ? "" : ", ") + l;
  return list;
}

int RunController(ControllerCliOptions opt) {
  auto logger = spdlog::stderr_color_mt("controller");
  spdlog::set_default_logger(logger);
  spdlog::set_level(opt.verbose ? spdlog::level::debug : spdlog::level::info);
  const std::string law = opt.law.empty() ? opt.host.name : opt.law;
  const auto laws = executors::LibraryLaws();
  if (std::find(laws.begin(), laws.end(), law) == laws.end()) {
    throw CommandError(kExitBadInput, (opt.law.empty() ? "--name: " : "--law: ") +
                                          std::string("no controller law '") + law +
                                          "' in arena's library (one of: " + LawList() +
                                          "; give --law when the name is your own)");
  }
  opt.host.domain_id = opt.dds.domain;
  opt.host.network = opt.dds.Network();
  // Signals: blocked before DDS starts its threads, handled on the
  // watcher's thread, which flips `stop` (as `arena cell`).
  std::atomic<bool> stop{false};
  SignalWatcher signals([&](int sig) {
    spdlog::info("controller {}: {} received, shutting down", opt.host.name,
                 sig == SIGINT ? "SIGINT" : "SIGTERM");
    stop = true;
  });
  if (!FollowParent(opt.parent_pid)) return kExitOk;
  // A name conflict, a bad identity or a refused set-up: main() maps its category.
  const executors::ControllerCounters counters = executors::RunController(
      opt.host,
      [law](const executors::ControlContext& context) {
        return executors::MakeLibraryController(law, context);
      },
      &stop);
  spdlog::info(
      "controller {}: answered {} samples of {} trials ({} live samples superseded before it "
      "took them, {} reported lost)",
      opt.host.name, counters.samples, counters.trials, counters.live.superseded,
      counters.live.lost);
  return kExitOk;
}

}  // namespace

void AddControllerCommand(CLI::App& app, Action* action) {
  auto opt = std::make_shared<ControllerCliOptions>();
  CLI::App* cmd = app.add_subcommand(
      "controller", "Host a closed-loop controller that commands the pusher of running trials");
  cmd->footer(
      "Example:\n  arena controller --name pivot_to_angle --domain 42\n"
      "  arena controller --name lab_pivot --law pivot_to_angle --domain 42 --security "
      "lab-pki/lab_pivot\n"
      "A scene whose pusher motion is {\"controller\": NAME, ...} is driven by the controller\n"
      "registered under NAME (docs/live_control.md). Laws: pivot_to_angle, sliding_to_position.\n"
      "One controller per name on a domain: a second one is refused (exit 2). Under\n"
      "--security the identity must be issued for the name (arena certs issue LAB --role\n"
      "controller --name NAME): only it may command the pusher of NAME's trials.\n"
      "Stops cleanly on SIGINT/SIGTERM (exit 0).");
  cmd->add_option("--name", opt->host.name, "Name scenes use to pick this controller")->required();
  cmd->add_option("--law", opt->law, "Library law to run (default: the name)");
  AddDdsOptions(cmd, &opt->dds,
                "a 'controller' identity directory issued for the name (`arena certs issue`)");
  cmd->add_option("--parent-pid", opt->parent_pid,
                  "Stop when this process exits (arena run passes its own pid)");
  cmd->add_flag("-v,--verbose", opt->verbose, "Debug log");
  cmd->callback([opt, action] { *action = [opt] { return RunController(*opt); }; });
}

}  // namespace arena::cli
