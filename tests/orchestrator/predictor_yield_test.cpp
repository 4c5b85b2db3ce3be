// When a trial's prediction may start (orchestrator/src/predictor_yield.hpp):
// the rule row by row, then the watch with real threads (every wait bounded).
#include "predictor_yield.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <future>
#include <string>
#include <thread>

namespace arena::orchestrator {
namespace {

using Clock = PredictorYield::Clock;
using std::chrono::milliseconds;

struct Row {
  const char* what;
  int backlog, bound, on_path;
  int waited_ms;    // since the job was taken
  int quiet_in_ms;  // quiet_from - now (negative: quiet already)
  bool start;
  const char* rule;
  int ask_again_in_ms;  // when not started: wait_until - now
};

TEST(PredictorYield, EachRowOfTheRule) {
  const int max =
      static_cast<int>(std::chrono::duration_cast<milliseconds>(PredictorYield::kMaxYield).count());
  const Row rows[] = {
      {"quiet path, small backlog: start", 1, 64, 0, 0, -1, true, "predictor.path_quiet", 0},
      {"quiet exactly now: start", 1, 64, 0, 0, 0, true, "predictor.path_quiet", 0},
      {"a cell on the path: wait for its hand-off", 1, 64, 1, 0, -5, false,
       "predictor.yields_to_path", max},
      {"two cells on the path, waited 5 ms: wait the rest", 3, 64, 2, 5, -5, false,
       "predictor.yields_to_path", max - 5},
      {"handed off, its hop not over: ask again when it is", 1, 64, 0, 0, 1, false,
       "predictor.yields_to_path", 1},
      {"hop ends after the yield would: ask again at the yield's end", 1, 64, 0, max - 1, 5, false,
       "predictor.yields_to_path", 1},
      {"yielded the whole time: start though the path is busy", 1, 64, 3, max, -5, true,
       "predictor.yielded_enough", 0},
      {"backlog half full: start though the path is busy", 32, 64, 1, 0, 5, true,
       "predictor.backlog_half_full", 0},
      {"backlog just below half: yield", 31, 64, 1, 0, 5, false, "predictor.yields_to_path", max},
      {"a bound of 1: never yields", 1, 1, 1, 0, 5, true, "predictor.backlog_half_full", 0},
  };
  const Clock::time_point now = Clock::time_point{} + std::chrono::hours(1);
  for (const Row& r : rows) {
    SCOPED_TRACE(r.what);
    PredictorStartInputs in;
    in.now = now;
    in.waiting_since = now - milliseconds(r.waited_ms);
    in.backlog = r.backlog;
    in.backlog_bound = r.bound;
    in.cells_on_path = r.on_path;
    in.quiet_from = now + milliseconds(r.quiet_in_ms);
    const PredictorStart d = DecidePredictorStart(in);
    EXPECT_EQ(d.start, r.start);
    EXPECT_STREQ(d.rule, r.rule);
    if (!d.start) {
      EXPECT_EQ(d.wait_until, now + milliseconds(r.ask_again_in_ms));
    }
  }
}

// The watch's waits end by the rule's bounds; these bounds are generous (a
// loaded machine), the test checks what released the waiter, not how fast.
std::future<std::string> Waiter(PathWatch& watch, std::atomic<int>& backlog) {
  return std::async(std::launch::async, [&watch, &backlog] {
    return std::string(watch.WaitToStart(64, [&backlog] { return backlog.load(); }));
  });
}

TEST(PathWatch, APredictionWaitsWhileACellIsOnThePathAndStartsAfterItsHandOff) {
  PathWatch watch;
  std::atomic<int> backlog{1};
  watch.OnPath("c1", Clock::now());
  auto waiter = Waiter(watch, backlog);
  watch.OffPath("c1", Clock::now());
  ASSERT_EQ(waiter.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  // Released by the hand-off (and its hop), or by its bound on a machine so
  // slow that 20 ms passed before the hand-off was written.
  const std::string rule = waiter.get();
  EXPECT_TRUE(rule == "predictor.path_quiet" || rule == "predictor.yielded_enough") << rule;
}

TEST(PathWatch, ACellThatStaysOnThePathHoldsAPredictionOnlyForTheYieldsBound) {
  PathWatch watch;
  std::atomic<int> backlog{1};
  const auto start = Clock::now();
  watch.OnPath("c1", start);
  auto waiter = Waiter(watch, backlog);
  ASSERT_EQ(waiter.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  const std::string rule = waiter.get();
  // Still on the path (not stale yet) when the bound ran out, unless the
  // thread started so late that the mark had gone stale.
  EXPECT_TRUE(rule == "predictor.yielded_enough" || rule == "predictor.path_quiet") << rule;
  EXPECT_GE(Clock::now() - start, PredictorYield::kMaxYield);
}

TEST(PathWatch, AStaleMarkHoldsNothingAndANewOneReplacesIt) {
  PathWatch watch;
  std::atomic<int> backlog{1};
  const auto long_ago = Clock::now() - PredictorYield::kStale - milliseconds(1);
  watch.OnPath("c1", long_ago);  // a cell lost between its phases, never handed off
  EXPECT_EQ(Waiter(watch, backlog).get(), "predictor.path_quiet");
  // A new phase end of the same cell counts from now, not from the stale mark.
  watch.OnPath("c1", Clock::now());
  const auto start = Clock::now();
  auto waiter = Waiter(watch, backlog);
  ASSERT_EQ(waiter.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_GE(Clock::now() - start, milliseconds(1));  // it waited: the mark counts
  EXPECT_NE(waiter.get(), "predictor.backlog_half_full");
}

TEST(PathWatch, AFullBacklogStartsAtOnceAndStopReleasesEveryWaiter) {
  PathWatch watch;
  std::atomic<int> backlog{32};
  watch.OnPath("c1", Clock::now());
  EXPECT_EQ(Waiter(watch, backlog).get(), "predictor.backlog_half_full");
  backlog = 1;
  watch.OnPath("c2", Clock::now());
  auto waiter = Waiter(watch, backlog);
  watch.Stop();
  ASSERT_EQ(waiter.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  const std::string rule = waiter.get();
  EXPECT_TRUE(rule.empty() || rule == "predictor.yielded_enough") << rule;
  EXPECT_EQ(Waiter(watch, backlog).get(), "");  // stopped for good
}

}  // namespace
}  // namespace arena::orchestrator
