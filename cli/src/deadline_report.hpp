// Closed-loop trials' missed control deadlines (issue 26): samples the cell
// held the last command for because no fresh answer came in time, and the
// loop's latency (live sample -> command accepted) against the 4 ms sample
// period. Read from closed_loop_runs / closed_loop_commands.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"

namespace arena::cli {

struct DeadlineReport {
  std::int64_t runs = 0;                    // closed-loop trial attempts with a record
  std::int64_t samples = 0;                 // samples the controller was asked to answer (all runs)
  std::int64_t held = 0;                    // of them, held (no fresh answer)
  std::int64_t runs_missing = 0;            // runs with a held sample or a p99 above the period
  std::int64_t runs_late = 0;               // of all runs, those with a p99 above the period
  std::int64_t min_held = 0, max_held = 0;  // per run
  std::optional<double> p50_ms;             // median over runs of their p50
  std::optional<double> worst_p99_ms;
  double period_ms = 4;  // one sample at 250 Hz
};

// Reads the store (opened read-only); runs == 0 for an open-loop campaign.
DeadlineReport CampaignDeadlines(const db::Store& store, std::int64_t campaign_id);

// "  closed loop: 8 of 9 trial attempts missed control deadlines: 0 of 3384
// samples held (0-0 per attempt); 8 with loop latency p99 above the 4 ms
// period (up to 6.91 ms), p50 0.268 ms" ("" when runs == 0).
std::string FormatDeadlines(const DeadlineReport& r, const std::string& indent);

nlohmann::json DeadlinesJson(const DeadlineReport& r);

// One trial attempt's line for its plot: "closed loop: 20 of 376 samples held,
// loop p50 0.8 ms, p99 5.2 ms (period 4 ms)".
std::string DeadlineCaption(const db::ClosedLoopRun& run);

}  // namespace arena::cli
