// Closed-loop trials on the service side (issue 19): what a cell reports of
// a closed-loop EXECUTE phase (TrialStatus.detail_json "closed_loop") as the
// store's ClosedLoopRun.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "arena/db/store.hpp"

namespace arena::orchestrator {

// nullopt when the detail has no closed_loop section (an open-loop trial).
// @throws std::invalid_argument naming the field when the section is malformed.
std::optional<db::ClosedLoopRun> ClosedLoopFromDetail(std::int64_t trial_id, int attempt,
                                                      const std::string& failure,
                                                      const std::string& detail_json);

}  // namespace arena::orchestrator
