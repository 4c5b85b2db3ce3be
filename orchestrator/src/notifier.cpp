// `arena serve --notify`; the contract is in notifier.hpp.
#include "arena/orchestrator/notifier.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include <spdlog/spdlog.h>

extern char** environ;

namespace arena::orchestrator {

namespace {
using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Waits for `pid` until `deadline_s` after t0; @returns true with *status when it ended.
bool WaitUntil(pid_t pid, Clock::time_point t0, double deadline_s, int* status) {
  for (;;) {
    const pid_t r = waitpid(pid, status, WNOHANG);
    if (r == pid) return true;
    if (r < 0 && errno != EINTR) {
      *status = 0;
      return true;  // not our child any more (nothing to wait for)
    }
    if (Since(t0) >= deadline_s) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}
}  // namespace

Notifier::Notifier(std::string command, double timeout_s, std::size_t capacity)
    : command_(std::move(command)), timeout_s_(timeout_s), capacity_(capacity) {
  if (command_.empty()) throw std::invalid_argument("--notify: the command is empty");
  if (!std::isfinite(timeout_s) || timeout_s <= 0 || timeout_s > 3600)
    throw std::invalid_argument("--notify-timeout: must be a number of seconds in (0, 3600], got " +
                                std::to_string(timeout_s));
  if (capacity < 1 || capacity > 100000)
    throw std::invalid_argument("--notify-queue: must be 1..100000 events, got " +
                                std::to_string(capacity));
  worker_ = std::thread([this] { Work(); });
}

Notifier::~Notifier() {
  {
    std::lock_guard lock(mu_);
    stop_ = true;
    if (!queue_.empty())
      spdlog::warn("notify: {} events not handed to the command at stop (they are in the store)",
                   queue_.size());
    queue_.clear();
  }
  cv_.notify_all();
  worker_.join();
}

bool Notifier::Post(std::string event_json) {
  {
    std::lock_guard lock(mu_);
    if (queue_.size() >= capacity_) {
      ++counters_.dropped;
      spdlog::warn("notify: queue full ({} events waiting on a slow command); event dropped: {}",
                   queue_.size(), event_json);
      return false;
    }
    queue_.push_back(std::move(event_json));
    ++counters_.posted;
  }
  cv_.notify_one();
  return true;
}

NotifierCounters Notifier::counters() const {
  std::lock_guard lock(mu_);
  return counters_;
}

bool Notifier::Drain(double timeout_s) {
  std::unique_lock lock(mu_);
  return idle_cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                           [&] { return queue_.empty() && !busy_; });
}

void Notifier::Work() {
  // A command that exits without reading its stdin: write() fails with EPIPE
  // instead of the signal ending the service (blocked in this thread only).
  sigset_t pipe_set;
  sigemptyset(&pipe_set);
  sigaddset(&pipe_set, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &pipe_set, nullptr);
  for (;;) {
    std::string event;
    {
      std::unique_lock lock(mu_);
      busy_ = false;
      idle_cv_.notify_all();
      cv_.wait(lock, [&] { return stop_ || !queue_.empty(); });
      if (stop_) return;
      event = std::move(queue_.front());
      queue_.pop_front();
      busy_ = true;
    }
    const Outcome o = RunOnce(event + "\n");
    std::lock_guard lock(mu_);
    if (o == Outcome::kOk)
      ++counters_.delivered;
    else if (o == Outcome::kTimedOut)
      ++counters_.timed_out;
    else
      ++counters_.failed;
  }
}

Notifier::Outcome Notifier::RunOnce(const std::string& input) {
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) {
    spdlog::error("notify: pipe: {}", std::strerror(errno));
    return Outcome::kFailed;
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[0], STDIN_FILENO);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  posix_spawnattr_setpgroup(&attr, 0);  // its own group: a timeout kills all it started
  sigset_t none;
  sigemptyset(&none);
  posix_spawnattr_setsigmask(&attr, &none);
  sigset_t dflt;
  sigemptyset(&dflt);
  sigaddset(&dflt, SIGPIPE);
  sigaddset(&dflt, SIGTERM);
  sigaddset(&dflt, SIGINT);
  posix_spawnattr_setsigdefault(&attr, &dflt);
  posix_spawnattr_setflags(&attr,
                           POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  const char* argv[] = {"/bin/sh", "-c", command_.c_str(), nullptr};
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, "/bin/sh", &actions, &attr, const_cast<char**>(argv), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  close(fds[0]);
  if (rc != 0) {
    close(fds[1]);
    spdlog::error("notify: cannot start /bin/sh -c '{}': {}", command_, std::strerror(rc));
    return Outcome::kFailed;
  }
  const auto t0 = Clock::now();
  // Write the event without blocking past the timeout (a command that never
  // reads its stdin must not hold us on a full pipe); EPIPE: it did not read.
  fcntl(fds[1], F_SETFL, O_NONBLOCK);
  std::size_t off = 0;
  while (off < input.size() && Since(t0) < timeout_s_) {
    const ssize_t n = ::write(fds[1], input.data() + off, input.size() - off);
    if (n > 0) {
      off += static_cast<std::size_t>(n);
    } else if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
      pollfd p{fds[1], POLLOUT, 0};
      poll(&p, 1, 50);
    } else {
      break;  // EPIPE: the command does not read its stdin (SIGPIPE is blocked here)
    }
  }
  close(fds[1]);
  int status = 0;
  if (!WaitUntil(pid, t0, timeout_s_, &status)) {
    spdlog::warn("notify: '{}' still running after {} s; killing its process group", command_,
                 timeout_s_);
    kill(-pid, SIGTERM);
    if (!WaitUntil(pid, Clock::now(), 1.0, &status)) {
      kill(-pid, SIGKILL);
      WaitUntil(pid, Clock::now(), 5.0, &status);
    }
    kill(-pid, SIGKILL);  // anything of its group still there
    return Outcome::kTimedOut;
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return Outcome::kOk;
  if (WIFEXITED(status))
    spdlog::warn("notify: '{}' exited {}", command_, WEXITSTATUS(status));
  else if (WIFSIGNALED(status))
    spdlog::warn("notify: '{}' killed by signal {}", command_, WTERMSIG(status));
  return Outcome::kFailed;
}

}  // namespace arena::orchestrator
