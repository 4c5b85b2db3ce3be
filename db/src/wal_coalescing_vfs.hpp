// A SQLite VFS shim that writes a transaction's WAL frames with one write
// per commit instead of two per frame (issue 27 item 7). Private to the room.
#pragma once

#include <sqlite3.h>

#include <cstddef>
#include <cstdint>

namespace arena::db::detail {

// The most one write of the real file carries: the unix VFS writes at most
// 0x1ffff bytes per call (os_unix.c seekAndWriteFd masks the length with it;
// SQLite itself never writes more than a 64 KiB page at once), so a larger
// buffer is flushed as consecutive writes of this size, all before the
// xWrite that triggered the flush returns.
inline constexpr std::size_t kMaxWalCoalescingWrite = 0x1ffff;

// The name of the shim over the default VFS, registered on the first call
// (thread-safe; never made the process default). The store names it in
// every sqlite3_open_v2.
const char* WalCoalescingVfsName();

// Registers a shim named `name` over `base` (tests: over a counting VFS).
// Returns SQLITE_OK, or an error code. `name` must outlive the process.
int RegisterWalCoalescingVfs(const char* name, sqlite3_vfs* base);

// Writes the shims issued to WAL files' real xWrite, process-wide (tests).
struct WalCoalescingCounts {
  std::int64_t wal_writes = 0;  // real xWrite calls on WAL files
  std::int64_t wal_bytes = 0;   // bytes they wrote
};
WalCoalescingCounts WalCoalescingCountsNow();

}  // namespace arena::db::detail
