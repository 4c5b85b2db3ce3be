// A long computation's result (an evaluation, a calibration) is never thrown
// away: it can be written to a file (--out), and when the store cannot take
// it (locked past Ctrl-C, full, read-only) it is saved to a file anyway.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace arena::cli {

// Writes `text` to `path` whole or not at all (a temporary file renamed).
// @throws CommandError(kExitFailure) naming the path.
void WriteResultFile(const std::string& path, const std::string& text);

// "arena-<what>-campaign<ID>-<unix seconds>.json" in the current directory.
std::string RescuePath(const std::string& what, std::int64_t campaign);

// For db::RetryWhileBusy: says on stderr, every 5 s, that `command`'s
// finished result waits for another process's write lock (Ctrl-C saves it to
// `rescue` instead). Returns false once *cancel is set.
std::function<bool(double, const std::string&)> BusyStoreNotice(
    const std::string& command, const std::string& rescue, const std::function<bool()>& cancel);

}  // namespace arena::cli
