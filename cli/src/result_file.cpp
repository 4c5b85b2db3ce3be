#include "result_file.hpp"

#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <memory>

#include "command_error.hpp"

namespace arena::cli {

void WriteResultFile(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw CommandError(kExitFailure, "cannot write '" + path + "': " + std::strerror(errno));
  const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size() &&
                  std::fflush(f) == 0 && ::fsync(::fileno(f)) == 0;
  const int err = errno;
  std::fclose(f);
  if (!ok || std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int why = ok ? errno : err;
    std::remove(tmp.c_str());
    throw CommandError(kExitFailure, "cannot write '" + path + "': " + std::strerror(why));
  }
}

std::string RescuePath(const std::string& what, std::int64_t campaign) {
  return "arena-" + what + "-campaign" + std::to_string(campaign) + "-" +
         std::to_string(static_cast<long long>(std::time(nullptr))) + ".json";
}

std::function<bool(double, const std::string&)> BusyStoreNotice(
    const std::string& command, const std::string& rescue, const std::function<bool()>& cancel) {
  auto next = std::make_shared<double>(0.0);
  return [command, rescue, cancel, next](double waited, const std::string&) {
    if (cancel && cancel()) return false;
    if (waited >= *next) {
      const std::string on_interrupt =
          rescue.empty() ? "Ctrl-C gives up" : "Ctrl-C saves the result to " + rescue + " instead";
      std::fprintf(stderr,
                   "%s: finished; the store is locked by another process, waiting to write "
                   "(%.0f s so far; %s)\n",
                   command.c_str(), waited, on_interrupt.c_str());
      *next = waited + 5.0;
    }
    return true;
  };
}

}  // namespace arena::cli
