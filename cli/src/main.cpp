// arena: one binary, many subcommands (docs/architecture.md, the cli room).
#include <cstdio>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "arena/cli/version.hpp"
#include "arena/db/store.hpp"
#include "commands.hpp"
#include "store_errors.hpp"

int main(int argc, char** argv) {
  using namespace arena::cli;
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
  try {
    return action();
  } catch (const CommandError& e) {
    std::fprintf(stderr, "arena: %s\n", UserMessage(e.what()).c_str());
    return e.exit_code();
  } catch (const arena::db::StoreError& e) {  // a store error a command did not translate
    std::fprintf(stderr, "arena: %s\n", UserMessage(e.what()).c_str());
    return ExitCodeFor(e);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "arena: internal error: %s\n", e.what());
    return kExitFailure;
  }
}
