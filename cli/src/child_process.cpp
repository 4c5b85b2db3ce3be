#include "child_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace arena::cli {

namespace {
int DecodeStatus(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}
}  // namespace

// Reads a child's output from a pipe into its log file, rotating the file
// to PATH.1 past `max` bytes. Ends when the pipe closes, or (after the child
// was stopped) once the pipe is drained: a grandchild holding the pipe open
// cannot keep it waiting.
class LogPump {
 public:
  LogPump(int fd, std::string path, std::uintmax_t max)
      : fd_(fd), path_(std::move(path)), max_(max), thread_([this] { Run(); }) {}
  ~LogPump() {
    stop_ = true;
    thread_.join();
    ::close(fd_);
  }
  LogPump(const LogPump&) = delete;
  LogPump& operator=(const LogPump&) = delete;

 private:
  void Run() {
    std::FILE* out = std::fopen(path_.c_str(), "ab");
    if (out) std::fseek(out, 0, SEEK_END);
    std::uintmax_t size = out ? static_cast<std::uintmax_t>(std::ftell(out)) : 0;
    char buf[65536];
    for (;;) {
      pollfd p{fd_, POLLIN, 0};
      const int r = ::poll(&p, 1, 100);
      if (r < 0 && errno == EINTR) continue;
      if (r == 0) {
        if (stop_) break;  // stopped and drained
        continue;
      }
      const ssize_t n = ::read(fd_, buf, sizeof buf);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;  // every writer closed it
      if (!out) continue;
      if (size + static_cast<std::uintmax_t>(n) > max_ && size > 0) {
        std::fclose(out);
        std::rename(path_.c_str(), (path_ + ".1").c_str());
        out = std::fopen(path_.c_str(), "ab");
        size = 0;
        if (!out) continue;
      }
      size += std::fwrite(buf, 1, static_cast<std::size_t>(n), out);
      std::fflush(out);
    }
    if (out) std::fclose(out);
  }

  int fd_;
  std::string path_;
  std::uintmax_t max_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

ChildProcess::ChildProcess(const std::vector<std::string>& argv, const std::string& log_path,
                           std::uintmax_t max_log_bytes) {
  if (argv.empty()) throw std::runtime_error("ChildProcess: empty argv");
  int out[2] = {-1, -1};
  if (!log_path.empty() && ::pipe2(out, O_CLOEXEC) != 0)
    throw std::runtime_error(std::string("cannot start ") + argv[0] +
                             ": pipe: " + std::strerror(errno));
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (!log_path.empty()) {
    posix_spawn_file_actions_adddup2(&actions, out[1], STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&actions, out[1], STDERR_FILENO);
  }
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const int rc = posix_spawn(&pid_, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (out[1] >= 0) ::close(out[1]);
  if (rc != 0) {
    if (out[0] >= 0) ::close(out[0]);
    pid_ = -1;
    throw std::runtime_error("cannot start " + argv[0] + ": " + std::strerror(rc));
  }
  if (out[0] >= 0) pump_ = std::make_shared<LogPump>(out[0], log_path, max_log_bytes);
}

ChildProcess::ChildProcess(ChildProcess&& other) noexcept
    : pid_(other.pid_), status_(other.status_), pump_(std::move(other.pump_)) {
  other.pid_ = -1;
}

ChildProcess::~ChildProcess() {
  if (pid_ > 0 && !status_) Stop();
  pump_.reset();  // drains what the child wrote last
}

std::optional<int> ChildProcess::Poll() {
  if (status_ || pid_ <= 0) return status_;
  int status = 0;
  const pid_t r = waitpid(pid_, &status, WNOHANG);
  if (r == pid_) status_ = DecodeStatus(status);
  return status_;
}

int ChildProcess::Stop(std::chrono::milliseconds grace) {
  if (pid_ <= 0) return -1;
  if (Poll()) return *status_;
  kill(pid_, SIGTERM);
  const auto deadline = std::chrono::steady_clock::now() + grace;
  while (std::chrono::steady_clock::now() < deadline) {
    if (Poll()) return *status_;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(pid_, SIGKILL);
  int status = 0;
  while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
  }
  status_ = DecodeStatus(status);
  return *status_;
}

std::string SelfExecutable() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n <= 0) throw std::runtime_error("cannot resolve /proc/self/exe");
  return std::string(buf, static_cast<size_t>(n));
}

}  // namespace arena::cli
