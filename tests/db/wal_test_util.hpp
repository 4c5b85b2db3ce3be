// Raw SQLite helpers for the WAL-coalescing VFS tests (wal_vfs_test.cpp,
// wal_vfs_crash_test.cpp): real files, the shim named or not.
#pragma once

#include <gtest/gtest.h>
#include <poll.h>
#include <sqlite3.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <random>
#include <string>

namespace arena::db::testing {

// A connection to `path` in WAL mode, through `vfs` (nullptr: the default VFS).
inline sqlite3* OpenWal(const std::string& path, const char* vfs, bool full = false,
                        int cache_pages = 0) {
  sqlite3* db = nullptr;
  const int rc =
      sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, vfs);
  if (rc != SQLITE_OK) {
    ADD_FAILURE() << "open " << path << ": " << sqlite3_errstr(rc);
    sqlite3_close_v2(db);
    return nullptr;
  }
  sqlite3_busy_timeout(db, 5000);
  std::string setup = "PRAGMA page_size = 8192; PRAGMA journal_mode = WAL; PRAGMA synchronous = ";
  setup += full ? "FULL;" : "NORMAL;";
  if (cache_pages > 0) setup += " PRAGMA cache_size = " + std::to_string(cache_pages) + ";";
  char* err = nullptr;
  if (sqlite3_exec(db, setup.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
    ADD_FAILURE() << "setup: " << (err ? err : "?");
    sqlite3_free(err);
  }
  return db;
}

inline int ExecSql(sqlite3* db, const std::string& sql) {
  char* err = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &err);
  if (rc != SQLITE_OK) {
    std::fprintf(stderr, "sql '%s': %s\n", sql.substr(0, 80).c_str(), err ? err : "?");
  }
  sqlite3_free(err);
  return rc;
}

inline std::int64_t ScalarSql(sqlite3* db, const std::string& sql) {
  sqlite3_stmt* s = nullptr;
  std::int64_t v = -1;
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) == SQLITE_OK &&
      sqlite3_step(s) == SQLITE_ROW) {
    v = sqlite3_column_int64(s, 0);
  }
  sqlite3_finalize(s);
  return v;
}

inline std::string TextSql(sqlite3* db, const std::string& sql) {
  sqlite3_stmt* s = nullptr;
  std::string out;
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) == SQLITE_OK) {
    while (sqlite3_step(s) == SQLITE_ROW) {
      const auto* t = reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
      if (!out.empty()) out += "; ";
      out += t ? t : "";
    }
  }
  sqlite3_finalize(s);
  return out;
}

// Transaction `txn` of the tests: rows of deterministic blobs; `big` spills a
// small page cache and then rewrites the pages it spilled.
inline int RowsOf(std::int64_t txn, bool big) { return big ? 120 : 1 + static_cast<int>(txn % 7); }

inline int WriteTxn(sqlite3* db, std::int64_t txn, bool big, bool commit) {
  int rc = ExecSql(db, "BEGIN IMMEDIATE");
  if (rc != SQLITE_OK) return rc;
  sqlite3_stmt* ins = nullptr;
  rc = sqlite3_prepare_v2(db, "INSERT INTO t(txn, n, v) VALUES(?, 0, ?)", -1, &ins, nullptr);
  std::mt19937 rng(static_cast<unsigned>(txn));
  for (int i = 0; rc == SQLITE_OK && i < RowsOf(txn, big); ++i) {
    std::string blob(1000 + rng() % (big ? 20000 : 12000), '\0');
    for (auto& c : blob) c = static_cast<char>(rng());
    sqlite3_bind_int64(ins, 1, txn);
    sqlite3_bind_blob(ins, 2, blob.data(), static_cast<int>(blob.size()), SQLITE_TRANSIENT);
    rc = sqlite3_step(ins) == SQLITE_DONE ? SQLITE_OK : sqlite3_errcode(db);
    sqlite3_reset(ins);
  }
  sqlite3_finalize(ins);
  if (rc == SQLITE_OK && big) {
    rc = ExecSql(db, "UPDATE t SET n = n + 1 WHERE txn = " + std::to_string(txn));
  }
  if (rc != SQLITE_OK) {
    ExecSql(db, "ROLLBACK");
    return rc;
  }
  return ExecSql(db, commit ? "COMMIT" : "ROLLBACK");
}

// What a reader checks: rows, their bytes, and the updates of big transactions.
inline std::string Digest(sqlite3* db) {
  return std::to_string(ScalarSql(db, "SELECT COUNT(*) FROM t")) + "/" +
         std::to_string(ScalarSql(db, "SELECT COALESCE(SUM(length(v)), 0) FROM t")) + "/" +
         std::to_string(ScalarSql(db, "SELECT COALESCE(SUM(n), 0) FROM t"));
}

// Reads exactly n bytes from fd within timeout_ms; false on timeout or EOF.
inline bool ReadFull(int fd, void* p, std::size_t n, int timeout_ms) {
  auto* out = static_cast<char*>(p);
  while (n > 0) {
    pollfd pfd{fd, POLLIN, 0};
    if (::poll(&pfd, 1, timeout_ms) <= 0) return false;
    const ssize_t got = ::read(fd, out, n);
    if (got <= 0) return false;
    out += got;
    n -= static_cast<std::size_t>(got);
  }
  return true;
}

inline bool WriteFull(int fd, const void* p, std::size_t n) {
  const auto* in = static_cast<const char*>(p);
  while (n > 0) {
    const ssize_t put = ::write(fd, in, n);
    if (put <= 0) return false;
    in += put;
    n -= static_cast<std::size_t>(put);
  }
  return true;
}

}  // namespace arena::db::testing
