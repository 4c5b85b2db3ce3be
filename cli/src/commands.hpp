// The arena binary's subcommands. Each Add*Command() registers one CLI11
// subcommand; when it is chosen on the command line its callback stores the
// action to run in *action, and main() runs it once parsing is done, so that
// every error is reported in one place (main) with its exit code.
#pragma once

#include <functional>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

namespace arena::cli {

// Exit codes (documented in README.md).
enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = 1,        // the command ran and failed (a solver failure, a failed campaign)
  kExitBadInput = 2,       // invalid arguments, scene, campaign or query
  kExitStore = 3,          // the store cannot be opened, is read-only, full or corrupt
  kExitCommunication = 4,  // DDS set-up failed, no cell answered in time
  kExitInterrupted = 130,  // stopped by SIGINT / SIGTERM before finishing
};

// An error a command reports to the user: the message says what went wrong and
// what to do next; main() prints it to stderr and exits with exit_code.
class CommandError : public std::runtime_error {
 public:
  CommandError(int exit_code, const std::string& message)
      : std::runtime_error(message), exit_code_(exit_code) {}
  int exit_code() const { return exit_code_; }

 private:
  int exit_code_;
};

using Action = std::function<int()>;

void AddSimulateCommand(CLI::App& app, Action* action);
void AddServeCommand(CLI::App& app, Action* action);
void AddRunCommand(CLI::App& app, Action* action);
void AddCampaignCommands(CLI::App& app, Action* action);  // submit list status pause resume cancel
void AddCellCommand(CLI::App& app, Action* action);
void AddCellsCommand(CLI::App& app, Action* action);      // cmd_cells.cpp (release)
void AddQueryCommand(CLI::App& app, Action* action);      // cmd_query.cpp (store room)
void AddExportCommand(CLI::App& app, Action* action);     // cmd_export.cpp (store room)
void AddEvaluateCommand(CLI::App& app, Action* action);   // cmd_evaluate.cpp
void AddPlotCommand(CLI::App& app, Action* action);       // cmd_plot.cpp (TRIAL or --tradeoff)
void AddWatchCommand(CLI::App& app, Action* action);      // cmd_watch.cpp
void AddCertsCommand(CLI::App& app, Action* action);      // cmd_certs.cpp (init, issue)
void AddCalibrateCommand(CLI::App& app, Action* action);  // cmd_calibrate.cpp
void AddImportCommand(CLI::App& app, Action* action);     // cmd_import.cpp (recordings room)

// cmd_sensitivity.cpp (scene and campaign views)
void AddSensitivityCommand(CLI::App& app, Action* action);
// cmd_controller.cpp (closed-loop controllers, issue 19)
void AddControllerCommand(CLI::App& app, Action* action);

}  // namespace arena::cli
