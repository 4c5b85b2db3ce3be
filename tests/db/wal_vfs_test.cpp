// The WAL-coalescing VFS (db/src/wal_coalescing_vfs.cpp, issue 27 item 7):
// one write per commit for a transaction's WAL frames, the same bytes as
// SQLite writes without it, and readers (another connection, another
// process, and a copy of the files as a crash would leave them) that see
// every committed transaction the moment its COMMIT returns.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>

#include "db_test_util.hpp"
#include "wal_coalescing_vfs.hpp"
#include "wal_test_util.hpp"

namespace arena::db {
namespace {

using detail::WalCoalescingCountsNow;
using detail::WalCoalescingVfsName;
using testing::Digest;
using testing::ExecSql;
using testing::OpenWal;
using testing::ScalarSql;
using testing::TempDir;
using testing::TextSql;
using testing::WriteTxn;

constexpr std::int64_t kFrame = 8192 + 24;

std::int64_t SizeOf(const std::string& path) {
  std::error_code ec;
  const auto n = std::filesystem::file_size(path, ec);
  return ec ? 0 : static_cast<std::int64_t>(n);
}

std::string Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

class WalCoalescing : public ::testing::TestWithParam<bool> {};

// The same transactions on two files, one through the shim: one write of the
// WAL per commit (SQLite itself: two per frame), and the same database.
TEST_P(WalCoalescing, OneWritePerCommitAndTheSameBytes) {
  const bool full = GetParam();
  TempDir dir;
  const std::string a = dir.File("shim.db"), b = dir.File("plain.db");
  sqlite3* sa = OpenWal(a, WalCoalescingVfsName(), full);
  sqlite3* sb = OpenWal(b, nullptr, full);
  ASSERT_NE(sa, nullptr);
  ASSERT_NE(sb, nullptr);
  const std::string schema =
      "PRAGMA wal_autocheckpoint = 0;"
      " CREATE TABLE t(id INTEGER PRIMARY KEY, txn INT, n INT, v BLOB)";
  ASSERT_EQ(ExecSql(sa, schema), SQLITE_OK);
  ASSERT_EQ(ExecSql(sb, schema), SQLITE_OK);
  std::int64_t frames = 0, commits = 0, writes = 0;
  for (int txn = 0; txn < 30; ++txn) {
    const auto before = WalCoalescingCountsNow();
    const std::int64_t wal_before = SizeOf(a + "-wal");
    ASSERT_EQ(WriteTxn(sa, txn, /*big=*/txn % 10 == 9, /*commit=*/true), SQLITE_OK);
    const auto after = WalCoalescingCountsNow();
    const std::int64_t grew = SizeOf(a + "-wal") - wal_before;
    const std::int64_t wal_b_before = SizeOf(b + "-wal");
    ASSERT_EQ(WriteTxn(sb, txn, txn % 10 == 9, true), SQLITE_OK);
    EXPECT_EQ(SizeOf(b + "-wal") - wal_b_before, grew) << "txn " << txn;
    EXPECT_EQ(grew % kFrame, 0) << "txn " << txn;
    EXPECT_GE(grew / kFrame, 1) << "txn " << txn;
    // One write per commit, in pieces of at most 128 KiB (the unix VFS's limit).
    const auto piece = static_cast<std::int64_t>(detail::kMaxWalCoalescingWrite);
    EXPECT_EQ(after.wal_writes - before.wal_writes, (grew + piece - 1) / piece)
        << "txn " << txn << ", frames " << grew / kFrame;
    writes += after.wal_writes - before.wal_writes;
    EXPECT_EQ(after.wal_bytes - before.wal_bytes, grew) << "txn " << txn;
    frames += grew / kFrame;
    ++commits;
  }
  EXPECT_GE(frames, 2 * commits);
  std::printf("[ wal ] %lld commits, %lld frames: %lld writes through the shim (SQLite: %lld)\n",
              static_cast<long long>(commits), static_cast<long long>(frames),
              static_cast<long long>(writes), static_cast<long long>(2 * frames));
  // Everything into the main files, then compare them byte for byte.
  ASSERT_EQ(ExecSql(sa, "PRAGMA wal_checkpoint(TRUNCATE)"), SQLITE_OK);
  ASSERT_EQ(ExecSql(sb, "PRAGMA wal_checkpoint(TRUNCATE)"), SQLITE_OK);
  EXPECT_EQ(TextSql(sa, "PRAGMA integrity_check"), "ok");
  EXPECT_EQ(Digest(sa), Digest(sb));
  EXPECT_EQ(sqlite3_close_v2(sa), SQLITE_OK);
  EXPECT_EQ(sqlite3_close_v2(sb), SQLITE_OK);
  const std::string da = Bytes(a), db = Bytes(b);
  EXPECT_GT(da.size(), 30u * 8192u);
  EXPECT_TRUE(da == db) << "main files differ (" << da.size() << " vs " << db.size() << " bytes)";
}

INSTANTIATE_TEST_SUITE_P(Sync, WalCoalescing, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "Full" : "Normal"; });

// The child: answers each request with the digest a fresh read sees.
[[noreturn]] void ServeDigests(const std::string& path, int in, int out) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) ::_exit(2);
  sqlite3_busy_timeout(db, 5000);
  char req = 0;
  while (testing::ReadFull(in, &req, 1, 60000)) {
    const std::string d = Digest(db);
    const auto n = static_cast<std::uint32_t>(d.size());
    if (!testing::WriteFull(out, &n, sizeof n) || !testing::WriteFull(out, d.data(), n)) break;
  }
  sqlite3_close_v2(db);
  ::_exit(0);
}

// What a crash at this instant would leave: the main file and the WAL as
// they are on disk (no -shm: SQLite rebuilds it from the WAL's checksums).
std::string DigestOfCopy(const std::string& path, const std::filesystem::path& dir, int n) {
  const auto copy = dir / ("copy" + std::to_string(n));
  std::filesystem::create_directories(copy);
  std::filesystem::copy_file(path, copy / "s.db");
  if (std::filesystem::exists(path + "-wal")) {
    std::filesystem::copy_file(path + "-wal", copy / "s.db-wal");
  }
  sqlite3* db = nullptr;
  std::string d = "cannot open";
  if (sqlite3_open_v2((copy / "s.db").c_str(), &db, SQLITE_OPEN_READWRITE, nullptr) == SQLITE_OK) {
    d = Digest(db);
    const std::string check = TextSql(db, "PRAGMA integrity_check");
    if (check != "ok") d += " integrity: " + check;
  }
  sqlite3_close_v2(db);
  std::filesystem::remove_all(copy);
  return d;
}

// A writer commits (small transactions, big ones that spill a tiny page
// cache and rewrite spilled pages, rollbacks of both); after every COMMIT
// or ROLLBACK returns, a reader connection, a reader process and a copy of
// the files each see exactly the committed rows.
TEST(WalCoalescingReaders, SeeEveryCommitImmediately) {
  TempDir dir;
  const std::string path = dir.File("s.db");
  {
    sqlite3* setup = OpenWal(path, WalCoalescingVfsName());
    ASSERT_NE(setup, nullptr);
    ASSERT_EQ(ExecSql(setup, "CREATE TABLE t(id INTEGER PRIMARY KEY, txn INT, n INT, v BLOB)"),
              SQLITE_OK);
    ASSERT_EQ(sqlite3_close_v2(setup), SQLITE_OK);
  }
  // The reader process forks before this process holds a connection (SQLite
  // connections must not cross a fork).
  int to_child[2], from_child[2];
  ASSERT_EQ(::pipe(to_child), 0);
  ASSERT_EQ(::pipe(from_child), 0);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::close(to_child[1]);
    ::close(from_child[0]);
    ServeDigests(path, to_child[0], from_child[1]);
  }
  ::close(to_child[0]);
  ::close(from_child[1]);
  const auto ask_child = [&] {
    const char req = 'd';
    std::uint32_t n = 0;
    if (!testing::WriteFull(to_child[1], &req, 1) ||
        !testing::ReadFull(from_child[0], &n, sizeof n, 20000) || n > 1000) {
      return std::string("no answer");
    }
    std::string d(n, '\0');
    return testing::ReadFull(from_child[0], d.data(), n, 20000) ? d : std::string("no answer");
  };

  sqlite3* writer = OpenWal(path, WalCoalescingVfsName(), false, /*cache_pages=*/8);
  sqlite3* reader = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &reader, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_busy_timeout(reader, 5000);
  // A plain connection that tracks the committed state: the expectation.
  sqlite3* truth = OpenWal(dir.File("truth.db"), nullptr, false, 8);
  ASSERT_EQ(ExecSql(truth, "CREATE TABLE t(id INTEGER PRIMARY KEY, txn INT, n INT, v BLOB)"),
            SQLITE_OK);
  const auto before = WalCoalescingCountsNow();
  int commits = 0, rollbacks = 0;
  for (int txn = 0; txn < 48; ++txn) {
    const bool big = txn % 3 == 1;
    const bool commit = txn % 5 != 3;
    ASSERT_EQ(WriteTxn(writer, txn, big, commit), SQLITE_OK) << "txn " << txn;
    ASSERT_EQ(WriteTxn(truth, txn, big, commit), SQLITE_OK) << "txn " << txn;
    (commit ? commits : rollbacks)++;
    const std::string want = Digest(truth);
    ASSERT_EQ(Digest(reader), want) << "reader connection, after txn " << txn;
    ASSERT_EQ(ask_child(), want) << "reader process, after txn " << txn;
    ASSERT_EQ(DigestOfCopy(path, dir.path(), txn), want) << "copy of the files, after txn " << txn;
  }
  const auto after = WalCoalescingCountsNow();
  std::printf("[ wal ] %d commits, %d rollbacks: %lld WAL writes, %lld MB\n", commits, rollbacks,
              static_cast<long long>(after.wal_writes - before.wal_writes),
              static_cast<long long>((after.wal_bytes - before.wal_bytes) >> 20));
  ::close(to_child[1]);  // the child's read ends: it exits
  int status = 0;
  for (int i = 0; i < 200 && ::waitpid(pid, &status, WNOHANG) == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  if (::waitpid(pid, &status, WNOHANG) == 0) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &status, 0);
    ADD_FAILURE() << "reader process did not exit";
  }
  ::close(from_child[0]);
  EXPECT_EQ(TextSql(writer, "PRAGMA integrity_check"), "ok");
  EXPECT_EQ(sqlite3_close_v2(reader), SQLITE_OK);
  EXPECT_EQ(sqlite3_close_v2(writer), SQLITE_OK);
  EXPECT_EQ(sqlite3_close_v2(truth), SQLITE_OK);
}

// Every method of the files reaches the real file: a store opened through
// the shim by Store::Open works for reads, mmap and a checkpoint.
TEST(WalCoalescingReaders, MmapAndCheckpointThroughTheShim) {
  TempDir dir;
  const std::string path = dir.File("m.db");
  sqlite3* db = OpenWal(path, WalCoalescingVfsName());
  ASSERT_NE(db, nullptr);
  ASSERT_EQ(ExecSql(db,
                    "PRAGMA mmap_size = 67108864;"
                    " CREATE TABLE t(id INTEGER PRIMARY KEY, txn INT, n INT, v BLOB)"),
            SQLITE_OK);
  for (int txn = 0; txn < 10; ++txn) ASSERT_EQ(WriteTxn(db, txn, txn == 5, true), SQLITE_OK);
  ASSERT_EQ(ExecSql(db, "PRAGMA wal_checkpoint(RESTART)"), SQLITE_OK);
  for (int txn = 10; txn < 20; ++txn) ASSERT_EQ(WriteTxn(db, txn, false, true), SQLITE_OK);
  EXPECT_EQ(TextSql(db, "PRAGMA integrity_check"), "ok");
  const std::int64_t rows = ScalarSql(db, "SELECT COUNT(*) FROM t");
  EXPECT_EQ(sqlite3_close_v2(db), SQLITE_OK);
  sqlite3* plain = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &plain, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  EXPECT_EQ(ScalarSql(plain, "SELECT COUNT(*) FROM t"), rows);
  sqlite3_close_v2(plain);
}

// A failing write: the unix VFS's pwrite replaced (xSetSystemCall) by one
// that fails with ENOSPC while `g_fail_writes` is set.
std::atomic<bool> g_fail_writes{false};
std::atomic<int> g_failed_writes{0};
ssize_t FailingPwrite(int fd, const void* p, size_t n, off_t off) {
  if (g_fail_writes.load()) {
    g_failed_writes.fetch_add(1);
    errno = ENOSPC;
    return -1;
  }
  return ::pwrite(fd, p, n, off);
}

// A flush that fails fails the COMMIT that triggered it (SQLITE_FULL, as a
// failed write of SQLite's own), its frames are never seen, and the next
// transaction commits as if nothing had happened.
TEST(WalCoalescingFaults, AFailedFlushFailsTheCommitAndLeavesNoTrace) {
  TempDir dir;
  const std::string path = dir.File("f.db");
  sqlite3_vfs* unix_vfs = sqlite3_vfs_find("unix");
  ASSERT_NE(unix_vfs, nullptr);
  ASSERT_NE(unix_vfs->xSetSystemCall, nullptr);
  sqlite3* db = OpenWal(path, WalCoalescingVfsName());
  ASSERT_NE(db, nullptr);
  ASSERT_EQ(ExecSql(db, "CREATE TABLE t(id INTEGER PRIMARY KEY, txn INT, n INT, v BLOB)"),
            SQLITE_OK);
  for (int txn = 0; txn < 3; ++txn) ASSERT_EQ(WriteTxn(db, txn, false, true), SQLITE_OK);
  const std::string before = Digest(db);
  int replaced = 0;
  for (const char* name : {"pwrite", "pwrite64"}) {
    if (unix_vfs->xGetSystemCall(unix_vfs, name) != nullptr &&
        unix_vfs->xSetSystemCall(
            unix_vfs, name, reinterpret_cast<sqlite3_syscall_ptr>(FailingPwrite)) == SQLITE_OK) {
      ++replaced;
    }
  }
  ASSERT_GT(replaced, 0);
  g_fail_writes = true;
  const int rc = WriteTxn(db, 3, false, true);
  g_fail_writes = false;
  for (const char* name : {"pwrite", "pwrite64"}) unix_vfs->xSetSystemCall(unix_vfs, name, nullptr);
  EXPECT_EQ(rc & 0xff, SQLITE_FULL) << sqlite3_errstr(rc);
  EXPECT_EQ(g_failed_writes.load(), 1) << "the commit's frames: one write";
  if (!sqlite3_get_autocommit(db)) ExecSql(db, "ROLLBACK");
  EXPECT_EQ(Digest(db), before);
  sqlite3* reader = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &reader, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  EXPECT_EQ(Digest(reader), before);
  // The same transaction again, now that the disk has room; then more.
  for (int txn = 3; txn < 6; ++txn) ASSERT_EQ(WriteTxn(db, txn, txn == 4, true), SQLITE_OK);
  const std::string after = Digest(db);
  EXPECT_NE(after, before);
  EXPECT_EQ(Digest(reader), after);
  EXPECT_EQ(DigestOfCopy(path, dir.path(), 0), after);
  EXPECT_EQ(TextSql(db, "PRAGMA integrity_check"), "ok");
  sqlite3_close_v2(reader);
  EXPECT_EQ(sqlite3_close_v2(db), SQLITE_OK);
}

}  // namespace
}  // namespace arena::db
