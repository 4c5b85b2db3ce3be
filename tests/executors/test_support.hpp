// Helpers for the DDS tests: a test-unique domain id, cell processes that
// die with the test, a driver participant, canonical scenes.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "arena/schemas/arena.h"
#include "arena/schemas/dds.hpp"

namespace arena::test {

using namespace std::chrono_literals;

// A domain id in 10..229 that no other process on this host holds: each
// (process, salt) claims one host-wide (dds::HostDomainClaim, the same lock
// `arena run` takes for the domain it picks), held until the process exits
// (the kernel drops it even on a crash). A pid-derived id alone collided when
// suites from several worktrees ran at once. The same salt gives the same id
// within a process; cells started by the test are told the id on their
// command line.
inline int TestDomain(int salt = 0) {
  static std::mutex mutex;
  static std::map<int, int> claimed;  // salt -> domain id
  static std::vector<dds::HostDomainClaim> held;
  std::lock_guard<std::mutex> lock(mutex);
  if (auto it = claimed.find(salt); it != claimed.end()) return it->second;
  constexpr unsigned kFirst = 10, kCount = 220;  // Fast DDS ports need id <= 232
  const unsigned start = static_cast<unsigned>(getpid()) * 7u + static_cast<unsigned>(salt) * 13u;
  for (unsigned probe = 0; probe < kCount; ++probe) {
    const int domain = static_cast<int>(kFirst + (start + probe) % kCount);
    auto claim = dds::HostDomainClaim::TryClaim(domain);  // fails for ids held here too
    if (!claim) continue;
    held.push_back(std::move(*claim));
    claimed[salt] = domain;
    return domain;
  }
  // Every id held (220 test processes at once): fall back to the old
  // pid-derived id rather than fail.
  const int domain = static_cast<int>(kFirst + start % kCount);
  claimed[salt] = domain;
  return domain;
}

inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The canonical scene (examples/scenes/canonical.json) with another duration
// and pusher speed.
inline std::string CanonicalScene(double duration_s, double pusher_vz = 0.001) {
  std::ostringstream s;
  s << R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2,
              "pose": {"position": [0, 0, 0], "rpy": [0, 0, 0]}},
  "gravity": [0, 0, -9.81], "duration": )"
    << duration_s << R"(, "grip_force": 10.0,
  "fingers": [
    {"name": "left",  "type": "point", "position": [-0.025, 0, 0], "normal": [1, 0, 0], "mu": 0.5},
    {"name": "right", "type": "line",  "position": [0.025, 0, 0], "normal": [-1, 0, 0],
     "axis": [0, 0, 1], "length": 0.02, "mu": 0.5}],
  "pusher": {"type": "point", "position": [0, 0, -0.05], "normal": [0, 0, 1], "mu": 0.3,
             "motion": {"velocity": [0, 0, )"
    << pusher_vz << R"(], "angular_velocity": [0, 0, 0]}},
  "model": {"facets": 8, "points": 3, "dt": 0.004, "reduce": "auto"}})";
  return s.str();
}

// A child process killed (SIGKILL) and reaped in the destructor, and killed by
// the kernel if the test process dies first (PR_SET_PDEATHSIG).
class Child {
 public:
  Child(const std::vector<std::string>& argv, const std::string& log_path) {
    pid_ = fork();
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      const int fd = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) {
        dup2(fd, 1);
        dup2(fd, 2);
        close(fd);
      }
      std::vector<char*> args;
      for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      execv(args[0], args.data());
      _exit(127);
    }
  }
  ~Child() {
    if (pid_ > 0 && !status_) {
      kill(pid_, SIGKILL);
      int st = 0;
      waitpid(pid_, &st, 0);
    }
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  pid_t pid() const { return pid_; }
  void Signal(int sig) {
    if (pid_ > 0 && !status_) kill(pid_, sig);
  }
  // The exit status once the child ended, waiting up to timeout.
  std::optional<int> Wait(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!status_) {
      int st = 0;
      if (waitpid(pid_, &st, WNOHANG) == pid_) {
        status_ = st;
        break;
      }
      if (std::chrono::steady_clock::now() > deadline) break;
      std::this_thread::sleep_for(10ms);
    }
    return status_;
  }

 private:
  pid_t pid_ = -1;
  std::optional<int> status_;
};

// The service side of a test: commands out, announcements, statuses and
// ground truth in.
struct Driver {
  explicit Driver(int domain, dds::NetworkOptions network = {})
      : participant(Options(domain, std::move(network))),
        announcements(participant),
        commands(participant),
        statuses(participant),
        ground_truth(participant) {}

  static dds::ParticipantOptions Options(int domain, dds::NetworkOptions network) {
    dds::ParticipantOptions o;
    o.domain_id = domain;
    o.name = "arena.test-driver";
    o.network = std::move(network);
    return o;
  }

  // Waits for the announcements of every cell in ids.
  bool WaitForCells(const std::vector<std::string>& ids, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      bool all = true;
      for (const auto& id : ids) all = all && seen.count(id) > 0;
      if (all) return true;
      const auto left = deadline - std::chrono::steady_clock::now();
      if (left <= 0ms) return false;
      if (auto a =
              announcements.Take(std::chrono::duration_cast<std::chrono::milliseconds>(left))) {
        seen[a->cell_id()] = *a;
      }
    }
  }

  msg::TrialCommand Command(const std::string& cell, std::uint64_t trial, msg::Phase phase,
                            const std::string& scene, std::uint64_t seed = 7,
                            std::uint32_t attempt = 1) {
    msg::TrialCommand c;
    c.cell_id(cell);
    c.trial_id(trial);
    c.attempt(attempt);
    c.phase(phase);
    c.scene_json(scene);
    c.seed(seed);
    c.deadline_s(60);
    c.service_session(session);
    return c;
  }

  // PHASE_CLAIM for `lease_s` (0 releases the cell).
  msg::TrialCommand Claim(const std::string& cell, double lease_s) {
    msg::TrialCommand c;
    c.cell_id(cell);
    c.phase(msg::PHASE_CLAIM);
    c.service_session(session);
    c.lease_s(lease_s);
    c.service_host("test-host");
    c.service_pid(1);
    return c;
  }

  bool Send(msg::TrialCommand c) { return commands.Write(c); }

  // The next status for (trial, attempt) whose state is not ACCEPTED.
  std::optional<msg::TrialStatus> FinalStatus(std::uint64_t trial,
                                              std::chrono::milliseconds timeout) {
    for (auto it = other_statuses.begin(); it != other_statuses.end(); ++it) {
      if (it->trial_id() == trial && it->state() != msg::STATE_ACCEPTED) {
        msg::TrialStatus s = *it;
        other_statuses.erase(it);
        return s;
      }
    }
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      const auto left = deadline - std::chrono::steady_clock::now();
      if (left <= 0ms) return std::nullopt;
      auto s = statuses.Take(std::chrono::duration_cast<std::chrono::milliseconds>(left));
      if (!s) return std::nullopt;
      if (s->trial_id() == trial && s->state() != msg::STATE_ACCEPTED) return s;
      if (s->state() != msg::STATE_ACCEPTED) other_statuses.push_back(*s);
    }
  }

  dds::Participant participant;
  dds::Reader<msg::CellAnnounce> announcements;
  dds::Writer<msg::TrialCommand> commands;
  dds::Reader<msg::TrialStatus> statuses;
  dds::Reader<msg::GroundTruth> ground_truth;
  std::map<std::string, msg::CellAnnounce> seen;
  std::uint64_t session = 0x7e57d21e;  // this driver's service session
  std::vector<msg::TrialStatus> other_statuses;
};

}  // namespace arena::test
