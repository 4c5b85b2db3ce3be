// The charts `arena plot` draws, built from store data (testable without a
// process; cmd_plot.cpp does the I/O). One builder per plot mode.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include "svg_chart.hpp"

namespace arena::cli {

// --tradeoff: an evaluation run's report (the JSON Store::RecordEvaluation
// keeps, assessment::ToJson). Panel 1: primary error against the predictor's
// wall time per simulated second (reports older than that field: median time
// per trial), both log axes; one series per predictor (named after it:
// markers joined coarse to fine, each labelled with its setting), "failed
// settings" (drawn apart, above every error, labelled with their divergence
// and failure counts), "pareto front", "recommended", and "noise floor
// (replicate spread)" when the report has one. Panel 2 (own x axis, when the
// report has duration_curves): p95 final position error against
// ground-truth duration per predictor. A setting with zero error cannot sit
// on a log axis; the title says how many were left out.
// @throws std::invalid_argument when the report lacks its fields.
Chart TradeoffChart(const nlohmann::json& report);

// --calibration: a calibration's stored parameters (db::Calibration's
// params_json, assessment::ParamsJson). One panel per parameter with a
// profile: the mean training loss against its scale (both log axes; series
// "loss NAME", markers joined), the fit ("fit NAME") and the dashed ends
// of what fits as well ("fits as well from NAME" / "fits as well up to NAME":
// the nearest scales that fit worse, or a bound);
// the title says when the data do not identify it.
// @throws std::invalid_argument when no parameter has a profile.
Chart CalibrationProfileChart(const nlohmann::json& params, const std::string& title);

}  // namespace arena::cli
