// The charts `arena plot` draws, built from store data (testable without a
// process; cmd_plot.cpp does the I/O). One builder per plot mode.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include "svg_chart.hpp"

namespace arena::cli {

// --tradeoff: an evaluation run's report (the JSON Store::RecordEvaluation
// keeps, orchestrator::ToJson) as primary error against median model time
// per trial, both log axes. Series: "settings" (markers, every setting that
// predicted all trials), "pareto front" (line through the front, by time),
// "recommended" (marker), "failed settings" (markers at their error over the
// trials they did predict). A setting with zero error cannot sit on a log
// axis; the title says how many were left out.
// @throws std::invalid_argument when the report lacks its fields.
Chart TradeoffChart(const nlohmann::json& report);

}  // namespace arena::cli
