// Sensitivity runs (arena/db/sensitivity.hpp): migration 8's two tables.
#include "arena/db/sensitivity.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

#include <nlohmann/json.hpp>

#include "arena/db/query.hpp"
#include "sqlite_util.hpp"

namespace arena::db {
namespace {

constexpr const char* kColumns =
    "condition, params_json, replicates, ensemble, ensemble_failed, predicted_position_spread, "
    "observed_position_spread, predicted_rotation_spread, observed_rotation_spread, "
    "predicted_displacement, observed_displacement, predicted_rotation, observed_rotation, "
    "verdict, flip_fraction, unstable, boundary_parameter, boundary_offset, boundary_tolerances, "
    "reason, detail_json";

using detail::BadInput;

void CheckJson(const std::string& text, const std::string& what) {
  try {
    if (!nlohmann::json::parse(text).is_object()) BadInput(what + " must be a JSON object");
  } catch (const nlohmann::json::out_of_range& e) {  // 1e999: valid JSON, no double holds it
    BadInput(what + " holds a number out of range (beyond a double): " + e.what());
  } catch (const nlohmann::json::exception& e) {
    BadInput(what + " is not valid JSON: " + e.what());
  }
}

void CheckNumber(std::optional<double> v, const std::string& what) {
  if (v && !std::isfinite(*v)) BadInput(what + " is not finite");
}

SensitivityCondition ReadRow(const detail::Stmt& s) {
  SensitivityCondition c;
  int k = 0;
  c.condition = static_cast<int>(s.Int(k++));
  c.params_json = s.Text(k++);
  c.replicates = static_cast<int>(s.Int(k++));
  c.ensemble = static_cast<int>(s.Int(k++));
  c.ensemble_failed = static_cast<int>(s.Int(k++));
  c.predicted_position_spread = s.OptReal(k++);
  c.observed_position_spread = s.OptReal(k++);
  c.predicted_rotation_spread = s.OptReal(k++);
  c.observed_rotation_spread = s.OptReal(k++);
  c.predicted_displacement = s.OptReal(k++);
  c.observed_displacement = s.OptReal(k++);
  c.predicted_rotation = s.OptReal(k++);
  c.observed_rotation = s.OptReal(k++);
  c.verdict = s.Text(k++);
  c.flip_fraction = s.Real(k++);
  c.unstable = s.Int(k++) != 0;
  c.boundary_parameter = s.Text(k++);
  c.boundary_offset = s.OptReal(k++);
  c.boundary_tolerances = s.OptReal(k++);
  c.reason = s.Text(k++);
  c.detail_json = s.Text(k++);
  return c;
}

}  // namespace

std::int64_t RecordSensitivityRun(Store& store, std::int64_t campaign_id,
                                  const std::string& settings_json, const std::string& report_json,
                                  const std::vector<SensitivityCondition>& conditions) {
  auto& impl = store.impl();
  impl.RequireWritable("RecordSensitivityRun");
  CheckJson(settings_json, "RecordSensitivityRun: settings_json");
  CheckJson(report_json, "RecordSensitivityRun: report_json");
  std::set<int> seen;
  for (const auto& c : conditions) {
    const std::string at = "RecordSensitivityRun: condition " + std::to_string(c.condition) + ": ";
    if (c.condition < 0 || c.replicates < 0 || c.ensemble < 0 || c.ensemble_failed < 0) {
      BadInput(at + "counts and the condition index must be >= 0");
    }
    if (!seen.insert(c.condition).second) BadInput(at + "appears twice");
    CheckJson(c.params_json, at + "params_json");
    CheckJson(c.detail_json, at + "detail_json");
    for (auto [v, name] : {std::pair{c.predicted_position_spread, "predicted_position_spread"},
                           {c.observed_position_spread, "observed_position_spread"},
                           {c.predicted_rotation_spread, "predicted_rotation_spread"},
                           {c.observed_rotation_spread, "observed_rotation_spread"},
                           {c.predicted_displacement, "predicted_displacement"},
                           {c.observed_displacement, "observed_displacement"},
                           {c.predicted_rotation, "predicted_rotation"},
                           {c.observed_rotation, "observed_rotation"},
                           {c.boundary_offset, "boundary_offset"},
                           {c.boundary_tolerances, "boundary_tolerances"},
                           {std::optional<double>(c.flip_fraction), "flip_fraction"}}) {
      CheckNumber(v, at + name);
    }
  }
  detail::Tx tx(impl.db, true);
  {
    detail::Stmt s(impl.db, "SELECT 1 FROM campaigns WHERE id = ?");
    s.Bind(1, campaign_id);
    if (!s.Step()) {
      throw StoreError(StoreError::Kind::kNotFound,
                       "RecordSensitivityRun: no campaign " + std::to_string(campaign_id));
    }
  }
  detail::Stmt run(impl.db,
                   "INSERT INTO sensitivity_runs(campaign_id, created_at, settings_json, "
                   "report_json) VALUES(?,?,?,?)");
  run.Bind(1, campaign_id).Bind(2, impl.Now()).Bind(3, settings_json).Bind(4, report_json).Run();
  const std::int64_t id = sqlite3_last_insert_rowid(impl.db);
  detail::Stmt ins(impl.db, std::string("INSERT INTO sensitivity_conditions(run_id, ") + kColumns +
                                ") VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
  for (const auto& c : conditions) {
    ins.Reset();
    ins.Bind(1, id)
        .Bind(2, c.condition)
        .Bind(3, c.params_json)
        .Bind(4, c.replicates)
        .Bind(5, c.ensemble)
        .Bind(6, c.ensemble_failed)
        .Bind(7, c.predicted_position_spread)
        .Bind(8, c.observed_position_spread)
        .Bind(9, c.predicted_rotation_spread)
        .Bind(10, c.observed_rotation_spread)
        .Bind(11, c.predicted_displacement)
        .Bind(12, c.observed_displacement)
        .Bind(13, c.predicted_rotation)
        .Bind(14, c.observed_rotation)
        .Bind(15, c.verdict)
        .Bind(16, c.flip_fraction)
        .Bind(17, c.unstable ? 1 : 0)
        .Bind(18, c.boundary_parameter)
        .Bind(19, c.boundary_offset)
        .Bind(20, c.boundary_tolerances)
        .Bind(21, c.reason)
        .Bind(22, c.detail_json);
    ins.Run();
  }
  tx.Commit();
  return id;
}

std::vector<SensitivityRun> ListSensitivityRuns(const Store& store, std::int64_t campaign_id) {
  detail::Stmt s(store.impl().db,
                 "SELECT id, campaign_id, created_at, settings_json, report_json FROM "
                 "sensitivity_runs WHERE campaign_id = ? ORDER BY id");
  s.Bind(1, campaign_id);
  std::vector<SensitivityRun> out;
  while (s.Step()) {
    out.push_back({s.Int(0), s.Int(1), s.Real(2), s.Text(3), s.Text(4)});
  }
  return out;
}

std::vector<SensitivityCondition> ListSensitivityConditions(const Store& store,
                                                            std::int64_t run_id) {
  {
    detail::Stmt s(store.impl().db, "SELECT 1 FROM sensitivity_runs WHERE id = ?");
    s.Bind(1, run_id);
    if (!s.Step()) {
      throw StoreError(StoreError::Kind::kNotFound,
                       "ListSensitivityConditions: no sensitivity run " + std::to_string(run_id));
    }
  }
  detail::Stmt s(store.impl().db, std::string("SELECT ") + kColumns +
                                      " FROM sensitivity_conditions WHERE run_id = ? ORDER BY "
                                      "condition");
  s.Bind(1, run_id);
  std::vector<SensitivityCondition> out;
  while (s.Step()) out.push_back(ReadRow(s));
  return out;
}

std::map<std::int64_t, std::string> AppliedDefectProfiles(const Store& store,
                                                          std::int64_t campaign_id) {
  detail::Stmt s(store.impl().db,
                 "SELECT id, json_set(json_extract(defects_applied, '$.effective'), '$.emulated', "
                 "json(CASE json_type(defects_applied, '$.emulated') WHEN 'false' THEN 'false' "
                 "ELSE 'true' END)), cell_defects_json FROM trials WHERE campaign_id = ?");
  s.Bind(1, campaign_id);
  std::map<std::int64_t, std::string> out;
  while (s.Step()) {
    if (!s.IsNull(1)) {
      out[s.Int(0)] = s.Text(1);
    } else if (!s.IsNull(2)) {
      out[s.Int(0)] = s.Text(2);
    }
  }
  return out;
}

std::string WriteSensitivityExport(const Store& store, std::int64_t campaign_id,
                                   const std::string& dir) {
  const auto runs = ListSensitivityRuns(store, campaign_id);
  if (runs.empty()) return "";
  QueryResult table;
  detail::Stmt s(store.impl().db,
                 std::string("SELECT run_id, ") + kColumns +
                     " FROM sensitivity_conditions WHERE run_id = ? ORDER BY condition");
  s.Bind(1, runs.back().id);
  const int ncol = sqlite3_column_count(s.get());
  for (int c = 0; c < ncol; ++c) table.columns.emplace_back(sqlite3_column_name(s.get(), c));
  while (s.Step()) {
    std::vector<Value> row;
    for (int c = 0; c < ncol; ++c) {
      switch (sqlite3_column_type(s.get(), c)) {
        case SQLITE_NULL:
          row.emplace_back(std::monostate{});
          break;
        case SQLITE_INTEGER:
          row.emplace_back(s.Int(c));
          break;
        case SQLITE_FLOAT:
          row.emplace_back(s.Real(c));
          break;
        default:
          row.emplace_back(s.Text(c));
      }
    }
    table.rows.push_back(std::move(row));
  }
  const std::string name = "sensitivity.csv";
  const auto path = std::filesystem::path(dir) / name;
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << FormatCsv(table);
  f.close();
  if (!f) {
    throw StoreError(StoreError::Kind::kIo, "export: cannot write '" + path.string() + "'");
  }
  return name;
}

}  // namespace arena::db
