// arena plot --db FILE TRIAL --out FILE.svg: one trial's object pose and
// contact forces over time, true vs observed vs predicted (plot_trial.hpp).
// Other plot modes (e.g. a campaign's --tradeoff chart) add their options
// here and dispatch in RunPlot; each mode builds a Chart and WriteSvg writes it.
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>

#include "arena/db/store.hpp"
#include "commands.hpp"
#include "plot_trial.hpp"
#include "store_errors.hpp"
#include "svg_chart.hpp"

namespace arena::cli {
namespace {

struct PlotOptions {
  std::string db_path;
  std::int64_t trial = -1;
  std::string out;
};

std::unique_ptr<db::Store> OpenReadOnly(const std::string& path) {
  try {
    db::StoreOptions so;
    so.read_only = true;
    so.create = false;
    return db::Store::Open(path, so);
  } catch (const db::StoreError& e) {
    throw CommandError(ExitCodeFor(e), std::string(e.what()) + " (is --db the store `arena serve` or `arena run` uses?)");
  }
}

// Writes next to the target and renames, so a reader never sees half an SVG.
void WriteSvg(const Chart& chart, const std::string& out) {
  const std::string svg = RenderSvg(chart);
  const std::string tmp = out + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) throw CommandError(kExitFailure, "cannot write " + tmp + ": check that its directory exists and is writable");
    f.write(svg.data(), static_cast<std::streamsize>(svg.size()));
    f.close();
    if (!f) throw CommandError(kExitFailure, "cannot write " + tmp + " (disk full?)");
  }
  if (std::rename(tmp.c_str(), out.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw CommandError(kExitFailure, "cannot rename " + tmp + " to " + out);
  }
}

int RunPlot(const PlotOptions& o) {
  if (o.trial < 0)
    throw CommandError(kExitBadInput, "give a TRIAL id to plot (find ids with `arena query --db " + o.db_path +
                                          " --campaign ID`)");
  auto store = OpenReadOnly(o.db_path);
  TrialPlotInfo info;
  const Chart chart = MakeTrialChart(*store, o.trial, &info);
  WriteSvg(chart, o.out);
  std::fprintf(stderr, "trial %lld: %zu samples, prediction %s (%s) -> %s\n", static_cast<long long>(o.trial),
               info.samples, info.model_key.empty() ? "-" : info.model_key.c_str(), info.prediction_status.c_str(),
               o.out.c_str());
  return kExitOk;
}

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
  cmd->callback([o, action] { *action = [o] { return RunPlot(*o); }; });
}

}  // namespace arena::cli
