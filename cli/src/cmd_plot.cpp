// arena plot --db FILE TRIAL --out FILE.svg: one trial's object pose and
// contact forces over time, true vs observed vs predicted (plot_trial.hpp).
// The per-trial mode is PlotTrial() (plot_trial.hpp); another mode (a
// campaign's --tradeoff chart) adds its options here and dispatches to its
// own function when its flag is given.
#include <memory>
#include <string>

#include "commands.hpp"
#include "plot_trial.hpp"

namespace arena::cli {
namespace {

struct PlotOptions {
  std::string db_path;
  std::int64_t trial = -1;
  std::string out;
};

}  // namespace

void AddPlotCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<PlotOptions>();
  auto* cmd = app.add_subcommand("plot", "Plot a trial: object pose and contact forces, true vs observed vs predicted");
  cmd->add_option("trial", o->trial, "Trial id (see `arena query`)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--db", o->db_path, "Store file (opened read-only)")->required();
  cmd->add_option("--out", o->out, "SVG file to write")->required();
  cmd->footer(
      "Example:\n"
      "  arena plot --db lab.db 12 --out trial12.svg\n"
      "The prediction is re-run with the campaign's \"prediction\" settings, as `arena serve` ran it.\n"
      "View the SVG in a browser, or convert it: rsvg-convert trial12.svg -o trial12.png\n");
  cmd->callback([o, action] { *action = [o] { return PlotTrial(o->db_path, o->trial, o->out); }; });
}

}  // namespace arena::cli
