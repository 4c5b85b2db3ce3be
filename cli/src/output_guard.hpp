// Output files a command writes (`plot --out`, `simulate --trajectory`,
// `export --out`, ...) must never clobber a store: an SVG written over lab.db
// destroys months of data.
#pragma once

#include <string>

namespace arena::cli {

// @throws CommandError(kExitBadInput) naming `option` when `path` is the
//   store `db_path` (same file, however spelled), an existing SQLite database,
//   one of a database's -wal / -shm / -journal files, a file the store keeps
//   beside it (STORE.log, its rotations STORE.N.log, STORE.sim1.log, ...), or
//   a path inside an export's unfinished `.NAME.partial-*` directory.
void RefuseToOverwriteStore(const std::string& path, const std::string& option,
                            const std::string& db_path = "");

}  // namespace arena::cli
