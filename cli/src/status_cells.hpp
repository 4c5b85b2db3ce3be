// What each cell is doing now, for `arena status`: its backend, the phase and
// trial it is in and for how long; cells gone for more than a day folded into
// a count unless --all (issue 26: status an operator can trust).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "arena/db/store.hpp"

namespace arena::cli {

struct CellActivity {
  std::string backend;         // from the cell's announcement ("" if never announced)
  std::string phase = "idle";  // "execute", "reset", "idle"
  std::int64_t trial_id = 0;   // 0: none
  double in_phase_s = 0;       // since the trial entered the phase
};

// A cell silent for longer than this is folded into a count.
inline constexpr double kGoneFoldS = 24 * 3600.0;

// One per cell of `cells`, same order. Reads the store (opened read-only).
std::vector<CellActivity> ReadCellActivity(const db::Store& store,
                                           const std::vector<db::CellInfo>& cells);

// The cell table of `arena status`, with a leading blank line.
std::string FormatCellTable(const std::vector<db::CellInfo>& cells,
                            const std::vector<CellActivity>& activity, double now, bool all);

}  // namespace arena::cli
