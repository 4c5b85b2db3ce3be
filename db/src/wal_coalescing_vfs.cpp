// Why: SQLite writes each WAL frame as two writes (the 24-byte frame header,
// then the page), so a trial's ~50 frames cost ~100 pwrite syscalls, about
// 370 us of the service's CPU per trial; one pwrite of the same bytes costs
// a third of that (issue 27 item 7). This shim buffers a WAL file's
// contiguous writes and hands them to the real file as ONE write (one per
// 128 KiB, the most the unix VFS writes at once) when the transaction's
// commit frame is complete. Only files opened with SQLITE_OPEN_WAL buffer;
// the main file, journals and every other method pass straight through.
//
// When readers can see a frame: SQLite publishes a transaction to readers
// (other connections, other processes) by writing the wal-index header in
// shared memory, right after the xWrite of its last frame returns (and the
// xSync, with synchronous=FULL). So the buffer is flushed inside the xWrite
// that completes a commit frame: a reader never finds a published frame
// that is not in the file.
//
// Crashes: frames still in the buffer belong to a transaction that has not
// committed (its commit frame is not yet written), and were never
// published; a process killed then loses only them, exactly as if SQLite
// had been killed before writing them. WAL recovery ignores frames after the
// last valid commit frame anyway. The bytes written are the bytes SQLite
// wrote, at the offsets it wrote them, in the same order.
#include "wal_coalescing_vfs.hpp"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <mutex>

namespace arena::db::detail {
namespace wal_coalescing {

// Bigger than a trial's commits (~50 frames of 8 KiB); a larger transaction
// is written in 4 MiB pieces (only the commit needs the flush, not the size).
constexpr std::size_t kMaxBuffer = std::size_t{4} << 20;
constexpr int kFrameHeader = 24;
constexpr int kWalHeader = 32;

std::atomic<std::int64_t> g_wal_writes{0};
std::atomic<std::int64_t> g_wal_bytes{0};

struct ShimFile {
  sqlite3_file base;   // first: SQLite sees this
  sqlite3_file* real;  // the real file, in the same allocation after this struct
  bool wal;
  // The buffer: len bytes that belong at file offset off.
  unsigned char* buf;
  std::size_t len;
  std::size_t cap;
  sqlite3_int64 off;
  // The end (file offset) of a commit frame whose header is buffered and whose
  // page is not yet complete in the file; 0: none.
  sqlite3_int64 commit_end;
  // The page size, from the WAL header; 0 unknown (learn it), -1 unknowable
  // (every write goes straight through).
  int page_size;
  // The previous call on this file was an xRead of [read_off, read_off+read_len).
  bool last_was_read;
  sqlite3_int64 read_off;
  int read_len;
};

constexpr std::size_t RealOffset() { return (sizeof(ShimFile) + 15) & ~std::size_t{15}; }

sqlite3_file* Real(sqlite3_file* f) { return reinterpret_cast<ShimFile*>(f)->real; }

std::uint32_t Be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

// The page size a WAL header names, or -1 if it is not a WAL header.
int PageSizeOfWalHeader(const unsigned char* h) {
  const std::uint32_t magic = Be32(h);
  const std::uint32_t ps = Be32(h + 8);
  if ((magic & 0xFFFFFFFEu) != 0x377f0682u || ps < 512 || ps > 65536 || (ps & (ps - 1)) != 0) {
    return -1;
  }
  return static_cast<int>(ps);
}

int WriteReal(ShimFile* f, const void* data, std::size_t n, sqlite3_int64 off) {
  g_wal_writes.fetch_add(1, std::memory_order_relaxed);
  g_wal_bytes.fetch_add(static_cast<std::int64_t>(n), std::memory_order_relaxed);
  const int rc = f->real->pMethods->xWrite(f->real, data, static_cast<int>(n), off);
  if (f->commit_end != 0 && off + static_cast<sqlite3_int64>(n) >= f->commit_end) {
    f->commit_end = 0;
  }
  return rc;
}

// Writes the buffer with one write of the real file (one per 128 KiB: see
// kMaxWalCoalescingWrite). On failure the buffer is dropped all the same and the error returned:
// SQLite then fails the call's transaction as after a failed write of its own, and the
// transaction's frames are never published; its next transaction writes its frames again from the
// same offset. Keeping the bytes for a retry would only risk writing stale frames over newer ones
// later.
int Flush(ShimFile* f) {
  std::size_t done = 0;
  int rc = SQLITE_OK;
  while (rc == SQLITE_OK && done < f->len) {
    const std::size_t n = std::min(f->len - done, kMaxWalCoalescingWrite);
    rc = WriteReal(f, f->buf + done, n, f->off + static_cast<sqlite3_int64>(done));
    done += n;
  }
  f->len = 0;
  if (rc != SQLITE_OK) f->commit_end = 0;
  return rc;
}

bool Append(ShimFile* f, const void* data, std::size_t n, sqlite3_int64 off) {
  if (f->len + n > f->cap) {
    std::size_t cap = f->cap ? f->cap : std::size_t{64} << 10;
    while (cap < f->len + n) cap *= 2;
    auto* grown = static_cast<unsigned char*>(std::realloc(f->buf, cap));
    if (grown == nullptr) return false;
    f->buf = grown;
    f->cap = cap;
  }
  if (f->len == 0) f->off = off;
  std::memcpy(f->buf + f->len, data, n);
  f->len += n;
  return true;
}

// The page size, from a WAL header this write carries or else from the file.
void LearnPageSize(ShimFile* f, const unsigned char* data, int amt, sqlite3_int64 off) {
  if (off == 0 && amt >= kWalHeader) {
    f->page_size = PageSizeOfWalHeader(data);
    return;
  }
  if (f->page_size != 0) return;
  // A frame before this connection wrote a header: the header is in the file
  // (another connection wrote it; page size cannot change in WAL mode).
  unsigned char h[kWalHeader];
  const int rc = f->real->pMethods->xRead(f->real, h, kWalHeader, 0);
  f->page_size = rc == SQLITE_OK ? PageSizeOfWalHeader(h) : -1;
}

int WalWrite(ShimFile* f, const void* data, int amt, sqlite3_int64 off) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  const bool after_read = f->last_was_read;
  f->last_was_read = false;
  int rc = SQLITE_OK;
  if (f->len != 0 && off != f->off + static_cast<sqlite3_int64>(f->len)) {
    rc = Flush(f);  // not contiguous: keep SQLite's order of writes
    if (rc != SQLITE_OK) return rc;
  }
  if (off == 0 || f->page_size == 0) LearnPageSize(f, bytes, amt, off);
  const auto n = static_cast<std::size_t>(amt);
  if (f->len + n > kMaxBuffer) {
    rc = Flush(f);
    if (rc != SQLITE_OK) return rc;
  }
  if (f->page_size < 0 || n > kMaxBuffer || !Append(f, data, n, off)) {
    rc = Flush(f);
    return rc != SQLITE_OK ? rc : WriteReal(f, data, n, off);
  }
  const sqlite3_int64 frame = f->page_size + kFrameHeader;
  if (amt == kFrameHeader && off >= kWalHeader && (off - kWalHeader) % frame == 0 &&
      Be32(bytes + 4) != 0) {
    // A commit frame's header (bytes 4-7: the database size after the
    // commit; 0 for the other frames). Padding frames (synchronous=FULL on a
    // device without powersafe overwrite) are commit frames too.
    f->commit_end = off + frame;
    // A header right after a read of its frame is SQLite rewriting the
    // checksums of frames it already wrote (walRewriteChecksums: a
    // transaction that spilled pages and then changed one): no page follows,
    // so the header goes to the file now, or a crash would leave the old
    // checksum and recovery would drop the committed transaction.
    // commit_end stays: in the rare case this was a new frame written right
    // after WAL recovery read a stale one there, its page still gets flushed.
    if (after_read && f->read_off == off && f->read_len >= kFrameHeader) return Flush(f);
  }
  if (f->commit_end != 0 && f->off + static_cast<sqlite3_int64>(f->len) >= f->commit_end) {
    return Flush(f);  // the commit frame is complete: to the file before it is published
  }
  return SQLITE_OK;
}

// io methods. Everything but the WAL's buffering forwards to the real file.

int Close(sqlite3_file* file) {
  auto* f = reinterpret_cast<ShimFile*>(file);
  const int flushed = f->wal ? Flush(f) : SQLITE_OK;
  const int rc = f->real->pMethods->xClose(f->real);
  std::free(f->buf);
  f->buf = nullptr;
  f->cap = 0;
  return flushed != SQLITE_OK ? flushed : rc;
}

int Read(sqlite3_file* file, void* p, int amt, sqlite3_int64 off) {
  auto* f = reinterpret_cast<ShimFile*>(file);
  if (f->wal) {
    const int flushed = Flush(f);
    if (flushed != SQLITE_OK) return flushed;
  }
  const int rc = f->real->pMethods->xRead(f->real, p, amt, off);
  if (f->wal) {
    f->last_was_read = rc == SQLITE_OK;
    f->read_off = off;
    f->read_len = amt;
  }
  return rc;
}

int Write(sqlite3_file* file, const void* p, int amt, sqlite3_int64 off) {
  auto* f = reinterpret_cast<ShimFile*>(file);
  if (!f->wal) return f->real->pMethods->xWrite(f->real, p, amt, off);
  return WalWrite(f, p, amt, off);
}

// The calls before which the file must hold every byte written.
int FlushIfWal(sqlite3_file* file) {
  auto* f = reinterpret_cast<ShimFile*>(file);
  if (!f->wal) return SQLITE_OK;
  f->last_was_read = false;
  return Flush(f);
}

int Truncate(sqlite3_file* file, sqlite3_int64 size) {
  const int rc = FlushIfWal(file);
  return rc != SQLITE_OK ? rc : Real(file)->pMethods->xTruncate(Real(file), size);
}

int Sync(sqlite3_file* file, int flags) {
  const int rc = FlushIfWal(file);
  return rc != SQLITE_OK ? rc : Real(file)->pMethods->xSync(Real(file), flags);
}

int FileSize(sqlite3_file* file, sqlite3_int64* size) {
  const int rc = FlushIfWal(file);
  return rc != SQLITE_OK ? rc : Real(file)->pMethods->xFileSize(Real(file), size);
}

int FileControl(sqlite3_file* file, int op, void* arg) {
  const int rc = FlushIfWal(file);
  return rc != SQLITE_OK ? rc : Real(file)->pMethods->xFileControl(Real(file), op, arg);
}

int Lock(sqlite3_file* file, int level) { return Real(file)->pMethods->xLock(Real(file), level); }
int Unlock(sqlite3_file* file, int level) {
  return Real(file)->pMethods->xUnlock(Real(file), level);
}
int CheckReservedLock(sqlite3_file* file, int* out) {
  return Real(file)->pMethods->xCheckReservedLock(Real(file), out);
}
int SectorSize(sqlite3_file* file) { return Real(file)->pMethods->xSectorSize(Real(file)); }
int DeviceCharacteristics(sqlite3_file* file) {
  return Real(file)->pMethods->xDeviceCharacteristics(Real(file));
}
// Shared memory and memory maps belong to the main database file (SQLite
// maps neither the WAL nor its buffer): straight through.
int ShmMap(sqlite3_file* file, int region, int size, int extend, void volatile** out) {
  return Real(file)->pMethods->xShmMap(Real(file), region, size, extend, out);
}
int ShmLock(sqlite3_file* file, int offset, int n, int flags) {
  return Real(file)->pMethods->xShmLock(Real(file), offset, n, flags);
}
void ShmBarrier(sqlite3_file* file) { Real(file)->pMethods->xShmBarrier(Real(file)); }
int ShmUnmap(sqlite3_file* file, int delete_flag) {
  return Real(file)->pMethods->xShmUnmap(Real(file), delete_flag);
}
int Fetch(sqlite3_file* file, sqlite3_int64 off, int amt, void** out) {
  return Real(file)->pMethods->xFetch(Real(file), off, amt, out);
}
int Unfetch(sqlite3_file* file, sqlite3_int64 off, void* p) {
  return Real(file)->pMethods->xUnfetch(Real(file), off, p);
}

// One table per io_methods version, so SQLite calls only what the real file has.
constexpr sqlite3_io_methods MethodsOfVersion(int version) {
  return sqlite3_io_methods{version,
                            Close,
                            Read,
                            Write,
                            Truncate,
                            Sync,
                            FileSize,
                            Lock,
                            Unlock,
                            CheckReservedLock,
                            FileControl,
                            SectorSize,
                            DeviceCharacteristics,
                            version >= 2 ? ShmMap : nullptr,
                            version >= 2 ? ShmLock : nullptr,
                            version >= 2 ? ShmBarrier : nullptr,
                            version >= 2 ? ShmUnmap : nullptr,
                            version >= 3 ? Fetch : nullptr,
                            version >= 3 ? Unfetch : nullptr};
}
const sqlite3_io_methods kMethods[3] = {MethodsOfVersion(1), MethodsOfVersion(2),
                                        MethodsOfVersion(3)};

// The VFS: the base VFS's methods, with the base as their first argument.
sqlite3_vfs* Base(sqlite3_vfs* vfs) { return static_cast<sqlite3_vfs*>(vfs->pAppData); }

int Open(sqlite3_vfs* vfs, const char* name, sqlite3_file* file, int flags, int* out_flags) {
  auto* f = reinterpret_cast<ShimFile*>(file);
  std::memset(f, 0, sizeof(ShimFile));  // pMethods null until the real open succeeds
  f->real = reinterpret_cast<sqlite3_file*>(reinterpret_cast<unsigned char*>(file) + RealOffset());
  const int rc = Base(vfs)->xOpen(Base(vfs), name, f->real, flags, out_flags);
  if (rc != SQLITE_OK || f->real->pMethods == nullptr) return rc;
  f->wal = (flags & SQLITE_OPEN_WAL) != 0;
  int version = f->real->pMethods->iVersion;
  version = version < 1 ? 1 : version > 3 ? 3 : version;
  f->base.pMethods = &kMethods[version - 1];
  return SQLITE_OK;
}

int Delete(sqlite3_vfs* vfs, const char* name, int sync_dir) {
  return Base(vfs)->xDelete(Base(vfs), name, sync_dir);
}
int Access(sqlite3_vfs* vfs, const char* name, int flags, int* out) {
  return Base(vfs)->xAccess(Base(vfs), name, flags, out);
}
int FullPathname(sqlite3_vfs* vfs, const char* name, int n, char* out) {
  return Base(vfs)->xFullPathname(Base(vfs), name, n, out);
}
void* DlOpen(sqlite3_vfs* vfs, const char* name) { return Base(vfs)->xDlOpen(Base(vfs), name); }
void DlError(sqlite3_vfs* vfs, int n, char* out) { Base(vfs)->xDlError(Base(vfs), n, out); }
void (*DlSym(sqlite3_vfs* vfs, void* h, const char* sym))(void) {
  return Base(vfs)->xDlSym(Base(vfs), h, sym);
}
void DlClose(sqlite3_vfs* vfs, void* h) { Base(vfs)->xDlClose(Base(vfs), h); }
int Randomness(sqlite3_vfs* vfs, int n, char* out) {
  return Base(vfs)->xRandomness(Base(vfs), n, out);
}
int Sleep(sqlite3_vfs* vfs, int us) { return Base(vfs)->xSleep(Base(vfs), us); }
int CurrentTime(sqlite3_vfs* vfs, double* out) { return Base(vfs)->xCurrentTime(Base(vfs), out); }
int GetLastError(sqlite3_vfs* vfs, int n, char* out) {
  return Base(vfs)->xGetLastError ? Base(vfs)->xGetLastError(Base(vfs), n, out) : 0;
}
int CurrentTimeInt64(sqlite3_vfs* vfs, sqlite3_int64* out) {
  return Base(vfs)->xCurrentTimeInt64(Base(vfs), out);
}
int SetSystemCall(sqlite3_vfs* vfs, const char* name, sqlite3_syscall_ptr p) {
  return Base(vfs)->xSetSystemCall(Base(vfs), name, p);
}
sqlite3_syscall_ptr GetSystemCall(sqlite3_vfs* vfs, const char* name) {
  return Base(vfs)->xGetSystemCall(Base(vfs), name);
}
const char* NextSystemCall(sqlite3_vfs* vfs, const char* name) {
  return Base(vfs)->xNextSystemCall(Base(vfs), name);
}

}  // namespace wal_coalescing

int RegisterWalCoalescingVfs(const char* name, sqlite3_vfs* base) {
  namespace w = wal_coalescing;
  if (base == nullptr) return SQLITE_ERROR;
  // Lives as long as the process: SQLite keeps the pointer once registered.
  auto* vfs = new sqlite3_vfs{};
  vfs->iVersion = base->iVersion < 3 ? base->iVersion : 3;
  vfs->szOsFile = static_cast<int>(w::RealOffset()) + base->szOsFile;
  vfs->mxPathname = base->mxPathname;
  vfs->zName = name;
  vfs->pAppData = base;
  vfs->xOpen = w::Open;
  vfs->xDelete = w::Delete;
  vfs->xAccess = w::Access;
  vfs->xFullPathname = w::FullPathname;
  vfs->xDlOpen = base->xDlOpen ? w::DlOpen : nullptr;
  vfs->xDlError = base->xDlError ? w::DlError : nullptr;
  vfs->xDlSym = base->xDlSym ? w::DlSym : nullptr;
  vfs->xDlClose = base->xDlClose ? w::DlClose : nullptr;
  vfs->xRandomness = w::Randomness;
  vfs->xSleep = w::Sleep;
  vfs->xCurrentTime = w::CurrentTime;
  vfs->xGetLastError = w::GetLastError;
  if (vfs->iVersion >= 2)
    vfs->xCurrentTimeInt64 = base->xCurrentTimeInt64 ? w::CurrentTimeInt64 : nullptr;
  if (vfs->iVersion >= 3) {
    vfs->xSetSystemCall = base->xSetSystemCall ? w::SetSystemCall : nullptr;
    vfs->xGetSystemCall = base->xGetSystemCall ? w::GetSystemCall : nullptr;
    vfs->xNextSystemCall = base->xNextSystemCall ? w::NextSystemCall : nullptr;
  }
  const int rc = sqlite3_vfs_register(vfs, /*makeDflt=*/0);
  if (rc != SQLITE_OK) delete vfs;
  return rc;
}

const char* WalCoalescingVfsName() {
  static constexpr const char* kName = "arena-wal-coalescing";
  static std::once_flag once;
  static const char* registered = nullptr;
  std::call_once(once, [] {
    if (RegisterWalCoalescingVfs(kName, sqlite3_vfs_find(nullptr)) == SQLITE_OK) {
      registered = kName;
    }
  });
  // nullptr (the default VFS) if registration failed: slower, never wrong.
  return registered;
}

WalCoalescingCounts WalCoalescingCountsNow() {
  return {wal_coalescing::g_wal_writes.load(std::memory_order_relaxed),
          wal_coalescing::g_wal_bytes.load(std::memory_order_relaxed)};
}

}  // namespace arena::db::detail
