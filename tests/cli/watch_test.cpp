// arena watch with a real cell process over DDS (test-unique domain): the
// watcher follows a trial to its last batch and exits 0; --cell follows the
// next trial of a cell; with nothing to watch it gives up after --timeout
// with exit 4 and says what to check.
#include <gtest/gtest.h>

#include "executors/test_support.hpp"

namespace arena::test {
namespace {

std::string Tmp(const std::string& name) {
  return "/tmp/arena-watch-test-" + std::to_string(getpid()) + "-" + name;
}

int ExitCode(const std::optional<int>& st) { return st && WIFEXITED(*st) ? WEXITSTATUS(*st) : -1; }

// Starts a watcher, waits until the cell's ground truth writer can reach it,
// runs trial `trial` on the cell and returns the watcher's exit code.
int WatchOneTrial(const std::vector<std::string>& watch_args, const std::string& log, int domain,
                  std::uint64_t trial) {
  Child cell(
      {ARENA_BINARY, "cell", "--id", "w1", "--domain", std::to_string(domain), "--speed", "1"},
      Tmp("cell.log"));
  Driver driver(domain);
  EXPECT_TRUE(driver.WaitForCells({"w1"}, 15s));
  std::vector<std::string> argv = {ARENA_BINARY, "watch"};
  argv.insert(argv.end(), watch_args.begin(), watch_args.end());
  Child watch(argv, log);
  EXPECT_TRUE(driver.participant.WaitForPeer("arena.watch", 15s));
  std::this_thread::sleep_for(1s);  // endpoint matching follows participant discovery
  EXPECT_TRUE(driver.Send(driver.Command("w1", trial, msg::PHASE_EXECUTE, CanonicalScene(0.4))));
  auto st = driver.FinalStatus(trial, 20s);
  EXPECT_TRUE(st.has_value());
  if (st) {
    EXPECT_EQ(st->state(), msg::STATE_EXECUTED) << st->reason();
  }
  return ExitCode(watch.Wait(20s));
}

TEST(Watch, FollowsATrialToItsLastBatch) {
  const int domain = TestDomain(31);
  const std::string log = Tmp("trial.log");
  const int rc =
      WatchOneTrial({"77", "--domain", std::to_string(domain), "--timeout", "20"}, log, domain, 77);
  const std::string out = ReadFile(log);
  EXPECT_EQ(rc, 0) << out;
  // Not a terminal: one line per batch, then the summary (0.4 s at 250 Hz).
  EXPECT_NE(out.find("trial 77 #1 on w1"), std::string::npos) << out;
  EXPECT_NE(out.find("object [mm]"), std::string::npos) << out;
  EXPECT_NE(out.find("trial 77 attempt 1: complete, 101 samples"), std::string::npos) << out;
  EXPECT_EQ(out.find("\033[K"), std::string::npos) << "no terminal control codes into a file";
  std::remove(log.c_str());
}

TEST(Watch, FollowsTheNextTrialOfACell) {
  const int domain = TestDomain(32);
  const std::string log = Tmp("cell-watch.log");
  const int rc = WatchOneTrial(
      {"--cell", "w1", "--domain", std::to_string(domain), "--timeout", "20"}, log, domain, 5);
  EXPECT_EQ(rc, 0) << ReadFile(log);
  EXPECT_NE(ReadFile(log).find("trial 5 attempt 1: complete"), std::string::npos) << ReadFile(log);
  std::remove(log.c_str());
}

TEST(Watch, GivesUpWithAClearMessageWhenNothingArrives) {
  const std::string log = Tmp("timeout.log");
  Child watch(
      {ARENA_BINARY, "watch", "9", "--domain", std::to_string(TestDomain(33)), "--timeout", "1"},
      log);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(ExitCode(watch.Wait(15s)), 4) << ReadFile(log);
  EXPECT_LT(std::chrono::steady_clock::now() - start, 10s);
  EXPECT_NE(ReadFile(log).find("no ground truth for trial 9"), std::string::npos) << ReadFile(log);
  std::remove(log.c_str());
  // Neither a trial nor a cell: bad input.
  Child bad({ARENA_BINARY, "watch", "--domain", "5"}, log);
  EXPECT_EQ(ExitCode(bad.Wait(15s)), 2) << ReadFile(log);
  std::remove(log.c_str());
}

}  // namespace
}  // namespace arena::test
