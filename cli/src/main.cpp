// arena: one binary, many subcommands (docs/architecture.md, the cli room).
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <exception>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

#include "arena/cli/version.hpp"
#include "arena/db/store.hpp"
#include "arena/errors/error.hpp"
#include "commands.hpp"
#include "store_errors.hpp"

int main(int argc, char** argv) {
  using namespace arena::cli;
  // Logs go to stderr: stdout is a command's answer, which scripts read
  // (`id=$(arena submit ...)`); spdlog's default logger writes to stdout.
  spdlog::set_default_logger(spdlog::stderr_color_mt("arena"));
  CLI::App app{"arena: autonomous prehensile-pushing experiment campaigns", "arena"};
  app.require_subcommand(0, 1);
  app.set_version_flag("--version", std::string("arena ") + arena::Version() + " (commit " +
                                        arena::GitCommit() + ")");
  app.footer("Run 'arena COMMAND --help' for a command's options and an example.");

  Action action;
  AddRunCommand(app, &action);
  AddCampaignCommands(app, &action);
  AddServeCommand(app, &action);
  AddSimulateCommand(app, &action);
  AddCellCommand(app, &action);
  AddControllerCommand(app, &action);
  AddCellsCommand(app, &action);
  AddQueryCommand(app, &action);
  AddExportCommand(app, &action);
  AddEvaluateCommand(app, &action);
  AddPlotCommand(app, &action);
  AddWatchCommand(app, &action);
  AddCertsCommand(app, &action);
  AddSensitivityCommand(app, &action);
  AddCalibrateCommand(app, &action);
  AddImportCommand(app, &action);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11 prints help/version itself (exit 0); other parse errors are usage errors.
    const int rc = app.exit(e);
    return rc == 0 ? kExitOk : kExitBadInput;
  }
  if (!action) {
    // No command is a usage error (README: exit codes): the usage goes to stderr.
    std::fputs(app.help().c_str(), stderr);
    std::fputs("arena: no command given\n", stderr);
    return kExitBadInput;
  }
  // The one place an error becomes an exit code (README: exit codes): every
  // room's typed error carries its category; a plain std::invalid_argument is
  // a value a command refused (bad input); anything else is a bug of ours.
  try {
    return action();
  } catch (const arena::Error& e) {
    // The store's messages lead with the function that refused: noise for a user.
    const bool from_store = dynamic_cast<const arena::db::StoreError*>(&e) != nullptr ||
                            dynamic_cast<const CommandError*>(&e) != nullptr;
    std::fprintf(stderr, "arena: %s\n", from_store ? UserMessage(e.what()).c_str() : e.what());
    return e.exit_code();
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "arena: %s\n", e.what());
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "arena: internal error: %s\n", e.what());
    return kExitFailure;
  }
}
