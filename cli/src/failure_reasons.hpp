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

// A group is one typed kind of failure: the rule that decided the
// transition (trial_transitions.rule, e.g. "execute.cell_failure") or the
// prediction's status ("solver_failure"); the reason text is its detail.
// Rows stored before rules were (rule '') are grouped by their text.
struct ReasonGroup {
  std::string source;   // "cell", "driver", "controller", "service", "store", "scene", ...
  std::string kind;     // the rule or prediction status ("" for a row without one)
  std::string label;    // what the kind means, in words
  std::string example;  // one reason of the group, verbatim
  std::int64_t count = 0;
  std::int64_t first_trial = 0;  // the lowest trial id with this reason
  std::int64_t texts = 0;        // distinct reasons (numbers and cell ids aside) in the group
};

struct FailureReport {
  std::vector<ReasonGroup> failures;     // trials that ended failed (their last reason)
  std::vector<ReasonGroup> retries;      // attempts that were retried
  std::vector<ReasonGroup> predictions;  // predictions that did not give a result
  std::int64_t failed_trials = 0, retried_attempts = 0, failed_predictions = 0;
};

// Who a reason blames: the robot driver (an exec: backend), the cell, or the
// service itself (timeouts, restarts). Predictions are the predictor's.
// For rows without a rule only (read from the text).
std::string ReasonSource(const std::string& reason);

// The typed kind of a transition: the first rule its row names ("execute.cell_failure
// retry.attempts_exhausted" -> "execute.cell_failure"), who it blames (an exec: backend's
// failure is the driver's) and what it means. source "" for an unknown rule.
struct FailureKind {
  std::string kind, source, label;
};
FailureKind KindOfRule(const std::string& rule, const std::string& backend);

// The grouping key: cell ids and numbers replaced, so "cell sim1-3fa2c1:
// ... 500 s" and "cell sim2-3fa2c1: ... 480 s" are one reason.
std::string ReasonKey(const std::string& reason, const std::string& cell_id);

// Reads the store (opened read-only). Groups are ordered by count, largest first.
FailureReport CampaignFailures(const db::Store& store, std::int64_t campaign_id);

// "  failures    18 of 36 trials, by reason:\n    18  cell: ..." lines for
// the run summary and `arena status`; "" when nothing failed or was retried.
std::string FormatFailures(const FailureReport& report, const std::string& indent);

// {"failed": [{"source", "kind", "label", "reason", "count", "first_trial", "texts"}],
// "retried": [...], "predictions": [...]}
nlohmann::json FailuresJson(const FailureReport& report);

}  // namespace arena::cli
