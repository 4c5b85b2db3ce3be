#include "output_guard.hpp"

#include <sys/stat.h>

#include <cstring>
#include <fstream>

#include "commands.hpp"

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
