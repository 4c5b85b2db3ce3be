#include "sqlite_util.hpp"

#include <chrono>
#include <filesystem>

namespace arena::db::detail {

// Said when a write meets a read-only store: what may be wrong, not which
// command to run (a read-only command never writes; the error means the
// store or its directory is write-protected for a command that must write).
constexpr const char* kReadOnlyHint =
    " (the store is read-only here: commands that change it, such as submit, pause or serve, "
    "need write access to the store file and its directory)";

StoreError::Kind KindOf(int rc) {
  switch (rc & 0xff) {
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
      return StoreError::Kind::kBusy;
    case SQLITE_READONLY:
      return StoreError::Kind::kReadOnly;
    case SQLITE_FULL:
      return StoreError::Kind::kFull;
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
      return StoreError::Kind::kCorrupt;
    case SQLITE_CONSTRAINT:
    case SQLITE_MISMATCH:
    case SQLITE_TOOBIG:
    case SQLITE_RANGE:
    case SQLITE_ERROR:
      return StoreError::Kind::kBadInput;
    default:
      return StoreError::Kind::kIo;
  }
}

void Throw(sqlite3* db, int rc, const std::string& context) {
  std::string msg = context + ": " + (db ? sqlite3_errmsg(db) : sqlite3_errstr(rc));
  const auto kind = KindOf(rc);
  if (kind == StoreError::Kind::kReadOnly) {
    msg += kReadOnlyHint;
  } else if (kind == StoreError::Kind::kFull) {
    msg += " (free disk space, then restart; nothing of this write was stored)";
  } else if (kind == StoreError::Kind::kBusy) {
    msg += " (another process holds the write lock; retry)";
  }
  throw StoreError(kind, msg);
}

Stmt::Stmt(sqlite3* db, std::string_view sql, bool persistent) : db_(db), sql_(sql) {
  const int rc = sqlite3_prepare_v3(db, sql.data(), static_cast<int>(sql.size()),
                                    persistent ? SQLITE_PREPARE_PERSISTENT : 0, &s_, nullptr);
  if (rc != SQLITE_OK) Throw(db, rc, "prepare '" + sql_.substr(0, 60) + "'");
}

Stmt::~Stmt() { sqlite3_finalize(s_); }

#define ARENA_BIND_CHECK(expr)                                          \
  do {                                                                  \
    const int rc_ = (expr);                                             \
    if (rc_ != SQLITE_OK) Throw(db_, rc_, "bind " + std::to_string(i)); \
  } while (0)

Stmt& Stmt::Bind(int i, std::int64_t v) {
  ARENA_BIND_CHECK(sqlite3_bind_int64(s_, i, v));
  return *this;
}
Stmt& Stmt::Bind(int i, double v) {
  ARENA_BIND_CHECK(sqlite3_bind_double(s_, i, v));
  return *this;
}
Stmt& Stmt::Bind(int i, std::string_view v) {
  ARENA_BIND_CHECK(
      sqlite3_bind_text(s_, i, v.data(), static_cast<int>(v.size()), SQLITE_TRANSIENT));
  return *this;
}
Stmt& Stmt::Bind(int i, std::optional<double> v) { return v ? Bind(i, *v) : BindNull(i); }
Stmt& Stmt::BindNull(int i) {
  ARENA_BIND_CHECK(sqlite3_bind_null(s_, i));
  return *this;
}
Stmt& Stmt::BindBlob(int i, const void* data, std::size_t size) {
  ARENA_BIND_CHECK(sqlite3_bind_blob64(s_, i, data, size, SQLITE_STATIC));
  return *this;
}

bool Stmt::Step() {
  const int rc = sqlite3_step(s_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  Throw(db_, rc, "'" + sql_.substr(0, 60) + "'");
}

void Stmt::Reset() {
  sqlite3_reset(s_);
  sqlite3_clear_bindings(s_);
}

std::string Stmt::Text(int col) const {
  const auto* p = sqlite3_column_text(s_, col);
  return p ? std::string(reinterpret_cast<const char*>(p), sqlite3_column_bytes(s_, col))
           : std::string();
}

Tx::Tx(sqlite3* db, bool immediate) : db_(db) {
  if (!immediate && sqlite3_get_autocommit(db) == 0) {
    joined_ = true;  // a reader inside the connection's open transaction
    return;
  }
  Exec(db, immediate ? "BEGIN IMMEDIATE" : "BEGIN", "begin transaction");
  open_ = true;
}

Tx::~Tx() {
  if (open_) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
}

void Tx::Commit() {
  if (joined_) return;  // the owner of the transaction ends it
  // Statements still positioned on a row would make COMMIT fail; they are done with.
  for (sqlite3_stmt* p = sqlite3_next_stmt(db_, nullptr); p; p = sqlite3_next_stmt(db_, p)) {
    if (sqlite3_stmt_busy(p)) sqlite3_reset(p);
  }
  Exec(db_, "COMMIT", "commit");
  open_ = false;
}

void Exec(sqlite3* db, const std::string& sql, const std::string& context) {
  char* err = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &err);
  if (rc != SQLITE_OK) {
    const std::string msg = err ? err : sqlite3_errstr(rc);
    sqlite3_free(err);
    StoreError::Kind kind = KindOf(rc);
    std::string full = context + ": " + msg;
    if (kind == StoreError::Kind::kReadOnly) {
      full += kReadOnlyHint;
    }
    throw StoreError(kind, full);
  }
}

}  // namespace arena::db::detail

namespace arena::db {

Store::Impl::~Impl() {
  cache.clear();  // finalize every statement before closing
  if (db) sqlite3_close_v2(db);
  if (!private_copy_dir.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(private_copy_dir, ec);
  }
}

detail::StmtRef Store::Impl::Prepare(std::string_view sql) const {
  auto it = cache.find(sql);
  if (it == cache.end()) {
    it = cache.emplace(std::string(sql), std::make_unique<detail::Stmt>(db, sql, true)).first;
  }
  return detail::StmtRef(it->second.get());
}

double Store::Impl::Now() const {
  if (options.clock) return options.clock();
  using namespace std::chrono;
  return duration<double>(system_clock::now().time_since_epoch()).count();
}

void Store::Impl::RequireWritable(const char* function) const {
  if (options.read_only) {
    throw StoreError(StoreError::Kind::kReadOnly,
                     std::string(function) + ": the store '" + path +
                         "' is open read-only; this command only reads");
  }
}

}  // namespace arena::db
