// Read-only SQL over the store (`arena query`) and its output formats.
//
// A query runs only on a store opened read-only and only if SQLite itself
// says the statement does not write (sqlite3_stmt_readonly); one statement
// per call; ATTACH/DETACH and pragmas that change settings are refused by an
// authorizer. Tables and columns: db/README.md.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "arena/db/store.hpp"

namespace arena::db {

// NULL, INTEGER, REAL, TEXT; a BLOB is shown as the text "<blob N bytes>".
using Value = std::variant<std::monostate, std::int64_t, double, std::string>;

struct QueryResult {
  std::vector<std::string> columns;
  std::vector<std::vector<Value>> rows;
};

// The filter shortcuts of `arena query`. Each one set adds a condition on the
// columns of the query's result (campaign_id, outcome); `where` is an SQL
// expression over those columns ("grip_force > 5").
struct QueryFilter {
  std::optional<std::int64_t> campaign_id;
  std::string where;
  std::string outcome;
};

// The default query when none is given: every trial with its summary.
inline constexpr const char* kDefaultQuery = "SELECT * FROM trial_results ORDER BY trial_id";

// Wraps `sql` (kDefaultQuery if empty) so the filter applies to its rows:
// SELECT * FROM (sql) WHERE campaign_id = ?1 AND (where) AND outcome = ?2.
// Values are bound, never spliced into the text. @returns the SQL.
std::string ComposeQuery(const std::string& sql, const QueryFilter& filter);

// Bounds on one query: a runaway statement (an infinite recursive CTE, a
// cross join of the sample tables) stops instead of running for ever.
struct QueryLimits {
  double max_seconds = 60;             // wall time (sqlite3_progress_handler)
  std::int64_t max_rows = 10'000'000;  // rows kept in memory
};

// Runs one read-only statement. Parameters ?1 and ?2 are bound to the
// filter's campaign id and outcome (see ComposeQuery).
// @throws StoreError(kReadOnly) if the store is not read-only or the statement
//   would write; kBadInput for SQL errors (message from SQLite), several
//   statements, a refused ATTACH/pragma, or a query past `limits`.
QueryResult RunQuery(const Store& store, const std::string& sql, const QueryFilter& filter = {},
                     const QueryLimits& limits = {});

// Output formats. Numbers: table with up to 6 significant digits; CSV and
// JSON with enough digits to round-trip a double exactly.
std::string FormatTable(const QueryResult& result);
std::string FormatCsv(const QueryResult& result);   // RFC 4180, header row, \n line ends
std::string FormatJson(const QueryResult& result);  // [{"column": value, ...}, ...]

}  // namespace arena::db
