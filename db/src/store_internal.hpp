// Helpers shared by the store's translation units (private).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "sqlite_util.hpp"

namespace arena::db::internal {

// Angle between two quaternions (w, x, y, z; rad, in [0, pi]); 0 when
// either is zero.
inline double QuatAngle(const double* a, const double* b) {
  const double na = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3]);
  const double nb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2] + b[3] * b[3]);
  if (na == 0 || nb == 0) return 0;
  const double d = std::abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]) / (na * nb);
  return 2 * std::acos(std::min(1.0, d));
}

struct TrialRow {
  TrialState state = TrialState::kPlanned;
  int attempt = 1;
  std::string cell_id;
  std::int64_t campaign_id = 0;
  std::optional<std::int64_t> gt_stream_id;
};

// @throws kNotFound naming `function`.
TrialRow LoadTrialRow(const Store::Impl& impl, std::int64_t trial_id, const char* function);
// @throws kStaleAttempt unless row.attempt == attempt.
void CheckAttempt(const TrialRow& row, std::int64_t trial_id, int attempt, const char* function);
// @throws kIllegalTransition unless IsLegalTransition(from, to).
void CheckEdge(TrialState from, TrialState to, std::int64_t trial_id, const char* function);
// Checks the edge, updates trials.state and appends the audit row with the
// name of the rule that decided it. Call inside a write transaction.
void WriteTransition(const Store::Impl& impl, std::int64_t trial_id, int attempt, TrialState from,
                     TrialState to, const std::string& cell_id, const std::string& reason,
                     std::string_view rule, const char* function);

// Store::RecordExecution's and Store::BeginReset's writes without a
// transaction of their own (Ingest::Finish joins them to its own).
void WriteExecution(const Store::Impl& impl, std::int64_t trial_id, int attempt,
                    const ExecutionRecord& record, const char* function);
void WriteBeginReset(const Store::Impl& impl, std::int64_t trial_id, int attempt,
                     std::string_view rule, const char* function);

// Inserts an active campaign's row (fields checked, kBadInput naming
// `function`); no transaction of its own. @returns its id.
std::int64_t InsertCampaignRow(const Store::Impl& impl, const NewCampaign& campaign,
                               const char* function);

// Inserts planned trials with indices first_index.. and their audit rows;
// no transaction of its own. @returns their ids. @throws kBadInput naming `function`.
std::vector<std::int64_t> InsertPlannedTrials(const Store::Impl& impl, std::int64_t campaign_id,
                                              int first_index,
                                              const std::vector<PlannedTrial>& trials,
                                              const char* function);

// The samples of one stream, in order; no transaction of its own (the caller's
// read transaction gives the snapshot). @throws kCorrupt on a count mismatch.
std::vector<Sample> ReadStreamSamples(const Store::Impl& impl, std::int64_t stream_id,
                                      std::int64_t expected, const char* function);

}  // namespace arena::db::internal

namespace arena::db {
struct TrialOutcome;
}

namespace arena::db::internal {
// Parameter columns of the result views (result_views.cpp): the names
// campaigns varied, as registered in campaign_parameters.
std::vector<std::string> ParameterColumns(sqlite3* db);
// A name that may become a view column (an identifier not already a column).
bool IsParameterColumnName(const std::string& name);
// Recreates trial_results and contact_results with one column per parameter.
void RebuildResultViews(sqlite3* db);
// Records the parameter names of a campaign's trials; rebuilds the views if
// one is new. Call inside the write transaction that inserted the trials.
void RegisterParameters(const Store::Impl& impl, std::int64_t campaign_id);
// Stores a stream's outcome (contact_outcomes rows, gt_summary net_* and
// grasp_kept). Call inside a write transaction, after gt_summary's row exists.
void WriteOutcome(const Store::Impl& impl, std::int64_t stream_id, std::int64_t trial_id,
                  int attempt, const TrialOutcome& outcome);
// Schema version 6: outcomes of the streams already stored, then the views.
void MigrateToOutcomes(const Store::Impl& impl);
}  // namespace arena::db::internal

namespace arena::db {
// Block codec pieces (sample.cpp) used by the ingest to encode as samples arrive.
void EncodeSampleBody(const Sample& s, std::string* out);
void EncodeBlockHeader(std::uint32_t count, std::string* out);
// Sets the sample count of a block that started with EncodeBlockHeader(0, ...).
void PatchBlockCount(std::uint32_t count, std::string* block);
}  // namespace arena::db
