// Child processes owned by RAII: `arena run` starts its simulated cells this
// way. The destructor stops the child (SIGTERM, then SIGKILL after a grace
// period) so that no cell outlives the command that started it.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace arena::cli {

class LogPump;

class ChildProcess {
 public:
  // Starts argv[0] with argv; stdout and stderr go to log_path (appended),
  // or are inherited when log_path is empty. The log is bounded: a thread
  // copies the child's output into it and, past max_log_bytes, renames it
  // to log_path.1 (replacing the older one) and starts afresh, so a child
  // printing in a loop holds at most twice that on disk.
  // @throws std::runtime_error.
  static constexpr std::uintmax_t kMaxLogBytes = std::uintmax_t{16} << 20;
  ChildProcess(const std::vector<std::string>& argv, const std::string& log_path,
               std::uintmax_t max_log_bytes = kMaxLogBytes);
  ~ChildProcess();
  ChildProcess(ChildProcess&& other) noexcept;
  ChildProcess& operator=(ChildProcess&&) = delete;
  ChildProcess(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }
  // The exit status if the child has ended (without blocking), else nullopt.
  std::optional<int> Poll();
  // SIGTERM, wait up to grace, then SIGKILL; returns the exit status.
  int Stop(std::chrono::milliseconds grace = std::chrono::milliseconds(3000));

 private:
  pid_t pid_ = -1;
  std::optional<int> status_;
  std::shared_ptr<LogPump> pump_;  // copies the child's output into its log
};

// The path of the running executable (to start `arena cell` children).
std::string SelfExecutable();

}  // namespace arena::cli
