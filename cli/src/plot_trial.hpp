// The per-trial chart of `arena plot TRIAL`: object pose and contact forces
// over time, true (the cell's ground truth) vs observed (what its sensors
// saw) vs predicted (the model re-run on the trial's scene with the
// campaign's prediction settings, as the service predicted it).
#pragma once

#include <cstdint>
#include <string>

#include "arena/db/prediction_status.hpp"
#include "svg_chart.hpp"

namespace arena::db {
class Store;
}

namespace arena::cli {

// Series names the chart uses (tests and scripts find them by data-name).
// Pose panels: "true", "observed", "predicted". Force panels (one per contact,
// fingers in scene order then the pusher): "normal true", "normal observed",
// "normal predicted", "tangential true", "tangential observed", "tangential predicted".
struct TrialPlotInfo {
  db::PredictionStatus prediction_status = db::PredictionStatus::kOk;
  std::string model_key;    // fidelity label of the prediction ("" if it could not be made)
  std::size_t samples = 0;  // ground-truth samples plotted
};

// @throws CommandError: kExitBadInput for an unknown trial or one without
//   ground truth yet (the message says what to do), kExitStore for a store failure.
Chart MakeTrialChart(const db::Store& store, std::int64_t trial_id, TrialPlotInfo* info = nullptr);

// `arena plot --db DB TRIAL --out OUT`: opens the store read-only, builds the
// chart, writes it atomically (OUT.tmp, then rename), reports on stderr.
// @returns kExitOk. @throws CommandError (exit code per README).
int PlotTrial(const std::string& db_path, std::int64_t trial, const std::string& out);

// `arena plot --db DB TRIAL --paths`: the trial seen from above (x right, y
// up, one scale): the object's true path (for an imported recording: the
// measured one) and the prediction's (the campaign's prediction settings),
// the object's outline at the start, 1/3, 2/3 and the end of both, and the
// pusher's centre path with its tip at those instants. Groups carry ids:
// measured-path, predicted-path, measured-outlines, predicted-outlines,
// pusher-path, scale-bar.
// @throws CommandError as MakeTrialChart.
std::string TrialPathsSvg(const db::Store& store, std::int64_t trial_id,
                          TrialPlotInfo* info = nullptr);

// Writes the chart's SVG to `out` atomically. @throws CommandError(kExitFailure).
void WriteSvgFile(const Chart& chart, const std::string& out);

}  // namespace arena::cli
