// `arena serve --notify` (notifier.hpp) with real commands: each event
// reaches the command on stdin as one JSON line; a command that hangs is
// killed with its whole process group after the timeout and a failing one
// is counted, and neither ever blocks Post(); a full queue drops (counted).
#include "arena/orchestrator/notifier.hpp"

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

namespace arena::orchestrator {
namespace {

using Clock = std::chrono::steady_clock;

struct Dir {
  std::string path;
  Dir() {
    char tmpl[] = "/tmp/arena-notify-XXXXXX";
    path = mkdtemp(tmpl);
  }
  ~Dir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

std::string Read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

TEST(Notifier, EachEventReachesTheCommandOnStdin) {
  Dir d;
  Notifier n("cat >> " + d.path + "/events.jsonl", 5.0, 16);
  EXPECT_TRUE(n.Post(R"({"event":"campaign_done","campaign":1})"));
  EXPECT_TRUE(n.Post(R"({"event":"cell_gone","cell":"c2"})"));
  ASSERT_TRUE(n.Drain(10));
  EXPECT_EQ(
      Read(d.path + "/events.jsonl"),
      "{\"event\":\"campaign_done\",\"campaign\":1}\n{\"event\":\"cell_gone\",\"cell\":\"c2\"}\n");
  const auto c = n.counters();
  EXPECT_EQ(c.posted, 2);
  EXPECT_EQ(c.delivered, 2);
  EXPECT_EQ(c.failed + c.timed_out + c.dropped, 0);
}

TEST(Notifier, AFailingCommandIsCountedAndTheNextEventStillGoes) {
  Dir d;
  Notifier n(
      "read line; case \"$line\" in *bad*) exit 7;; esac; echo \"$line\" >> " + d.path + "/ok.txt",
      5.0, 16);
  n.Post(R"({"event":"bad"})");
  n.Post(R"({"event":"good"})");
  ASSERT_TRUE(n.Drain(10));
  EXPECT_EQ(n.counters().failed, 1);
  EXPECT_EQ(n.counters().delivered, 1);
  EXPECT_EQ(Read(d.path + "/ok.txt"), "{\"event\":\"good\"}\n");
  // A command that does not exist: sh exits 127, counted as failed.
  Notifier missing("/nonexistent/notify-command", 5.0, 4);
  missing.Post("{}");
  ASSERT_TRUE(missing.Drain(10));
  EXPECT_EQ(missing.counters().failed, 1);
}

TEST(Notifier, AHangingCommandIsKilledWithItsGroupAndNeverBlocksPost) {
  Dir d;
  // The command starts a grandchild that would outlive it, writes its pid, then hangs.
  Notifier n("sleep 300 & echo $! > " + d.path + "/grandchild.pid; sleep 300", 0.5, 2);
  const auto t0 = Clock::now();
  EXPECT_TRUE(n.Post(R"({"event":"one"})"));
  usleep(200000);  // the worker takes it and runs the command
  const auto t1 = Clock::now();
  EXPECT_TRUE(n.Post(R"({"event":"two"})"));
  EXPECT_TRUE(n.Post(R"({"event":"three"})"));  // the first is already running: 2 queued
  EXPECT_FALSE(n.Post(R"({"event":"four"})")) << "the queue (2) is full: dropped";
  EXPECT_LT(Since(t1), 0.1) << "Post() waited for the command";
  EXPECT_EQ(n.counters().dropped, 1);
  ASSERT_TRUE(n.Drain(20));
  EXPECT_EQ(n.counters().timed_out, 3);
  EXPECT_GE(Since(t0), 1.5) << "three commands, each killed after 0.5 s";
  const std::string pid = Read(d.path + "/grandchild.pid");
  ASSERT_FALSE(pid.empty());
  // The grandchild went with its group (a zombie of a dead parent is reaped by init).
  bool gone = false;
  for (int i = 0; i < 100 && !gone; ++i) {
    const std::string status = Read("/proc/" + std::to_string(std::stoi(pid)) + "/status");
    gone = status.empty() || status.find("State:\tZ") != std::string::npos;
    if (!gone) usleep(20000);
  }
  EXPECT_TRUE(gone) << "the command's own child outlived the timeout: pid " << pid;
}

TEST(Notifier, ACommandThatDoesNotReadItsStdinDoesNotHurtTheService) {
  Notifier n("exit 0", 5.0, 4);
  n.Post(std::string(1 << 20, 'x'));  // larger than a pipe's buffer: EPIPE, not SIGPIPE
  ASSERT_TRUE(n.Drain(10));
  EXPECT_EQ(n.counters().delivered, 1);
}

TEST(Notifier, BadSettingsAreRefusedNamingTheFlag) {
  EXPECT_THROW(Notifier("", 1, 1), std::invalid_argument);
  try {
    Notifier n("true", 0, 1);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("--notify-timeout"), std::string::npos);
  }
  EXPECT_THROW(Notifier("true", 1, 0), std::invalid_argument);
}

}  // namespace
}  // namespace arena::orchestrator
