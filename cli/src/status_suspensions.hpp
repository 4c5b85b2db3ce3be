// `arena status`: the suspensions (issue 29) that hold dispatch back now and
// the last ones lifted, as text and as JSON.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"

namespace arena::cli {

// `all`: the store's suspensions, newest first (Store::ListSuspensions).
// Text: every active one, then at most `recent_lifted` lifted ones; "" when none.
std::string FormatSuspensions(const std::vector<db::Suspension>& all, double now,
                              std::size_t recent_lifted = 5);
nlohmann::json SuspensionsJson(const std::vector<db::Suspension>& all);

}  // namespace arena::cli
