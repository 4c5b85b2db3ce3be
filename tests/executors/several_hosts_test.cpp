// Several hosts: the service side and two cells in separate network
// namespaces joined by veth pairs on a bridge, with addresses (10.77.0.0/24)
// that exist only inside those namespaces. The test creates and removes the
// namespaces itself; where it cannot (not root, no `ip netns`), it is
// SKIPPED with the reason, never passed.
//
//   ns S (driver, bridge br0 10.77.0.1) --veth-- ns A (cell a, 10.77.0.2)
//                                       --veth-- ns B (cell b, 10.77.0.3; cell hidden, no --peers)
//
// Shared memory is off in every process (--no-shm): namespaces share
// /dev/shm, and the point is to cross the (virtual) network.
#include <fcntl.h>
#include <sched.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include <gtest/gtest.h>

#include "test_support.hpp"

namespace arena {
namespace {

using namespace std::chrono_literals;

int Shell(const std::string& command) {
  const int rc = std::system((command + " > /dev/null 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// Three namespaces and a bridge, removed in the destructor.
class Lab {
 public:
  Lab() {
    const std::string tag = std::to_string(getpid());
    s_ = "arena" + tag + "s";
    a_ = "arena" + tag + "a";
    b_ = "arena" + tag + "b";
    if (geteuid() != 0) {
      why_ = "not root: cannot create network namespaces";
      return;
    }
    if (Shell("ip netns add " + s_) != 0) {
      why_ = "`ip netns add` failed (no iproute2 or no CAP_SYS_ADMIN)";
      return;
    }
    created_ = true;
    RemoveStale();
    const std::vector<std::string> steps = {
        "ip netns add " + a_,
        "ip netns add " + b_,
        "ip -n " + s_ + " link set lo up",
        "ip -n " + a_ + " link set lo up",
        "ip -n " + b_ + " link set lo up",
        "ip -n " + s_ + " link add br0 type bridge",
        "ip -n " + s_ + " addr add 10.77.0.1/24 dev br0",
        "ip -n " + s_ + " link set br0 up",
        "ip link add va" + tag + " netns " + s_ + " type veth peer name eth0 netns " + a_,
        "ip link add vb" + tag + " netns " + s_ + " type veth peer name eth0 netns " + b_,
        "ip -n " + s_ + " link set va" + tag + " master br0 up",
        "ip -n " + s_ + " link set vb" + tag + " master br0 up",
        "ip -n " + a_ + " addr add 10.77.0.2/24 dev eth0",
        "ip -n " + b_ + " addr add 10.77.0.3/24 dev eth0",
        "ip -n " + a_ + " link set eth0 up",
        "ip -n " + b_ + " link set eth0 up",
    };
    for (const auto& step : steps) {
      if (Shell(step) != 0) {
        why_ = "set-up step failed: " + step;
        return;
      }
    }
    if (Shell("ip netns exec " + a_ + " ping -c 1 -W 2 10.77.0.3") != 0 &&
        Shell("ip netns exec " + a_ + " ping -c 1 -W 2 10.77.0.1") != 0) {
      // ping may be missing; not fatal, DDS discovery is the real check.
    }
    ok_ = true;
  }
  ~Lab() {
    if (created_) {
      Shell("ip netns del " + a_);
      Shell("ip netns del " + b_);
      Shell("ip netns del " + s_);  // removes br0 and the veth ends
    }
  }
  // Namespaces left by an earlier run of this test that was killed before
  // its teardown (its pid no longer exists).
  void RemoveStale() {
    FILE* list = popen("ip netns list 2>/dev/null", "r");
    if (list == nullptr) return;
    char line[256];
    std::vector<std::string> stale;
    while (std::fgets(line, sizeof line, list) != nullptr) {
      std::string name(line);
      name = name.substr(0, name.find_first_of(" \n"));
      if (name.size() < 7 || name.rfind("arena", 0) != 0) continue;
      const std::string digits = name.substr(5, name.size() - 6);
      const char last = name.back();
      if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos ||
          (last != 's' && last != 'a' && last != 'b')) {
        continue;
      }
      const int pid = std::atoi(digits.c_str());
      if (pid != getpid() && kill(pid, 0) != 0 && errno == ESRCH) stale.push_back(name);
    }
    pclose(list);
    for (const auto& name : stale) Shell("ip netns del " + name);
  }

  bool ok() const { return ok_; }
  const std::string& why() const { return why_; }
  const std::string& s() const { return s_; }
  const std::string& a() const { return a_; }
  const std::string& b() const { return b_; }

 private:
  std::string s_, a_, b_, why_;
  bool created_ = false, ok_ = false;
};

std::unique_ptr<test::Child> CellIn(const std::string& ns, const std::string& id, int domain,
                                    const std::vector<std::string>& network) {
  std::vector<std::string> argv = {
      "/usr/sbin/ip", "netns", "exec",    ns,         ARENA_BINARY,
      "cell",         "--id",  id,        "--domain", std::to_string(domain),
      "--speed",      "0",     "--no-shm"};
  argv.insert(argv.end(), network.begin(), network.end());
  return std::make_unique<test::Child>(
      argv, ::testing::TempDir() + "netns_" + id + "_" + std::to_string(getpid()) + ".log");
}

// Runs the driver in namespace ns in a forked child (this process stays in
// its own namespace); returns "" on success or what went wrong.
std::string DriveFrom(const std::string& ns, int domain, dds::NetworkOptions network) {
  int pipe_fd[2];
  if (pipe(pipe_fd) != 0) return "pipe failed";
  const pid_t pid = fork();
  if (pid == 0) {
    close(pipe_fd[0]);
    std::string result;
    const int fd = open(("/var/run/netns/" + ns).c_str(), O_RDONLY);
    if (fd < 0 || setns(fd, CLONE_NEWNET) != 0) {
      result = "setns failed";
    } else {
      try {
        network.shared_memory = false;
        test::Driver d(domain, network);
        if (!d.WaitForCells({"a", "b"}, 20s)) {
          result = "cells in the other namespaces were not discovered";
        } else if (!d.commands.WaitForMatched(2, 10s)) {
          result = "command writer did not match both cells";
        } else {
          for (const std::string cell : {"a", "b"}) {
            const std::uint64_t trial = cell == "a" ? 1 : 2;
            if (!d.Send(d.Command(cell, trial, msg::PHASE_EXECUTE, test::CanonicalScene(1.0)))) {
              result = "write failed";
            }
          }
          std::map<std::uint64_t, std::uint32_t> samples, next;
          bool ok = true;
          const auto deadline = std::chrono::steady_clock::now() + 30s;
          int last_seen = 0;
          while (last_seen < 2 && std::chrono::steady_clock::now() < deadline && ok) {
            auto g = d.ground_truth.Take(1000ms);
            if (!g) continue;
            if (g->first_sample() != next[g->trial_id()]) ok = false;
            next[g->trial_id()] += static_cast<std::uint32_t>(g->samples().size());
            last_seen += g->last() ? 1 : 0;
          }
          if (!ok)
            result = "ground truth out of order";
          else if (last_seen < 2)
            result = "ground truth incomplete";
          for (std::uint64_t trial : {1, 2}) {
            auto st = d.FinalStatus(trial, 20s);
            if (!st || st->state() != msg::STATE_EXECUTED) {
              result = "trial " + std::to_string(trial) + " not EXECUTED";
            } else if (st->samples() != next[trial]) {
              result = "trial " + std::to_string(trial) + ": samples differ from status";
            }
          }
          // The local-only cell in namespace B must have stayed invisible.
          d.WaitForCells({"hidden"}, 500ms);
          if (result.empty() && d.seen.count("hidden")) {
            result = "a cell without --peers was seen from another host";
          }
        }
      } catch (const std::exception& e) {
        result = std::string("driver: ") + e.what();
      }
    }
    if (write(pipe_fd[1], result.data(), result.size()) < 0) {
    }
    close(pipe_fd[1]);
    _exit(result.empty() ? 0 : 1);
  }
  close(pipe_fd[1]);
  std::string result;
  char buf[512];
  ssize_t n;
  while ((n = read(pipe_fd[0], buf, sizeof buf)) > 0) result.append(buf, static_cast<size_t>(n));
  close(pipe_fd[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (!WIFEXITED(status)) return "driver process crashed";
  if (WEXITSTATUS(status) != 0 && result.empty()) return "driver failed";
  return result;
}

TEST(SeveralHosts, CellsJoinByInitialPeers) {
  Lab lab;
  if (!lab.ok()) GTEST_SKIP() << "network namespaces unavailable: " << lab.why();
  const int domain = test::TestDomain(11);
  auto a = CellIn(lab.a(), "a", domain, {"--peers", "10.77.0.1"});
  auto b = CellIn(lab.b(), "b", domain, {"--peers", "10.77.0.1"});
  auto hidden = CellIn(lab.b(), "hidden", domain, {});
  dds::NetworkOptions network;
  network.peers = {"10.77.0.2", "10.77.0.3"};
  EXPECT_EQ(DriveFrom(lab.s(), domain, network), "");
}

TEST(SeveralHosts, CellsJoinThroughADiscoveryServer) {
  Lab lab;
  if (!lab.ok()) GTEST_SKIP() << "network namespaces unavailable: " << lab.why();
  if (Shell("command -v fastdds") != 0) GTEST_SKIP() << "fastdds (fastdds-tools) not installed";
  const int domain = test::TestDomain(12);
  test::Child server({"/usr/sbin/ip", "netns", "exec", lab.s(), "/usr/bin/fastdds", "discovery",
                      "-i", "0", "-l", "10.77.0.1", "-p", "11811"},
                     ::testing::TempDir() + "netns_server_" + std::to_string(getpid()) + ".log");
  auto a = CellIn(lab.a(), "a", domain, {"--discovery-server", "0@10.77.0.1:11811"});
  auto b = CellIn(lab.b(), "b", domain, {"--discovery-server", "10.77.0.1:11811"});
  auto hidden = CellIn(lab.b(), "hidden", domain, {});
  dds::NetworkOptions network;
  network.discovery_server = "0@10.77.0.1:11811";
  EXPECT_EQ(DriveFrom(lab.s(), domain, network), "");
}

}  // namespace
}  // namespace arena
