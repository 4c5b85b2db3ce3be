// Read-only queries and their output formats (query.hpp).
#include "arena/db/query.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>

#include "sqlite_util.hpp"

namespace arena::db {
namespace {

// Functions a query may not call, though SQLite offers them: fts3_tokenizer()
// returns a live code address and (two arguments) installs a pointer, a known
// attack primitive; fts5() hands out an API pointer; load_extension() runs a
// shared library; readfile/writefile/edit are the shell's file access. Every
// other function name SQLite ships only computes on its arguments. The
// prefixes catch what a newer SQLite adds to the same families.
bool DeniedFunction(const char* name) {
  if (!name) return true;
  std::string n(name);
  for (auto& c : n) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  static const char* kDenied[] = {"fts3_tokenizer", "fts5", "load_extension", "readfile",
                                  "writefile",      "edit", "lsmode",         "fts3_exprtest"};
  for (const char* d : kDenied)
    if (n == d) return true;
  // Internal and test hooks (sqlite_rename_*, fts3_*, fts5_* helpers); the
  // version functions are plain text.
  if (n.rfind("fts3", 0) == 0 || n.rfind("fts4", 0) == 0 || n.rfind("fts5", 0) == 0) return true;
  if (n.rfind("sqlite_", 0) == 0 && n != "sqlite_version" && n != "sqlite_source_id") return true;
  return false;
}

// Only reads pass: no ATTACH/DETACH (they would open other files), pragmas
// only from a list of pure queries, and no function of DeniedFunction().
int Authorizer(void*, int action, const char* a1, const char* a2, const char*, const char*) {
  switch (action) {
    case SQLITE_ATTACH:
    case SQLITE_DETACH:
      return SQLITE_DENY;
    case SQLITE_FUNCTION:  // a1: unused, a2: the function's name
      return DeniedFunction(a2) ? SQLITE_DENY : SQLITE_OK;
    case SQLITE_PRAGMA: {
      static const char* kAllowed[] = {"table_info",        "table_xinfo",     "index_list",
                                       "index_info",        "index_xinfo",     "table_list",
                                       "foreign_key_list",  "integrity_check", "quick_check",
                                       "foreign_key_check", "database_list",   "collation_list",
                                       "function_list"};
      for (const char* name : kAllowed) {
        if (a1 && std::strcmp(a1, name) == 0) return SQLITE_OK;
      }
      // Reading a setting (no argument) is fine; setting one is not.
      if (a1 && !a2 &&
          (std::strcmp(a1, "user_version") == 0 || std::strcmp(a1, "schema_version") == 0 ||
           std::strcmp(a1, "journal_mode") == 0 || std::strcmp(a1, "page_count") == 0 ||
           std::strcmp(a1, "page_size") == 0 || std::strcmp(a1, "freelist_count") == 0)) {
        return SQLITE_OK;
      }
      return SQLITE_DENY;
    }
    default:
      return SQLITE_OK;
  }
}

std::string Trim(const std::string& s) {
  std::size_t b = 0, e = s.size();
  while (b < e && (std::isspace(static_cast<unsigned char>(s[b])) || s[b] == ';')) ++b;
  while (e > b && (std::isspace(static_cast<unsigned char>(s[e - 1])) || s[e - 1] == ';')) --e;
  return s.substr(b, e - b);
}

// 6 significant digits, but never an exponent for a value a person reads
// whole: a timestamp (1795810000.125 s, not 1.79581e+09) keeps its
// integer part and milliseconds.
std::string ShortNumber(double v) {
  char buf[48];
  if (std::isfinite(v) && std::abs(v) >= 1e6 && std::abs(v) < 1e15) {
    std::snprintf(buf, sizeof buf, "%.3f", v);
    std::string s = buf;
    while (s.back() == '0') s.pop_back();
    if (s.back() == '.') s.pop_back();
    return s;
  }
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::string ExactNumber(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  // Prefer the shortest text that reads back as the same double.
  for (int p = 1; p <= 17; ++p) {
    char t[40];
    std::snprintf(t, sizeof t, "%.*g", p, v);
    if (std::strtod(t, nullptr) == v) return t;
  }
  return buf;
}

std::string Text(const Value& v, bool exact) {
  if (std::holds_alternative<std::monostate>(v)) return "";
  if (const auto* i = std::get_if<std::int64_t>(&v)) return std::to_string(*i);
  if (const auto* d = std::get_if<double>(&v)) return exact ? ExactNumber(*d) : ShortNumber(*d);
  return std::get<std::string>(v);
}

}  // namespace

std::string ComposeQuery(const std::string& sql, const QueryFilter& filter) {
  std::string base = Trim(sql);
  if (base.empty()) base = kDefaultQuery;
  std::vector<std::string> conds;
  if (filter.campaign_id) conds.push_back("campaign_id = ?1");
  if (!Trim(filter.where).empty()) conds.push_back("(" + filter.where + ")");
  if (!filter.outcome.empty()) conds.push_back("outcome = ?2");
  if (conds.empty()) return base;
  std::string out = "SELECT * FROM (" + base + ") WHERE ";
  for (std::size_t i = 0; i < conds.size(); ++i) {
    if (i) out.append(" AND ");
    out.append(conds[i]);
  }
  return out;
}

namespace {
struct Budget {
  std::chrono::steady_clock::time_point deadline;
  bool expired = false;
};
int OverBudget(void* p) {
  auto* b = static_cast<Budget*>(p);
  if (std::chrono::steady_clock::now() > b->deadline) b->expired = true;
  return b->expired ? 1 : 0;  // non-zero interrupts the statement (SQLITE_INTERRUPT)
}
}  // namespace

QueryResult RunQuery(const Store& store, const std::string& sql_in, const QueryFilter& filter,
                     const QueryLimits& limits) {
  if (!(limits.max_seconds > 0) || limits.max_rows < 1)
    throw StoreError(StoreError::Kind::kBadInput, "query: limits must be > 0");
  if (!store.read_only()) {
    throw StoreError(StoreError::Kind::kReadOnly,
                     "RunQuery: the store must be opened read-only for a query");
  }
  const std::string sql = ComposeQuery(sql_in, filter);
  sqlite3* db = store.impl().db;
  sqlite3_stmt* raw = nullptr;
  const char* tail = nullptr;
  sqlite3_set_authorizer(db, Authorizer, nullptr);
  const int rc = sqlite3_prepare_v2(db, sql.c_str(), static_cast<int>(sql.size()), &raw, &tail);
  sqlite3_set_authorizer(db, nullptr, nullptr);
  std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)> stmt(raw, sqlite3_finalize);
  if (rc != SQLITE_OK) {
    const std::string msg = sqlite3_errmsg(db);
    throw StoreError(
        StoreError::Kind::kBadInput,
        "query: " + msg +
            (rc == SQLITE_AUTH ? " (ATTACH, DETACH, settings pragmas and functions that "
                                 "touch memory or files are refused)"
                               : "") +
            "; tables and columns: db/README.md");
  }
  if (!stmt) throw StoreError(StoreError::Kind::kBadInput, "query: the SQL text is empty");
  if (tail && !Trim(tail).empty()) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "query: one statement at a time (found more after the first ';')");
  }
  if (!sqlite3_stmt_readonly(stmt.get())) {
    throw StoreError(StoreError::Kind::kReadOnly,
                     "query: refused, the statement would write; arena query only reads "
                     "(use arena pause/resume/cancel to change a campaign)");
  }
  const int params = sqlite3_bind_parameter_count(stmt.get());
  if (params >= 1 && filter.campaign_id) sqlite3_bind_int64(stmt.get(), 1, *filter.campaign_id);
  if (params >= 2 && !filter.outcome.empty()) {
    sqlite3_bind_text(stmt.get(), 2, filter.outcome.c_str(), -1, SQLITE_TRANSIENT);
  }
  QueryResult out;
  const int ncol = sqlite3_column_count(stmt.get());
  for (int c = 0; c < ncol; ++c) out.columns.emplace_back(sqlite3_column_name(stmt.get(), c));
  Budget budget{std::chrono::steady_clock::now() +
                std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                    std::chrono::duration<double>(std::min(limits.max_seconds, 1e7)))};
  sqlite3_progress_handler(db, 10000, OverBudget, &budget);
  struct Unset {
    sqlite3* db;
    ~Unset() { sqlite3_progress_handler(db, 0, nullptr, nullptr); }
  } unset{db};
  while (true) {
    const int step = sqlite3_step(stmt.get());
    if (step == SQLITE_DONE) break;
    if (step == SQLITE_INTERRUPT || budget.expired) {
      throw StoreError(StoreError::Kind::kBadInput,
                       "query: stopped after " + std::to_string(limits.max_seconds) +
                           " s (--timeout); a recursive CTE without a LIMIT, or a join that "
                           "needs one?");
    }
    if (step != SQLITE_ROW) {
      throw StoreError(detail::KindOf(step), std::string("query: ") + sqlite3_errmsg(db));
    }
    if (static_cast<std::int64_t>(out.rows.size()) >= limits.max_rows) {
      throw StoreError(StoreError::Kind::kBadInput, "query: more than " +
                                                        std::to_string(limits.max_rows) +
                                                        " rows; add a LIMIT or a --where");
    }
    std::vector<Value> row;
    row.reserve(static_cast<std::size_t>(ncol));
    for (int c = 0; c < ncol; ++c) {
      switch (sqlite3_column_type(stmt.get(), c)) {
        case SQLITE_NULL:
          row.emplace_back(std::monostate{});
          break;
        case SQLITE_INTEGER:
          row.emplace_back(static_cast<std::int64_t>(sqlite3_column_int64(stmt.get(), c)));
          break;
        case SQLITE_FLOAT:
          row.emplace_back(sqlite3_column_double(stmt.get(), c));
          break;
        case SQLITE_BLOB:
          row.emplace_back("<blob " + std::to_string(sqlite3_column_bytes(stmt.get(), c)) +
                           " bytes>");
          break;
        default: {
          const auto* p = sqlite3_column_text(stmt.get(), c);
          row.emplace_back(
              std::string(reinterpret_cast<const char*>(p), sqlite3_column_bytes(stmt.get(), c)));
        }
      }
    }
    out.rows.push_back(std::move(row));
  }
  return out;
}

std::string FormatTable(const QueryResult& r) {
  const std::size_t n = r.columns.size();
  std::vector<std::size_t> width(n);
  std::vector<bool> numeric(n, true);
  for (std::size_t c = 0; c < n; ++c) width[c] = r.columns[c].size();
  for (const auto& row : r.rows) {
    for (std::size_t c = 0; c < n; ++c) {
      width[c] = std::max(width[c], Text(row[c], false).size());
      if (std::holds_alternative<std::string>(row[c])) numeric[c] = false;
    }
  }
  auto cell = [&](const std::string& s, std::size_t c) {
    const std::string pad(width[c] - std::min(width[c], s.size()), ' ');
    return numeric[c] ? pad + s : s + pad;
  };
  std::string out;
  auto line = [&](auto&& text_of) {
    for (std::size_t c = 0; c < n; ++c) {
      if (c) out.append("  ");
      out.append(text_of(c));
    }
    out.push_back('\n');
  };
  line([&](std::size_t c) { return cell(r.columns[c], c); });
  line([&](std::size_t c) { return std::string(width[c], '-'); });
  for (const auto& row : r.rows) line([&](std::size_t c) { return cell(Text(row[c], false), c); });
  out += "(" + std::to_string(r.rows.size()) + (r.rows.size() == 1 ? " row)\n" : " rows)\n");
  return out;
}

std::string FormatCsv(const QueryResult& r) {
  auto quote = [](const std::string& s) {
    if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
    std::string q = "\"";
    for (char ch : s) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
    return q + "\"";
  };
  std::string out;
  for (std::size_t c = 0; c < r.columns.size(); ++c) {
    if (c) out.push_back(',');
    out.append(quote(r.columns[c]));
  }
  out.push_back('\n');
  for (const auto& row : r.rows) {
    for (std::size_t c = 0; c < row.size(); ++c) {
      if (c) out.push_back(',');
      out.append(quote(Text(row[c], true)));
    }
    out.push_back('\n');
  }
  return out;
}

std::string FormatJson(const QueryResult& r) {
  nlohmann::ordered_json rows = nlohmann::ordered_json::array();
  for (const auto& row : r.rows) {
    nlohmann::ordered_json o = nlohmann::ordered_json::object();
    for (std::size_t c = 0; c < row.size(); ++c) {
      const auto& v = row[c];
      if (std::holds_alternative<std::monostate>(v))
        o[r.columns[c]] = nullptr;
      else if (const auto* i = std::get_if<std::int64_t>(&v))
        o[r.columns[c]] = *i;
      else if (const auto* d = std::get_if<double>(&v))
        o[r.columns[c]] = *d;
      else
        o[r.columns[c]] = std::get<std::string>(v);
    }
    rows.push_back(std::move(o));
  }
  // Invalid UTF-8 in a TEXT column is replaced rather than aborting the output.
  return rows.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

}  // namespace arena::db
