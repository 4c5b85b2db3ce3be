// arena query --db FILE ["SQL"] [--campaign ID] [--where EXPR] [--outcome X]
//              [--format table|csv|json]
// Read-only SQL over the store; tables and columns are in db/README.md.
#include <cmath>
#include <cstdio>
#include <string>

#include "arena/db/query.hpp"
#include "arena/db/store.hpp"
#include "boundary_report.hpp"
#include "commands.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

struct QueryOptions {
  std::string db_path;
  std::string sql;
  std::int64_t campaign = -1;
  std::string where;
  std::string outcome;
  std::string format = "table";
  bool decisions = false;
  double timeout_s = 60;
};

// Why each trial of an adaptive campaign was chosen (view trial_decisions).
constexpr const char* kDecisionsQuery =
    "SELECT trial_id, campaign_id, idx, round, state, params_json, reason FROM trial_decisions"
    " ORDER BY trial_id";

int RunQueryCommand(const QueryOptions& o) {
  try {
    db::StoreOptions so;
    so.read_only = true;
    auto store = db::Store::Open(o.db_path, so);
    db::QueryFilter filter;
    if (o.campaign >= 0) {
      // An unknown campaign is refused like every other command does, not an empty table.
      try {
        (void)store->GetCampaign(o.campaign);
      } catch (const db::StoreError& e) {
        if (e.kind() != db::StoreError::Kind::kNotFound) throw;
        throw CommandError(kExitBadInput, "no campaign " + std::to_string(o.campaign) + " in " +
                                              o.db_path + " (see `arena list --db " + o.db_path +
                                              "`)");
      }
      filter.campaign_id = o.campaign;
    }
    filter.where = o.where;
    filter.outcome = o.outcome;
    if (o.decisions && !o.sql.empty())
      throw CommandError(kExitBadInput, "--decisions: give either SQL or --decisions, not both");
    if (!std::isfinite(o.timeout_s) || o.timeout_s <= 0)
      throw CommandError(kExitBadInput, "--timeout: must be a number of seconds > 0");
    db::QueryLimits limits;
    limits.max_seconds = o.timeout_s;
    const auto result = db::RunQuery(*store, o.decisions ? kDecisionsQuery : o.sql, filter, limits);
    const std::string text = o.format == "csv"    ? db::FormatCsv(result)
                             : o.format == "json" ? db::FormatJson(result)
                                                  : db::FormatTable(result);
    std::fwrite(text.data(), 1, text.size(), stdout);
    // The decisions' conclusion: the boundary found so far, in the
    // parameters' units (after the table; on stderr for csv/json output).
    if (o.decisions && o.campaign > 0) {
      if (const auto b = FindBoundary(*store, o.campaign)) {
        const std::string statement = FormatBoundary(*b, "");
        std::fputs(statement.c_str(), o.format == "table" ? stdout : stderr);
      }
    }
    return kExitOk;
  } catch (const db::StoreError& e) {
    // A query that would write is the user's input, not a broken store.
    if (e.kind() == db::StoreError::Kind::kReadOnly)
      throw CommandError(kExitBadInput, UserMessage(e.what()));
    throw StoreCommandError(e);
  }
}

}  // namespace

void AddQueryCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<QueryOptions>();
  auto* cmd = app.add_subcommand("query", "Run a read-only SQL query over the store");
  cmd->add_option("--db", o->db_path, "Store file")->required();
  cmd->add_option("sql", o->sql,
                  "One SELECT statement (default: every trial with its ground-truth summary, "
                  "from the view trial_results)");
  cmd->add_option("--campaign", o->campaign, "Only rows whose campaign_id is ID")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--where", o->where,
                  "An SQL condition on the result's columns, e.g. 'grip_force > 5'");
  cmd->add_option("--outcome", o->outcome,
                  "Only rows whose outcome is X (ok, failed, refused, ...)");
  cmd->add_flag("--decisions", o->decisions,
                "Why each trial of an adaptive campaign was chosen (round, rule, evidence; "
                "view trial_decisions)");
  cmd->add_option("--timeout", o->timeout_s, "Stop a query running longer than this (s)")
      ->capture_default_str();
  cmd->add_option("--format", o->format, "Output format")
      ->check(CLI::IsMember({"table", "csv", "json"}))
      ->capture_default_str();
  cmd->footer(
      "Examples:\n"
      "  arena query --db lab.db --campaign 1 --where 'grip_force > 5' --format csv\n"
      "  arena query --db lab.db \"SELECT cell_id, COUNT(*) FROM trials GROUP BY cell_id\"\n"
      "  arena query --db lab.db \"SELECT * FROM start_state_drift\"\n"
      "  arena query --db lab.db --campaign 2 --where 'pivot_offset > 0'\n"
      "  arena query --db lab.db \"SELECT grip_force, AVG(slip_distance_m) FROM contact_results\n"
      "                          WHERE role = 'finger' GROUP BY grip_force\"\n"
      "Every varied parameter of a campaign is a column of trial_results and contact_results.\n"
      "  arena query --db lab.db --campaign 2 --decisions\n"
      "The store is opened read-only: a statement that would write is refused (exit 2).\n"
      "Tables and columns: db/README.md.\n");
  cmd->callback([o, action] { *action = [o] { return RunQueryCommand(*o); }; });
}

}  // namespace arena::cli
