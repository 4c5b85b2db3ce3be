// The trial driver's store policy (orchestrator/src/store_steps.hpp) with a
// hand-driven clock: a busy store retries with a doubling, capped back-off
// while the cell waits; fatal errors stop; the rest is moot.
#include "store_steps.hpp"

#include <gtest/gtest.h>

#include <map>
#include <vector>

namespace arena::orchestrator {
namespace {

using Clock = StoreSteps::Clock;
using db::StoreError;

struct Harness {
  Clock::time_point t{};
  std::map<std::string, int> waits;
  StoreSteps steps{[this] { return t; },
                   [this](const std::string& cell, int delta) { waits[cell] += delta; }};
  void Advance(double s) {
    t += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
  }
};

TEST(StoreSteps, ABusyStepIsRetriedWithADoublingCappedBackOffWhileItsCellWaits) {
  Harness h;
  std::vector<Clock::time_point> tried;
  int busy_left = 8;
  const auto run = [&] {
    tried.push_back(h.t);
    if (busy_left-- > 0) throw StoreError(StoreError::Kind::kBusy, "database is locked");
  };
  EXPECT_FALSE(h.steps.Step("trial 1: begin ingest", "c1", run));
  EXPECT_EQ(h.waits["c1"], 1);
  // Tick every 10 ms until the step went through.
  for (int i = 0; i < 2000 && h.steps.pending() > 0; ++i) {
    h.Advance(0.01);
    h.steps.RunDue();
  }
  ASSERT_EQ(h.steps.pending(), 0u);
  EXPECT_EQ(h.waits["c1"], 0) << "the cell no longer waits";
  ASSERT_EQ(tried.size(), 9u);
  // Gaps between tries: 0.05, 0.1, 0.2, ... doubling, never above 2 s (to a tick).
  double expected = StoreSteps::kFirstBackoff_s;
  for (std::size_t i = 1; i < tried.size(); ++i) {
    const double gap = std::chrono::duration<double>(tried[i] - tried[i - 1]).count();
    EXPECT_GE(gap, expected - 1e-9) << "try " << i;
    EXPECT_LT(gap, expected + 0.0100001) << "try " << i;
    expected = std::min(expected * 2, StoreSteps::kMaxBackoff_s);
  }
}

TEST(StoreSteps, AFatalStoreErrorStopsAndAMootOneGoesToItsHandler) {
  Harness h;
  for (auto kind : {StoreError::Kind::kFull, StoreError::Kind::kIo, StoreError::Kind::kCorrupt,
                    StoreError::Kind::kReadOnly, StoreError::Kind::kTooNew}) {
    EXPECT_THROW(h.steps.Step("x", "c1", [&] { throw StoreError(kind, "fatal"); }), StoreError);
    EXPECT_THROW(h.steps.Attempt("x", [&] { throw StoreError(kind, "fatal"); }), StoreError);
  }
  std::string moot;
  EXPECT_FALSE(h.steps.Step(
      "x", "c1", [] { throw StoreError(StoreError::Kind::kStaleAttempt, "attempt 2 is current"); },
      [&](const StoreError& e) { moot = e.what(); }));
  EXPECT_EQ(moot, "attempt 2 is current");
  EXPECT_EQ(h.steps.pending(), 0u);
  EXPECT_EQ(h.waits["c1"], 0);
  // Attempt never queues: the next pass does the work anyway.
  h.steps.Attempt("claim", [] { throw StoreError(StoreError::Kind::kBusy, "locked"); });
  EXPECT_EQ(h.steps.pending(), 0u);
}

}  // namespace
}  // namespace arena::orchestrator
