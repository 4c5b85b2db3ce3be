#include "deadline_report.hpp"

#include <algorithm>
#include <cstdio>
#include <variant>
#include <vector>

#include "arena/db/query.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::cli {
namespace {

std::optional<double> Real(const db::Value& v) {
  if (const auto* d = std::get_if<double>(&v)) return *d;
  if (const auto* i = std::get_if<std::int64_t>(&v)) return static_cast<double>(*i);
  return std::nullopt;
}

std::string Ms(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3g ms", v);
  return b;
}

}  // namespace

DeadlineReport CampaignDeadlines(const db::Store& store, std::int64_t campaign_id) {
  DeadlineReport r;
  r.period_ms = 1e3 / mechanics::kSampleRateHz;
  db::QueryFilter filter;
  filter.campaign_id = campaign_id;
  db::QueryResult rows;
  try {
    rows = db::RunQuery(
        store,
        "SELECT t.campaign_id, r.held, r.loop_p50_ms, r.loop_p99_ms, "
        "(SELECT count(*) FROM closed_loop_commands c WHERE c.trial_id = r.trial_id AND "
        "c.attempt = r.attempt) "
        "FROM closed_loop_runs r JOIN trials t ON t.id = r.trial_id",
        filter);
  } catch (const db::StoreError&) {
    return r;  // a store from before closed loops: none
  }
  std::vector<double> p50s;
  for (const auto& row : rows.rows) {
    const std::int64_t held = static_cast<std::int64_t>(Real(row[1]).value_or(0));
    const auto p50 = Real(row[2]), p99 = Real(row[3]);
    const std::int64_t commands = static_cast<std::int64_t>(Real(row[4]).value_or(0));
    r.min_held = r.runs == 0 ? held : std::min(r.min_held, held);
    r.max_held = std::max(r.max_held, held);
    ++r.runs;
    r.held += held;
    r.samples += commands;
    if (p50) p50s.push_back(*p50);
    if (p99) r.worst_p99_ms = std::max(r.worst_p99_ms.value_or(0), *p99);
    const bool late = p99 && *p99 > r.period_ms;
    r.runs_late += late;
    if (held > 0 || late) ++r.runs_missing;
  }
  if (!p50s.empty()) {
    std::sort(p50s.begin(), p50s.end());
    r.p50_ms = p50s[p50s.size() / 2];
  }
  return r;
}

// Both ways to miss a deadline are counted apart: a held sample (the cell
// had no fresh command) and a loop slower than the period at its p99 (late
// commands, none held when the cell waits for them).
std::string FormatDeadlines(const DeadlineReport& r, const std::string& indent) {
  if (r.runs == 0) return "";
  std::string out =
      indent + "closed loop: " + std::to_string(r.runs_missing) + " of " + std::to_string(r.runs) +
      " trial attempts missed control deadlines: " + std::to_string(r.held) + " of " +
      std::to_string(r.samples) + " samples held (" + std::to_string(r.min_held) + "-" +
      std::to_string(r.max_held) + " per attempt); " + std::to_string(r.runs_late) +
      " with loop latency p99 above the " + Ms(r.period_ms) + " period";
  if (r.worst_p99_ms) out += " (p99 up to " + Ms(*r.worst_p99_ms) + ")";
  if (r.p50_ms) out += ", loop latency p50 " + Ms(*r.p50_ms);
  out += "\n";
  return out;
}

nlohmann::json DeadlinesJson(const DeadlineReport& r) {
  return {{"attempts", r.runs},
          {"attempts_missing_deadlines", r.runs_missing},
          {"attempts_late", r.runs_late},
          {"samples", r.samples},
          {"held_samples", r.held},
          {"held_per_attempt_min", r.min_held},
          {"held_per_attempt_max", r.max_held},
          {"loop_p50_s", r.p50_ms ? nlohmann::json(*r.p50_ms * 1e-3) : nlohmann::json()},
          {"loop_p99_max_s",
           r.worst_p99_ms ? nlohmann::json(*r.worst_p99_ms * 1e-3) : nlohmann::json()},
          {"period_s", r.period_ms * 1e-3}};
}

std::string DeadlineCaption(const db::ClosedLoopRun& run) {
  std::string out = "closed loop: " + std::to_string(run.held) + " of " +
                    std::to_string(run.commands.size()) + " samples held";
  if (run.loop_p50_ms) out += ", loop p50 " + Ms(*run.loop_p50_ms);
  if (run.loop_p99_ms) out += ", p99 " + Ms(*run.loop_p99_ms);
  out += " (period " + Ms(1e3 / mechanics::kSampleRateHz) + ")";
  return out;
}

}  // namespace arena::cli
