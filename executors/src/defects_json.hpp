// The defect profiles as JSON trees (private): the canonical text
// (DefectProfileToJson, DefectLayer::AppliedJson) and the cell's trial details
// build on these, with no dump and parse in between (issue 27: that round
// trip was most of the time between a trial's last sample and its status).
#pragma once

#include <nlohmann/json.hpp>

#include "arena/executors/defect_layer.hpp"
#include "arena/executors/defects.hpp"

namespace arena::executors::internal {

nlohmann::json DefectProfileTree(const DefectProfile& profile);

// {"emulated", "cell", "campaign" (null when none), "effective", "perturbation"}.
nlohmann::json AppliedDefectsTree(const DefectLayer& layer);
// AppliedDefectsTree(layer).dump(), from the layer's cached profiles' text.
std::string AppliedDefectsText(const DefectLayer& layer);

}  // namespace arena::executors::internal
