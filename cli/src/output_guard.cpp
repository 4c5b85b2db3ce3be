#include "output_guard.hpp"

#include <sys/stat.h>

#include <cstring>
#include <filesystem>
#include <fstream>

#include "command_error.hpp"

namespace arena::cli {
namespace {

bool IsSqliteFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char header[16] = {};
  if (!f.read(header, sizeof header)) return false;
  return std::memcmp(header, "SQLite format 3", 16) == 0;  // includes the terminating NUL
}

bool SameFile(const std::string& a, const std::string& b) {
  struct stat sa {
  }, sb{};
  return ::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0 && sa.st_dev == sb.st_dev &&
         sa.st_ino == sb.st_ino;
}

std::string Parent(const std::string& path) {
  const std::string p = std::filesystem::path(path).parent_path().string();
  return p.empty() ? "." : p;
}

// The files arena keeps beside a store STORE, named after it: STORE-wal,
// STORE-shm, STORE-journal (SQLite's), STORE.log and its rotations
// STORE.N.log, the logs of `arena run`'s children (STORE.sim1.log,
// STORE.controller.log). `name` is the output's file name, `store` the store's.
bool OwnedName(const std::string& name, const std::string& store) {
  if (name.size() <= store.size() || name.compare(0, store.size(), store) != 0) return false;
  const std::string rest = name.substr(store.size());
  if (rest == "-wal" || rest == "-shm" || rest == "-journal") return true;
  return rest.size() >= 4 && rest[0] == '.' && rest.compare(rest.size() - 4, 4, ".log") == 0;
}

// An export's staging directory (".NAME.partial-..."), anywhere on the path.
bool InStagingDir(const std::string& path) {
  for (const auto& part : std::filesystem::path(path)) {
    const std::string s = part.string();
    if (s.size() > 1 && s[0] == '.' && s.find(".partial-") != std::string::npos) return true;
  }
  return false;
}

}  // namespace

void RefuseToOverwriteStore(const std::string& path, const std::string& option,
                            const std::string& db_path) {
  if (path.empty()) return;
  const std::string refuse = option + ": '" + path + "' ";
  const std::string advice = "; refusing to overwrite it (choose another output file)";
  if (!db_path.empty() && (path == db_path || SameFile(path, db_path)))
    throw CommandError(kExitBadInput, refuse + "is the store (--db)" + advice);
  if (IsSqliteFile(path))
    throw CommandError(kExitBadInput, refuse + "is an SQLite database" + advice);
  if (!db_path.empty()) {
    const std::string name = std::filesystem::path(path).filename().string();
    const std::string store = std::filesystem::path(db_path).filename().string();
    if (!store.empty() && OwnedName(name, store) && SameFile(Parent(path), Parent(db_path)))
      throw CommandError(kExitBadInput, refuse + "is kept by the store '" + db_path +
                                            "' (its log or SQLite's files)" + advice);
  }
  if (InStagingDir(path))
    throw CommandError(kExitBadInput,
                       refuse + "is inside an export's unfinished (.partial-) directory" + advice);
  for (const char* suffix : {"-wal", "-shm", "-journal"}) {
    const std::size_t n = std::strlen(suffix);
    if (path.size() > n && path.compare(path.size() - n, n, suffix) == 0) {
      const std::string base = path.substr(0, path.size() - n);
      if (IsSqliteFile(base) || (!db_path.empty() && SameFile(base, db_path)))
        throw CommandError(kExitBadInput,
                           refuse + "belongs to the SQLite database '" + base + "'" + advice);
    }
  }
}

}  // namespace arena::cli
