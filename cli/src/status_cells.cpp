#include "status_cells.hpp"

#include <cstdio>
#include <ctime>
#include <map>
#include <variant>

#include <nlohmann/json.hpp>

#include "arena/db/query.hpp"
#include "progress.hpp"

namespace arena::cli {
std::vector<CellActivity> ReadCellActivity(const db::Store& store,
                                           const std::vector<db::CellInfo>& cells) {
  std::vector<CellActivity> out(cells.size());
  std::map<std::string, size_t> index;
  for (size_t k = 0; k < cells.size(); ++k) {
    index[cells[k].id] = k;
    const auto caps = nlohmann::json::parse(cells[k].capabilities_json, nullptr, false);
    if (caps.is_object() && caps.contains("backend") && caps["backend"].is_string())
      out[k].backend = caps["backend"].get<std::string>();
  }
  // A cell executes a dispatched trial and resets for a resetting one; the
  // trial's updated_at is when it entered that state.
  const db::QueryResult rows =
      db::RunQuery(store,
                   "SELECT cell_id, id, state, updated_at FROM trials "
                   "WHERE state IN ('dispatched', 'resetting') ORDER BY updated_at");
  const double now = store.Now();
  for (const auto& row : rows.rows) {
    const auto* cell = std::get_if<std::string>(&row[0]);
    if (!cell) continue;
    const auto it = index.find(*cell);
    if (it == index.end()) continue;
    CellActivity& a = out[it->second];
    a.trial_id = std::get<std::int64_t>(row[1]);
    a.phase = std::get<std::string>(row[2]) == "dispatched" ? "execute" : "reset";
    const double since = std::holds_alternative<double>(row[3])
                             ? std::get<double>(row[3])
                             : static_cast<double>(std::get<std::int64_t>(row[3]));
    a.in_phase_s = std::max(0.0, now - since);
  }
  return out;
}

std::string FormatCellTable(const std::vector<db::CellInfo>& cells,
                            const std::vector<CellActivity>& activity, double now, bool all) {
  std::string out;
  char line[512];
  std::snprintf(line, sizeof line, "\n%-16s %-12s %-10s %-8s %-8s %-9s %-21s %s\n", "cell",
                "health", "backend", "phase", "trial", "in phase", "last seen",
                "failures in a row");
  out += line;
  int folded = 0;
  for (size_t k = 0; k < cells.size(); ++k) {
    const auto& c = cells[k];
    const auto& a = activity[k];
    if (!all && c.state == db::CellState::kGone && now - c.last_seen > kGoneFoldS) {
      ++folded;
      continue;
    }
    const bool busy = a.trial_id != 0;
    std::snprintf(line, sizeof line, "%-16s %-12s %-10s %-8s %-8s %-9s %-21s %d%s%s\n",
                  c.id.c_str(), db::ToString(c.state), a.backend.empty() ? "-" : a.backend.c_str(),
                  busy                                 ? a.phase.c_str()
                  : c.state == db::CellState::kHealthy ? "idle"
                                                       : "-",
                  busy ? std::to_string(a.trial_id).c_str() : "-",
                  busy ? FormatDuration(a.in_phase_s).c_str() : "-", IsoTime(c.last_seen).c_str(),
                  c.consecutive_failures, c.quarantine_reason.empty() ? "" : "  ",
                  c.quarantine_reason.c_str());
    out += line;
  }
  if (folded > 0)
    out += std::to_string(folded) + (folded == 1 ? " cell" : " cells") +
           " gone for more than a day (arena status --all lists them)\n";
  return out;
}

}  // namespace arena::cli
