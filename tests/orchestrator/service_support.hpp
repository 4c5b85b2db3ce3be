// Helpers for the multi-process service tests: a temp directory, the arena
// binary as child processes, and a read-only look at the store.
#pragma once

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "arena/db/store.hpp"
#include "executors/test_support.hpp"

namespace arena::test {

inline std::string TestCampaign(const std::string& name) {
  return std::string(ARENA_SOURCE_DIR) + "/tests/orchestrator/data/" + name;
}

class TempDir {
 public:
  TempDir() {
    char tmpl[] = "/tmp/arena-service-test-XXXXXX";
    path_ = mkdtemp(tmpl);
  }
  ~TempDir() {
    std::error_code ec;
    if (!HasFailure()) std::filesystem::remove_all(path_, ec);  // keep logs of a failed test
  }
  const std::string& path() const { return path_; }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  static bool HasFailure() { return ::testing::Test::HasFailure(); }
  std::string path_;
};

// Runs `arena ARGS...` to completion; returns its exit status (or -1 on timeout).
inline int RunArena(const std::vector<std::string>& args, const std::string& log,
                    std::chrono::milliseconds timeout) {
  std::vector<std::string> argv = {ARENA_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  Child child(argv, log);
  auto st = child.Wait(timeout);
  if (!st) return -1;
  return WIFEXITED(*st) ? WEXITSTATUS(*st) : 128 + WTERMSIG(*st);
}

inline std::unique_ptr<Child> StartArena(const std::vector<std::string>& args,
                                         const std::string& log) {
  std::vector<std::string> argv = {ARENA_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  return std::make_unique<Child>(argv, log);
}

inline std::unique_ptr<db::Store> OpenReadOnly(const std::string& path) {
  db::StoreOptions o;
  o.read_only = true;
  return db::Store::Open(path, o);
}

// Trials of a campaign by state name.
inline std::map<std::string, int> CountStates(const std::string& db_path, std::int64_t campaign) {
  std::map<std::string, int> counts;
  auto store = OpenReadOnly(db_path);
  for (const auto& t : store->ListTrials(campaign)) counts[db::ToString(t.state)]++;
  return counts;
}

// Polls `done` every 50 ms until it holds or the timeout passes.
inline bool WaitUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    try {
      if (done()) return true;
    } catch (const db::StoreError&) {
      // the store may not exist yet, or be mid-migration: try again
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

// Waits for `done` while `progress` keeps moving: false when it stood still
// for `stall` or `cap` passed. For whole campaigns, whose length depends on
// how loaded the machine is; a stuck service still fails within `stall`.
inline bool WaitWhileProgressing(const std::function<bool()>& done,
                                 const std::function<int()>& progress,
                                 std::chrono::milliseconds stall, std::chrono::milliseconds cap) {
  const auto start = std::chrono::steady_clock::now();
  auto moved = start;
  int last = -1;
  while (std::chrono::steady_clock::now() - start < cap) {
    try {
      if (done()) return true;
      const int now = progress();
      if (now != last) {
        last = now;
        moved = std::chrono::steady_clock::now();
      }
    } catch (const db::StoreError&) {
      // the store may be busy or mid-migration: try again
    }
    if (std::chrono::steady_clock::now() - moved > stall) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

// What every finished campaign must satisfy, whatever happened on the way:
// every trial ended exactly once, the file is intact, the invariants hold.
inline void ExpectCampaignConsistent(const std::string& db_path, std::int64_t campaign,
                                     int trials) {
  auto store = OpenReadOnly(db_path);
  EXPECT_EQ(store->IntegrityCheck(), "ok");
  const auto violations = store->CheckInvariants();
  EXPECT_TRUE(violations.empty()) << violations.front();
  const auto all = store->ListTrials(campaign);
  EXPECT_EQ(static_cast<int>(all.size()), trials);
  for (const auto& t : all) {
    EXPECT_TRUE(db::IsTerminal(t.state)) << "trial " << t.id << " is " << db::ToString(t.state);
    int terminal_rows = 0;
    for (const auto& tr : store->ListTransitions(t.id)) {
      terminal_rows +=
          tr.to_state == "done" || tr.to_state == "failed" || tr.to_state == "cancelled";
    }
    EXPECT_EQ(terminal_rows, 1) << "trial " << t.id << " ended " << terminal_rows << " times";
    if (t.state == db::TrialState::kDone) {
      EXPECT_FALSE(store->ListPredictions(t.id).empty())
          << "trial " << t.id << " done without a prediction";
      EXPECT_EQ(store->ReadGroundTruth(t.id).attempt, t.attempt);
    }
  }
}

}  // namespace arena::test
