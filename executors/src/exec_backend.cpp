// exec:COMMAND: a driver process speaking the JSON-lines protocol
// (exec_protocol.hpp). Each sample line goes to the cell's sink as it is
// read (the cell streams it on at once); while the driver is quiet the cell
// is told (TrialContext::idle) so it can flush what it holds. Every failure
// of the driver fails the phase with a reason, kills the driver and leaves
// the next Prepare to start it afresh.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <thread>

#include <spdlog/spdlog.h>

#include "arena/executors/backend.hpp"
#include "arena/executors/exec_protocol.hpp"

namespace arena::executors {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

constexpr std::size_t kMaxLine = 4 << 20;  // a longer line is malformed output
// A driver's stderr reaches the log through the cell, at most this much per
// phase (a driver printing in a loop grew a cell's log by 200 MiB in two
// trials); the rest is counted and said once.
constexpr std::size_t kStderrPerPhase = 64 << 10;
// A driver log file (ExecBackendOptions::log_path) is rotated to PATH.1 past this size.
constexpr std::uintmax_t kDriverLogRotate = 16u << 20;

Clock::time_point After(double s) {
  return Clock::now() +
         std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

std::string DescribeWaitStatus(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    const char* name = strsignal(WTERMSIG(status));
    return std::string("killed by signal ") + std::to_string(WTERMSIG(status)) + " (" +
           (name ? name : "?") + ")";
  }
  return "ended (status " + std::to_string(status) + ")";
}

// One running driver: its pid and the two pipes.
class DriverProcess {
 public:
  enum class Read { kLine, kTimeout, kEof, kTooLong };

  DriverProcess(const std::string& command, const std::string& log_path) : log_path_(log_path) {
    int to_child[2], from_child[2], err[2];
    if (pipe2(to_child, O_CLOEXEC) != 0 || pipe2(from_child, O_CLOEXEC) != 0 ||
        pipe2(err, O_CLOEXEC) != 0)
      throw std::runtime_error(std::string("pipe: ") + std::strerror(errno));
    const pid_t parent = getpid();
    pid_ = fork();
    if (pid_ < 0) throw std::runtime_error(std::string("fork: ") + std::strerror(errno));
    if (pid_ == 0) {
      // Child: its own process group (so the whole driver can be killed), dies with the cell.
      setpgid(0, 0);
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(127);
      dup2(to_child[0], STDIN_FILENO);
      dup2(from_child[1], STDOUT_FILENO);
      dup2(err[1], STDERR_FILENO);  // read by the cell, capped per phase
      sigset_t none;
      sigemptyset(&none);
      sigprocmask(SIG_SETMASK, &none, nullptr);  // the cell blocks SIGTERM; the driver must not
      execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    setpgid(pid_, pid_);
    close(to_child[0]);
    close(from_child[1]);
    close(err[1]);
    in_ = to_child[1];
    out_ = from_child[0];
    err_ = err[0];
    fcntl(err_, F_SETFL, fcntl(err_, F_GETFL) | O_NONBLOCK);
    StartWatchdog();
  }
  ~DriverProcess() { Kill(); }
  DriverProcess(const DriverProcess&) = delete;
  DriverProcess& operator=(const DriverProcess&) = delete;

  // false when the driver no longer reads (it exited).
  bool Send(const json& message) {
    std::string line = message.dump() + "\n";
    std::size_t off = 0;
    while (off < line.size()) {
      const ssize_t n = write(in_, line.data() + off, line.size() - off);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return false;
      off += static_cast<std::size_t>(n);
    }
    return true;
  }

  // `idle` (may be empty) is called after each 50 ms without a line.
  Read ReadLine(Clock::time_point until, std::string* line,
                const std::function<void()>& idle = nullptr) {
    for (;;) {
      if (auto nl = buffer_.find('\n'); nl != std::string::npos) {
        *line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        return Read::kLine;
      }
      if (buffer_.size() > kMaxLine) return Read::kTooLong;
      if (eof_) return Read::kEof;
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - Clock::now());
      if (left.count() <= 0) return Read::kTimeout;
      pollfd p[2] = {{out_, POLLIN, 0}, {err_, POLLIN, 0}};
      const int r = poll(p, err_ >= 0 ? 2 : 1,
                         static_cast<int>(std::min<long long>(left.count(), idle ? 50 : 200)));
      if (r < 0 && errno != EINTR) return Read::kEof;
      if (r == 0 && idle) idle();  // the driver is quiet: the cell sends what it holds
      if (r > 0 && err_ >= 0 && (p[1].revents & (POLLIN | POLLHUP))) DrainStderr();
      if (r <= 0 || !(p[0].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      char chunk[65536];
      const ssize_t n = read(out_, chunk, sizeof chunk);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        eof_ = true;
        continue;
      }
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }

  // A new phase: a new stderr allowance (and a word on what the last one dropped).
  void NewPhase() {
    if (stderr_dropped_ > 0)
      WriteLog("[arena] driver stderr: " + std::to_string(stderr_dropped_) +
               " bytes dropped in the last phase (over " + std::to_string(kStderrPerPhase >> 10) +
               " KiB)");
    stderr_dropped_ = 0;
    stderr_left_ = kStderrPerPhase;
  }

  // How the driver ended (waits up to `grace` for it); "" if still running.
  std::string Ended(double grace_s) {
    if (!status_.empty()) return status_;
    const auto until = After(grace_s);
    for (;;) {
      int st = 0;
      const pid_t r = waitpid(pid_, &st, WNOHANG);
      if (r == pid_) {
        status_ = DescribeWaitStatus(st);
        return status_;
      }
      if (r < 0) return status_ = "gone";
      if (Clock::now() >= until) return "";
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }

  // Asks nicely (shutdown), then SIGTERM, then SIGKILL to the whole group.
  void Shutdown() {
    if (pid_ <= 0) return;
    Send(json{{"type", "shutdown"}});
    close(in_);
    in_ = -1;
    if (Ended(2.0).empty()) Kill();
    Close();
  }
  void Kill() {
    if (pid_ <= 0) return;
    if (status_.empty()) {
      kill(-pid_, SIGTERM);
      if (Ended(1.0).empty()) {
        kill(-pid_, SIGKILL);
        Ended(5.0);
      }
    }
    kill(-pid_, SIGKILL);  // anything the driver left in its group
    if (watchdog_ > 0) {   // its work is done: it must not kill a reused group id later
      kill(watchdog_, SIGKILL);
      waitpid(watchdog_, nullptr, 0);
      watchdog_ = -1;
    }
    Close();
    pid_ = -1;
  }

 private:
  void Close() {
    if (err_ >= 0) DrainStderr();
    if (in_ >= 0) close(in_);
    if (out_ >= 0) close(out_);
    if (err_ >= 0) close(err_);
    if (watch_fd_ >= 0) close(watch_fd_);  // EOF: the watchdog ends (killing what is left)
    if (watchdog_ > 0) waitpid(watchdog_, nullptr, 0);
    in_ = out_ = err_ = watch_fd_ = -1;
    watchdog_ = -1;
  }

  // PR_SET_PDEATHSIG reaches the driver's shell only, not what it started:
  // a SIGKILLed cell left the driver's own children running. A watchdog
  // process (a shell, exec'd: it holds none of the cell's descriptors) waits
  // for EOF on a pipe only the cell writes to; the cell's death, however it
  // dies, closes that pipe, and the watchdog kills the driver's whole group.
  void StartWatchdog() {
    int w[2];
    if (pipe2(w, O_CLOEXEC) != 0) return;
    const std::string script =
        "read -r _; kill -9 -" + std::to_string(pid_) + " 2>/dev/null; exit 0";
    const pid_t wd = fork();
    if (wd == 0) {
      setpgid(0, 0);  // not in the cell's group (a group kill of the cell must not take it)
      dup2(w[0], STDIN_FILENO);
      const int null = open("/dev/null", O_WRONLY);
      if (null >= 0) {
        dup2(null, STDOUT_FILENO);
        dup2(null, STDERR_FILENO);
      }
      sigset_t none;
      sigemptyset(&none);
      sigprocmask(SIG_SETMASK, &none, nullptr);
      signal(SIGTERM, SIG_IGN);  // only the pipe's EOF (or the cell's SIGKILL) ends it
      signal(SIGINT, SIG_IGN);
      signal(SIGHUP, SIG_IGN);
      execl("/bin/sh", "sh", "-c", script.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    close(w[0]);
    if (wd < 0) {
      close(w[1]);
      return;
    }
    watchdog_ = wd;
    watch_fd_ = w[1];
  }

  void WriteLog(const std::string& line) {
    if (log_path_.empty()) {
      spdlog::info("driver: {}", line);
      return;
    }
    std::error_code ec;
    if (std::filesystem::file_size(log_path_, ec) > kDriverLogRotate && !ec)
      std::filesystem::rename(log_path_, log_path_ + ".1", ec);
    const int fd = open(log_path_.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0) return;
    const std::string text = line + "\n";
    [[maybe_unused]] const ssize_t n = write(fd, text.data(), text.size());
    close(fd);
  }

  // What the driver wrote on stderr, line by line into the log, up to the
  // phase's allowance.
  void DrainStderr() {
    char chunk[65536];
    for (int reads = 0; reads < 64 && err_ >= 0; ++reads) {  // a fast writer cannot hold us here
      const ssize_t n = read(err_, chunk, sizeof chunk);
      if (n < 0 && errno == EINTR) continue;
      if (n == 0) {  // the driver closed its stderr: stop polling it
        close(err_);
        err_ = -1;
        break;
      }
      if (n < 0) break;
      err_buffer_.append(chunk, static_cast<std::size_t>(n));
      std::size_t start = 0;
      for (;;) {
        std::size_t nl = err_buffer_.find('\n', start);
        if (nl == std::string::npos && err_buffer_.size() - start > 4096)
          nl = start + 4096;  // a long line without an end: logged in pieces
        if (nl == std::string::npos) break;
        const std::string line = err_buffer_.substr(start, nl - start);
        start = std::min(err_buffer_.size(), nl + (err_buffer_[nl] == '\n' ? 1 : 0));
        if (line.size() + 1 <= stderr_left_) {
          stderr_left_ -= line.size() + 1;
          WriteLog(line);
        } else {
          if (stderr_dropped_ == 0)
            WriteLog("[arena] driver stderr: over " + std::to_string(kStderrPerPhase >> 10) +
                     " KiB in this phase; the rest of it is dropped");
          stderr_dropped_ += line.size() + 1;
        }
      }
      err_buffer_.erase(0, start);
    }
  }

  std::string log_path_;
  int err_ = -1;
  int watch_fd_ = -1;
  pid_t watchdog_ = -1;
  std::string err_buffer_;
  std::size_t stderr_left_ = kStderrPerPhase;
  std::uint64_t stderr_dropped_ = 0;
  pid_t pid_ = -1;
  int in_ = -1, out_ = -1;
  std::string buffer_;
  bool eof_ = false;
  std::string status_;
};

bool MentionsNonFinite(const std::string& line) {
  return line.find("NaN") != std::string::npos || line.find("Infinity") != std::string::npos;
}

mechanics::ContactType ParseType(const std::string& s) {
  if (s == "point") return mechanics::ContactType::kPoint;
  if (s == "line") return mechanics::ContactType::kLine;
  if (s == "patch") return mechanics::ContactType::kPatch;
  throw std::invalid_argument("hello.contact_types: unknown type '" + s + "'");
}

json PoseJson(const reset::Pose& p) {
  return {{"position", {p.position.x(), p.position.y(), p.position.z()}},
          {"orientation",
           {p.orientation.w(), p.orientation.x(), p.orientation.y(), p.orientation.z()}}};
}

class ExecBackend final : public Backend {
 public:
  explicit ExecBackend(const ExecBackendOptions& o) : options_(o) {
    struct sigaction ignore {};
    ignore.sa_handler = SIG_IGN;
    sigaction(SIGPIPE, &ignore, nullptr);  // a dead driver's pipe is an error return, not a kill
    if (std::string why = Start(); !why.empty()) throw std::invalid_argument(why);
  }
  ~ExecBackend() override {
    if (driver_) driver_->Shutdown();
  }

  BackendCapabilities Capabilities() const override { return caps_; }

  std::string Prepare(const mechanics::Scene&, const TrialContext& trial) override {
    if (!driver_) {
      if (std::string why = Start(); !why.empty()) return why;
    }
    json scene = json::parse(trial.scene_json, nullptr, false);
    if (scene.is_discarded()) scene = nullptr;
    StartPhase();
    if (!driver_->Send({{"type", "prepare"},
                        {"trial_id", trial.trial_id},
                        {"attempt", trial.attempt},
                        {"seed", trial.seed},
                        {"scene", scene}}))
      return Fail("prepare", "driver " + Gone());
    json reply;
    if (std::string why = Await("prepare", Deadline(trial), &reply); !why.empty()) return why;
    const std::string type = reply.value("type", "");
    if (type == "ready") return "";
    if (type == "refused") {
      const auto r = reply.find("reason");
      return "driver refused: " + (r != reply.end() && r->is_string() ? r->get<std::string>()
                                                                      : std::string("(no reason)"));
    }
    return Fail("prepare",
                "driver: malformed output: expected ready or refused, got '" + type + "'");
  }

  ExecuteOutcome Execute(const mechanics::Scene&, const TrialContext& trial,
                         const SampleSink& sink) override {
    ExecuteOutcome out;
    const auto started = Clock::now();
    if (!driver_) {
      out.reason = "driver: not running";
      return out;
    }
    const double left = trial.deadline == Clock::time_point::max()
                            ? 0.0
                            : std::chrono::duration<double>(trial.deadline - Clock::now()).count();
    StartPhase();
    if (!driver_->Send({{"type", "execute"},
                        {"trial_id", trial.trial_id},
                        {"attempt", trial.attempt},
                        {"deadline_s", left}})) {
      out.reason = Fail("execute", "driver " + Gone());
      return out;
    }
    std::size_t count = 0;
    for (;;) {
      json msg;
      if (std::string why = Await("execute", Deadline(trial), &msg, trial.idle); !why.empty()) {
        out.reason = why;
        return out;
      }
      const std::string type = msg.value("type", "");
      const auto feed = [&](const json& j) -> bool {
        mechanics::TrajectorySample s;
        if (std::string why = exec::ParseSample(j, &s); !why.empty()) {
          out.reason =
              Fail("execute", "driver: malformed sample " + std::to_string(count) + ": " + why);
          return false;
        }
        ++count;
        if (!sink(s)) {
          // The cell refused the sample (NaN, order) or stops: the stream is
          // out of step now, so the driver starts afresh for the next trial.
          out.reason =
              "driver: stream stopped by the cell after " + std::to_string(count) + " samples";
          Restart();
          return false;
        }
        return true;
      };
      if (type == "sample") {
        if (!feed(msg)) return out;
      } else if (type == "samples") {
        const auto it = msg.find("samples");
        if (it == msg.end() || !it->is_array()) {
          out.reason = Fail("execute", "driver: malformed output: samples without an array");
          return out;
        }
        for (const auto& j : *it)
          if (!feed(j)) return out;
      } else if (type == "done") {
        out.ok = true;
        const auto d = msg.find("detail");
        json detail = d != msg.end() && d->is_object() ? *d : json::object();
        detail["driver_samples"] = count;
        detail["simulate_wall_s"] = std::chrono::duration<double>(Clock::now() - started).count();
        out.detail_json = detail.dump();
        return out;
      } else if (type == "failed") {
        const auto r = msg.find("reason");
        out.reason =
            "driver failed: " +
            (r != msg.end() && r->is_string() ? r->get<std::string>() : std::string("(no reason)"));
        return out;
      } else {
        out.reason = Fail("execute", "driver: malformed output: unexpected message type '" + type +
                                         "' during execute");
        return out;
      }
    }
  }

  std::optional<BackendResetOutcome> Reset(const BackendResetRequest& request,
                                           const TrialContext& trial) override {
    if (!resets_) return std::nullopt;
    BackendResetOutcome out;
    if (!driver_) {
      if (std::string why = Start(); !why.empty()) {
        out.reason = why;
        return out;
      }
    }
    json scene = json::parse(request.next_scene_json, nullptr, false);
    if (scene.is_discarded() || request.next_scene_json.empty()) scene = nullptr;
    StartPhase();
    if (!driver_->Send({{"type", "reset"},
                        {"trial_id", trial.trial_id},
                        {"attempt", trial.attempt},
                        {"target", PoseJson(request.target)},
                        {"scene", scene}})) {
      out.reason = Fail("reset", "driver " + Gone());
      return out;
    }
    json msg;
    if (std::string why = Await("reset", Deadline(trial), &msg); !why.empty()) {
      out.reason = why;
      return out;
    }
    const std::string type = msg.value("type", "");
    out.attempts = msg.value("attempts", 1);
    if (type == "reset_failed") {
      out.reason = "driver: reset failed: " + msg.value("reason", std::string("(no reason)"));
      return out;
    }
    if (type != "reset_done") {
      out.reason = Fail("reset", "driver: malformed output: expected reset_done or reset_failed");
      return out;
    }
    try {
      const auto& a = msg.at("achieved");
      const auto& p = a.at("position");
      const auto& q = a.at("orientation");
      out.achieved.position = {p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>()};
      out.achieved.orientation = Eigen::Quaterniond(q.at(0).get<double>(), q.at(1).get<double>(),
                                                    q.at(2).get<double>(), q.at(3).get<double>())
                                     .normalized();
      if (!out.achieved.position.allFinite() || !out.achieved.orientation.coeffs().allFinite())
        throw std::invalid_argument("non-finite");
    } catch (const std::exception&) {
      out.reason = Fail("reset",
                        "driver: malformed output: reset_done.achieved needs position[3] "
                        "and orientation[4] (finite)");
      return out;
    }
    out.ok = true;
    return out;
  }

 private:
  Clock::time_point Deadline(const TrialContext& trial) const {
    return std::min(trial.deadline, After(options_.reply_timeout_s));
  }

  void StartPhase() {
    phase_lines_ = 0;
    if (driver_) driver_->NewPhase();
  }

  std::string Gone() {
    const std::string how = driver_ ? driver_->Ended(1.0) : "";
    return "crashed: " + (how.empty() ? std::string("stopped reading its input") : how);
  }

  // Ends the driver; the next Prepare starts a new one.
  void Restart() {
    if (driver_) driver_->Kill();
    driver_.reset();
    ++restarts_;
  }
  std::string Fail(const char* phase, const std::string& reason) {
    spdlog::warn("exec backend: {} failed: {}; restarting the driver", phase, reason);
    Restart();
    return reason;
  }

  // One message; "" or the reason the phase fails.
  std::string Await(const char* phase, Clock::time_point until, json* msg,
                    const std::function<void()>& idle = nullptr) {
    // Which limit binds, known before waiting: the phase's deadline when it
    // comes before the reply timeout.
    const double waited = options_.reply_timeout_s;
    const bool deadline = until < After(waited - 0.5);
    for (;;) {
      std::string line;
      switch (driver_->ReadLine(until, &line, idle)) {
        case DriverProcess::Read::kTimeout: {
          if (phase_lines_ > 0 && deadline &&
              Clock::now() - last_line_at_ < std::chrono::seconds(1)) {
            // It talks, it just never finishes: not a hang.
            return Fail(phase, "driver overran the phase's deadline: still sending (" +
                                   std::to_string(phase_lines_) + " lines in this " + phase +
                                   ", no done)");
          }
          return Fail(phase, deadline
                                 ? std::string("driver hung: no reply before the phase's deadline")
                                 : "driver hung: no reply within " + std::to_string(waited) + " s");
        }
        case DriverProcess::Read::kEof:
          return Fail(phase, "driver " + Gone());
        case DriverProcess::Read::kTooLong:
          return Fail(phase, "driver: malformed output: a line longer than 4 MiB");
        case DriverProcess::Read::kLine:
          break;
      }
      if (line.empty()) continue;
      ++phase_lines_;
      last_line_at_ = Clock::now();
      try {
        *msg = json::parse(line);
      } catch (const json::out_of_range&) {
        // Valid JSON syntax, a number no double holds (1e999).
        return Fail(phase, "driver: a number out of range (beyond a double) in its output: " +
                               line.substr(0, 120));
      } catch (const json::exception&) {
        if (MentionsNonFinite(line))
          return Fail(phase, "driver: non-finite number (NaN or Infinity) in its output");
        return Fail(phase, "driver: malformed output (not JSON): " + line.substr(0, 120));
      }
      if (!msg->is_object() || !msg->contains("type") || !(*msg)["type"].is_string())
        return Fail(phase, "driver: malformed output (not an object with a \"type\"): " +
                               line.substr(0, 120));
      if ((*msg)["type"] == "error") {
        return Fail(phase, "driver error: " + msg->value("message", std::string("(no message)")));
      }
      if ((*msg)["type"] == "log") continue;  // free text for the cell's log
      return "";
    }
  }

  std::string Start() {
    try {
      driver_ = std::make_unique<DriverProcess>(options_.command, options_.log_path);
    } catch (const std::exception& e) {
      driver_.reset();
      return "driver '" + options_.command + "' cannot start: " + e.what();
    }
    json hello;
    if (std::string why = Await("hello", After(options_.hello_timeout_s), &hello); !why.empty())
      return "driver '" + options_.command + "': no hello: " + why;
    try {
      if (hello.value("type", "") != "hello")
        throw std::invalid_argument("first message must be hello");
      if (hello.value("protocol", 0) != exec::kProtocolVersion)
        throw std::invalid_argument("protocol " + hello.value("protocol", json(nullptr)).dump() +
                                    " is not supported (this cell speaks " +
                                    std::to_string(exec::kProtocolVersion) + ")");
      BackendCapabilities c;
      c.name = "exec:" + options_.command;
      c.truth = ParseTruthSource(hello.value("truth", std::string("robot")));
      c.engine = hello.value("engine", hello.value("name", std::string("driver")));
      if (auto it = hello.find("contact_types"); it != hello.end())
        for (const auto& t : *it) c.contact_types.push_back(ParseType(t.get<std::string>()));
      c.emulates_defects = hello.value("emulates_defects", false);
      c.settings_json = json({{"hello", hello}}).dump();
      resets_ = hello.value("resets", false);
      if (auto it = hello.find(schemas::kChangeCostsKey); it != hello.end()) {
        if (!it->is_object())
          throw std::invalid_argument("hello.fixture_changes: must be an object");
        schemas::ChangeCosts costs;
        for (auto [key, out] :
             {std::pair{"finger_s", &costs.finger_s}, std::pair{"pusher_s", &costs.pusher_s},
              std::pair{"object_s", &costs.object_s}}) {
          if (!it->contains(key) || !(*it)[key].is_number())
            throw std::invalid_argument(std::string("hello.fixture_changes.") + key +
                                        ": a number of seconds is required");
          *out = (*it)[key].get<double>();
        }
        if (std::string why = schemas::CheckChangeCosts(costs); !why.empty())
          throw std::invalid_argument("hello.fixture_changes." + why);
        c.change_costs = costs;
      }
      caps_ = c;
    } catch (const std::exception& e) {
      Fail("hello", e.what());
      return "driver '" + options_.command + "': bad hello: " + e.what();
    }
    if (restarts_ > 0) spdlog::info("exec backend: driver restarted ({} restarts)", restarts_);
    return "";
  }

  ExecBackendOptions options_;
  std::unique_ptr<DriverProcess> driver_;
  BackendCapabilities caps_;
  bool resets_ = false;
  int restarts_ = 0;
  std::size_t phase_lines_ = 0;  // lines the driver sent since the phase began
  Clock::time_point last_line_at_{};
};

std::string Vec3(const nlohmann::json& j, const char* key, Eigen::Vector3d* out, bool required) {
  const auto it = j.find(key);
  if (it == j.end()) return required ? std::string(key) + ": missing" : "";
  if (!it->is_array() || it->size() != 3) return std::string(key) + ": must be 3 numbers";
  for (int k = 0; k < 3; ++k) {
    if (!(*it)[k].is_number()) return std::string(key) + ": must be 3 finite numbers";
    (*out)[k] = (*it)[k].get<double>();
  }
  return "";
}

}  // namespace

namespace exec {

std::string ParseSample(const json& j, mechanics::TrajectorySample* s) {
  if (!j.is_object()) return "not an object";
  const auto t = j.find("t");
  if (t == j.end() || !t->is_number()) return "t: must be a number (s)";
  s->t = t->get<double>();
  for (auto [key, out, required] :
       {std::tuple{"position", &s->position, true}, std::tuple{"velocity", &s->velocity, false},
        std::tuple{"angular_velocity", &s->angular_velocity, false},
        std::tuple{"pusher_position", &s->pusher_position, false},
        std::tuple{"pusher_force", &s->pusher_force, false}}) {
    if (std::string why = Vec3(j, key, out, required); !why.empty()) return why;
  }
  const auto q = j.find("orientation");
  if (q == j.end() || !q->is_array() || q->size() != 4) return "orientation: must be [w, x, y, z]";
  for (int k = 0; k < 4; ++k)
    if (!(*q)[k].is_number()) return "orientation: must be 4 finite numbers";
  s->orientation = Eigen::Quaterniond((*q)[0].get<double>(), (*q)[1].get<double>(),
                                      (*q)[2].get<double>(), (*q)[3].get<double>());
  const auto cs = j.find("contacts");
  if (cs == j.end() || !cs->is_array()) return "contacts: must be an array (fingers, then pusher)";
  s->contacts.clear();
  for (const auto& c : *cs) {
    if (!c.is_object()) return "contacts[]: must be objects";
    mechanics::ContactState st;
    const auto n = c.find("normal_force");
    if (n == c.end() || !n->is_number()) return "contacts[].normal_force: must be a number";
    st.normal_force = n->get<double>();
    if (std::string why = Vec3(c, "tangential_force", &st.tangential_force, false); !why.empty())
      return "contacts[]." + why;
    if (std::string why = Vec3(c, "torque", &st.torque, false); !why.empty())
      return "contacts[]." + why;
    const std::string mode = c.value("mode", "");
    if (mode == "stick")
      st.mode = mechanics::ContactMode::kStick;
    else if (mode == "slide")
      st.mode = mechanics::ContactMode::kSlide;
    else if (mode == "separate")
      st.mode = mechanics::ContactMode::kSeparate;
    else
      return "contacts[].mode: must be stick, slide or separate";
    s->contacts.push_back(st);
  }
  return "";
}

json SampleToJson(const mechanics::TrajectorySample& s) {
  const auto v = [](const Eigen::Vector3d& x) { return json::array({x.x(), x.y(), x.z()}); };
  json contacts = json::array();
  for (const auto& c : s.contacts) {
    contacts.push_back({{"normal_force", c.normal_force},
                        {"tangential_force", v(c.tangential_force)},
                        {"torque", v(c.torque)},
                        {"mode", mechanics::ToString(c.mode)}});
  }
  return {
      {"type", "sample"},
      {"t", s.t},
      {"position", v(s.position)},
      {"orientation", {s.orientation.w(), s.orientation.x(), s.orientation.y(), s.orientation.z()}},
      {"velocity", v(s.velocity)},
      {"angular_velocity", v(s.angular_velocity)},
      {"pusher_position", v(s.pusher_position)},
      {"pusher_force", v(s.pusher_force)},
      {"contacts", contacts}};
}

}  // namespace exec

std::unique_ptr<Backend> MakeExecBackend(const ExecBackendOptions& options) {
  return std::make_unique<ExecBackend>(options);
}

}  // namespace arena::executors
