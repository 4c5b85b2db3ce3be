// Why a campaign's trials failed, were retried, or were not predicted: the
// reasons the store's transitions and predictions hold, grouped so that an
// operator reads "18 x cell: ..." instead of finding it in the log (issue 26).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"

namespace arena::cli {

struct ReasonGroup {
  std::string source;   // "cell", "driver", "predictor", "service"
  std::string example;  // one reason of the group, verbatim
  std::int64_t count = 0;
  std::int64_t first_trial = 0;  // the lowest trial id with this reason
};

struct FailureReport {
  std::vector<ReasonGroup> failures;     // trials that ended failed (their last reason)
  std::vector<ReasonGroup> retries;      // attempts that were retried
  std::vector<ReasonGroup> predictions;  // predictions that did not give a result
  std::int64_t failed_trials = 0, retried_attempts = 0, failed_predictions = 0;
};

// Who a reason blames: the robot driver (an exec: backend), the cell, or the
// service itself (timeouts, restarts). Predictions are the predictor's.
std::string ReasonSource(const std::string& reason);

// The grouping key: cell ids and numbers replaced, so "cell sim1-3fa2c1:
// ... 500 s" and "cell sim2-3fa2c1: ... 480 s" are one reason.
std::string ReasonKey(const std::string& reason, const std::string& cell_id);

// Reads the store (opened read-only). Groups are ordered by count, largest first.
FailureReport CampaignFailures(const db::Store& store, std::int64_t campaign_id);

// "  failures    18 of 36 trials, by reason:\n    18  cell: ..." lines for
// the run summary and `arena status`; "" when nothing failed or was retried.
std::string FormatFailures(const FailureReport& report, const std::string& indent);

// {"failed": [{"source", "reason", "count", "first_trial"}], "retried": [...], "predictions":
// [...]}
nlohmann::json FailuresJson(const FailureReport& report);

}  // namespace arena::cli
