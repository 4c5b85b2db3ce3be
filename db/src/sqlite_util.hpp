// Private RAII helpers over the SQLite C API (never included by a public header).
#pragma once

#include <sqlite3.h>

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <string_view>

#include "arena/db/store.hpp"

namespace arena::db::detail {

StoreError::Kind KindOf(int rc);
[[noreturn]] void Throw(sqlite3* db, int rc, const std::string& context);
// The store's refusal of a caller's bad value: kBadInput with `msg`.
[[noreturn]] inline void BadInput(const std::string& msg) {
  throw StoreError(StoreError::Kind::kBadInput, msg);
}

// One prepared statement. Bind indices start at 1, column indices at 0.
class Stmt {
 public:
  Stmt(sqlite3* db, std::string_view sql, bool persistent = false);
  ~Stmt();
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;

  Stmt& Bind(int i, std::int64_t v);
  Stmt& Bind(int i, int v) { return Bind(i, static_cast<std::int64_t>(v)); }
  Stmt& Bind(int i, double v);
  Stmt& Bind(int i, std::string_view v);
  Stmt& Bind(int i, const char* v) { return Bind(i, std::string_view(v)); }
  Stmt& Bind(int i, const std::string& v) { return Bind(i, std::string_view(v)); }
  Stmt& Bind(int i, std::optional<double> v);
  Stmt& BindNull(int i);
  Stmt& BindBlob(int i, const void* data, std::size_t size);

  // true: a row is ready; false: done. Throws StoreError on failure.
  bool Step();
  void Run() {
    while (Step()) {
    }
  }
  void Reset();

  std::int64_t Int(int col) const { return sqlite3_column_int64(s_, col); }
  double Real(int col) const { return sqlite3_column_double(s_, col); }
  bool IsNull(int col) const { return sqlite3_column_type(s_, col) == SQLITE_NULL; }
  std::string Text(int col) const;
  std::optional<double> OptReal(int col) const {
    return IsNull(col) ? std::nullopt : std::optional<double>(Real(col));
  }
  const void* Blob(int col) const { return sqlite3_column_blob(s_, col); }
  int Bytes(int col) const { return sqlite3_column_bytes(s_, col); }
  sqlite3_stmt* get() const { return s_; }

 private:
  sqlite3* db_;
  sqlite3_stmt* s_ = nullptr;
  std::string sql_;
};

// Binds consecutive parameters: Binder(s) << a << b; (left to right, C++17).
class Binder {
 public:
  explicit Binder(Stmt& s, int first = 1) : s_(s), k_(first) {}
  template <class T>
  Binder& operator<<(const T& v) {
    s_.Bind(k_++, v);
    return *this;
  }
  template <class T>
  Binder& operator<<(const std::optional<T>& v) {  // NULL when empty
    if (v)
      s_.Bind(k_++, *v);
    else
      s_.BindNull(k_++);
    return *this;
  }
  Binder& operator<<(std::nullopt_t) {
    s_.BindNull(k_++);
    return *this;
  }

 private:
  Stmt& s_;
  int k_;
};

// A statement from the connection's cache, reset and unbound on scope exit.
class StmtRef {
 public:
  explicit StmtRef(Stmt* s) : s_(s) {}
  ~StmtRef() {
    sqlite3_reset(s_->get());
    sqlite3_clear_bindings(s_->get());
  }
  Stmt* operator->() const { return s_; }
  Stmt& operator*() const { return *s_; }

 private:
  Stmt* s_;
};

// BEGIN IMMEDIATE (writers) or BEGIN (readers: one snapshot); rolls back
// unless Commit() was called. A reader inside a transaction already open on
// the connection joins it (it reads what that transaction sees, and leaves
// ending it to its owner): a write transaction may call the store's readers
// (Store::CreateAdaptiveCampaign's plan). A nested writer is an error.
class Tx {
 public:
  Tx(sqlite3* db, bool immediate);
  ~Tx();
  void Commit();

 private:
  sqlite3* db_;
  bool open_ = false;
  bool joined_ = false;
};

void Exec(sqlite3* db, const std::string& sql, const std::string& context);

}  // namespace arena::db::detail

namespace arena::db {

struct Store::Impl {
  sqlite3* db = nullptr;
  std::string path;
  StoreOptions options;
  // A private copy read instead of `path` (a read-only store whose
  // directory cannot be written, with an unmerged WAL); removed on close.
  std::string private_copy_dir;
  mutable std::map<std::string, std::unique_ptr<detail::Stmt>, std::less<>> cache;
  // The file opened (stat at open): CheckFileIdentity() notices it deleted,
  // renamed or replaced under us.
  unsigned long long file_dev = 0, file_ino = 0;
  Store::QuickCheckResult open_check;  // the read-write open's quick check
  // Store::RestrictClaimsTo: the campaigns this connection's claims may take
  // from (nullopt: every active one).
  std::optional<std::set<std::int64_t>> claimable;
  // StoreOptions::wal_checkpoint_due: the WAL sizes (frames) at which a
  // commit asks for a checkpoint, and at which it runs one itself.
  std::int64_t wal_due_frames = 0, wal_backstop_frames = 0;

  ~Impl();
  detail::StmtRef Prepare(std::string_view sql) const;
  double Now() const;
  void RequireWritable(const char* function) const;
};

}  // namespace arena::db
