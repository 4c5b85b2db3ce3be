// SIGKILL of a process writing through the WAL-coalescing VFS at seeded
// random moments (db/src/wal_coalescing_vfs.cpp): the reopened file passes
// integrity_check and holds exactly the committed transactions, whole: every
// one whose COMMIT returned, at most the one in flight besides, and no
// rolled-back one.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <map>
#include <random>
#include <set>
#include <thread>

#include "db_test_util.hpp"
#include "wal_coalescing_vfs.hpp"
#include "wal_test_util.hpp"

namespace arena::db {
namespace {

using testing::ExecSql;
using testing::OpenWal;
using testing::RowsOf;
using testing::TempDir;
using testing::TextSql;

bool IsBig(std::int64_t txn) { return txn % 3 == 1; }
bool Commits(std::int64_t txn) { return txn % 5 != 3; }

// The child: commits transactions until killed, reporting each COMMIT that returned.
[[noreturn]] void WriteUntilKilled(const std::string& path, int out) {
  sqlite3* db = OpenWal(path, detail::WalCoalescingVfsName(), false, /*cache_pages=*/8);
  if (db == nullptr) ::_exit(2);
  std::int64_t txn = testing::ScalarSql(db, "SELECT COALESCE(MAX(txn), -1) + 1 FROM t");
  for (;; ++txn) {
    if (testing::WriteTxn(db, txn, IsBig(txn), Commits(txn)) != SQLITE_OK) ::_exit(3);
    if (Commits(txn) && !testing::WriteFull(out, &txn, sizeof txn)) ::_exit(4);
  }
}

TEST(WalCoalescingCrash, SigkillKeepsExactlyTheCommittedTransactions) {
  TempDir dir;
  const std::string path = dir.File("crash.db");
  {
    sqlite3* db = OpenWal(path, nullptr);
    ASSERT_EQ(ExecSql(db, "CREATE TABLE t(id INTEGER PRIMARY KEY, txn INT, n INT, v BLOB)"),
              SQLITE_OK);
    ASSERT_EQ(sqlite3_close_v2(db), SQLITE_OK);
  }
  std::mt19937 rng(2027);
  std::set<std::int64_t> committed;  // survived an earlier round
  int kills = 0;
  std::int64_t in_flight_kept = 0;
  for (int round = 0; round < 10; ++round) {
    int fds[2];
    ASSERT_EQ(::pipe(fds), 0);
    const pid_t pid = ::fork();  // no connection open in this process
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      ::close(fds[0]);
      WriteUntilKilled(path, fds[1]);
    }
    ::close(fds[1]);
    // Mid-stream: after its first commit (however loaded the machine), then
    // at a random moment.
    std::set<std::int64_t> reported;
    std::int64_t id = 0;
    const bool started = testing::ReadFull(fds[0], &id, sizeof id, 30000);
    if (started) reported.insert(id);
    std::this_thread::sleep_for(std::chrono::milliseconds(rng() % 300));
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, WNOHANG), 0) << "writer exited early: " << status;
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &status, 0);
    ++kills;
    ASSERT_TRUE(started) << "round " << round << ": no commit within 30 s";
    while (testing::ReadFull(fds[0], &id, sizeof id, 5000)) reported.insert(id);
    ::close(fds[0]);

    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr), SQLITE_OK);
    sqlite3_busy_timeout(db, 5000);
    ASSERT_EQ(TextSql(db, "PRAGMA integrity_check"), "ok") << "round " << round;
    std::map<std::int64_t, std::pair<std::int64_t, std::int64_t>> present;  // rows, sum(n)
    sqlite3_stmt* s = nullptr;
    ASSERT_EQ(
        sqlite3_prepare_v2(db, "SELECT txn, COUNT(*), SUM(n) FROM t GROUP BY txn", -1, &s, nullptr),
        SQLITE_OK);
    while (sqlite3_step(s) == SQLITE_ROW) {
      present[sqlite3_column_int64(s, 0)] = {sqlite3_column_int64(s, 1),
                                             sqlite3_column_int64(s, 2)};
    }
    sqlite3_finalize(s);
    ASSERT_EQ(sqlite3_close_v2(db), SQLITE_OK);

    const std::int64_t last = reported.empty() ? -1 : *reported.rbegin();
    int unreported = 0;
    for (const auto& [txn, rows_n] : present) {
      const bool big = IsBig(txn);
      EXPECT_TRUE(Commits(txn)) << "rolled-back txn " << txn << " is in the file";
      EXPECT_EQ(rows_n.first, RowsOf(txn, big)) << "txn " << txn << " not whole";
      EXPECT_EQ(rows_n.second, big ? rows_n.first : 0) << "txn " << txn << " half updated";
      if (!reported.count(txn) && !committed.count(txn)) {
        // The one whose COMMIT was under way when the kill came.
        EXPECT_GT(txn, last) << "txn " << txn;
        ++unreported;
        ++in_flight_kept;
      }
    }
    EXPECT_LE(unreported, 1) << "round " << round;
    for (const auto txn : reported) EXPECT_TRUE(present.count(txn)) << "lost txn " << txn;
    for (const auto txn : committed) EXPECT_TRUE(present.count(txn)) << "lost txn " << txn;
    for (const auto& [txn, rows_n] : present) committed.insert(txn);
  }
  EXPECT_EQ(kills, 10);
  std::printf("[ crash ] %d SIGKILLs, %zu transactions kept, %lld of them committing at the kill\n",
              kills, committed.size(), static_cast<long long>(in_flight_kept));
}

}  // namespace
}  // namespace arena::db
