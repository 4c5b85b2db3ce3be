// The arena binary's subcommands. Each Add*Command() registers one CLI11
// subcommand; when it is chosen on the command line its callback stores the
// action to run in *action, and main() runs it once parsing is done, so that
// every error is reported in one place (main) with its exit code.
#pragma once

#include <functional>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

#include "command_error.hpp"

namespace arena::cli {

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
