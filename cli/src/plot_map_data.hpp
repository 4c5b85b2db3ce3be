// The data of `arena plot --campaign ID --map X,Y --metric M` (see
// plot_map.hpp for the drawing and cmd_plot.cpp for the command).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "arena/db/store.hpp"
#include "plot_map.hpp"

namespace arena::cli {

// "displacement, rotation, position_error, ..." (the --metric choices).
std::string MapMetricNames();

// One point per condition of the campaign at its values of the two varied
// parameters X and Y, coloured by the metric (mean over the condition's
// replicates for per-trial metrics; the latest sensitivity run for spreads
// and the unstable flag).
// @throws std::invalid_argument for an unknown metric or a parameter the
//   campaign does not have; db::StoreError for an unknown campaign.
MapData BuildCampaignMap(const db::Store& store, std::int64_t campaign_id, const std::string& x,
                         const std::string& y, const std::string& metric);

// Points an adaptive campaign placed on a boundary (its sampler_decisions
// whose rule is the nearest-neighbour margin, "nn_margin"), in (X, Y)
// coordinates; empty for campaigns that are not adaptive and for stores
// without adaptive samplers.
std::vector<std::pair<double, double>> AdaptiveBoundaryPoints(const db::Store& store,
                                                              std::int64_t campaign_id,
                                                              const std::string& x,
                                                              const std::string& y);

}  // namespace arena::cli
