// The claim chooser (claim_chooser.hpp) as a table, and as a property over
// simulated campaigns: change-aware scheduling saves change time, and a
// condition's trials still spread over cells and hours.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/claim_chooser.hpp"

namespace arena::orchestrator {
namespace {

using schemas::ChangeCosts;
using schemas::Fixtures;

const Fixtures kA{"line", "point", "box"};
const Fixtures kB{"patch", "point", "box"};  // another finger
const Fixtures kC{"line", "line", "box"};    // another pusher
const Fixtures kD{"patch", "line", "cyl"};   // everything differs
const ChangeCosts kCosts{30, 5, 10};

std::vector<ClaimCandidate> Window(const std::vector<Fixtures>& f, std::int64_t first_index = 0) {
  std::vector<ClaimCandidate> out;
  for (std::size_t i = 0; i < f.size(); ++i)
    out.push_back({100 + first_index + static_cast<std::int64_t>(i),
                   first_index + static_cast<std::int64_t>(i), f[i]});
  return out;
}

struct Row {
  const char* name;
  SchedulingOptions options;
  std::vector<ClaimCandidate> candidates;
  ClaimerState cell;
  std::int64_t want_trial;
  const char* want_rule;
  double want_change_s;
};

ClaimerState Cell(std::optional<Fixtures> mounted, std::optional<ChangeCosts> costs,
                  std::optional<std::int64_t> last_block) {
  ClaimerState s;
  s.mounted = std::move(mounted);
  s.costs = costs;
  s.last_block = last_block;
  s.draw_seed = 7;
  return s;
}

TEST(ClaimChooser, Table) {
  const SchedulingOptions on{true, 4};
  const SchedulingOptions off{false, 4};
  const std::vector<Row> rows = {
      {"off: plan order, whatever it costs", off, Window({kD, kA, kA}), Cell(kA, kCosts, 0), 100,
       "claim.plan_order", 45},
      {"no declared costs: plan order", on, Window({kD, kA}), Cell(kA, std::nullopt, 0), 100,
       "claim.plan_order", 0},
      {"window 1: plan order", SchedulingOptions{true, 1}, Window({kD, kA}), Cell(kA, kCosts, 0),
       100, "claim.plan_order", 45},
      {"same fixtures first", on, Window({kD, kB, kA, kC}), Cell(kA, kCosts, 0), 102,
       "claim.least_change", 0},
      {"cheapest change: the pusher (5 s) before the fingers (30 s)", on, Window({kB, kD, kC}),
       Cell(kA, kCosts, 0), 102, "claim.least_change", 5},
      {"ties go in plan order", on, Window({kB, kB, kB}), Cell(kA, kCosts, 0), 100,
       "claim.least_change", 30},
      {"only the current block: index 4 is the next block", on, Window({kD, kD, kD, kD, kA}),
       Cell(kA, kCosts, 0), 100, "claim.least_change", 45},
      {"the current block is the first candidate's (indices 5..7 of block 1)", on,
       Window({kD, kA, kD, kA}, 5), Cell(kA, kCosts, 1), 106, "claim.least_change", 0},
      {"unknown mounting (set up for its first trial): no change, plan order", on, Window({kB, kA}),
       Cell(std::nullopt, kCosts, 0), 100, "claim.least_change", 0},
  };
  for (const Row& r : rows) {
    SCOPED_TRACE(r.name);
    const auto c = ChooseClaim(r.options, r.candidates, r.cell);
    ASSERT_TRUE(c.has_value());
    EXPECT_EQ(c->trial_id, r.want_trial);
    EXPECT_EQ(c->rule, r.want_rule);
    EXPECT_DOUBLE_EQ(c->change_s, r.want_change_s);
  }
  EXPECT_FALSE(ChooseClaim(on, {}, Cell(kA, kCosts, 0)).has_value());
}

TEST(ClaimChooser, FirstClaimInABlockIsDrawnAndDeterministic) {
  const SchedulingOptions on{true, 8};
  const auto w = Window({kA, kA, kA, kA, kA, kA, kA, kA});
  std::set<std::int64_t> picked;
  for (std::uint64_t seed = 0; seed < 64; ++seed) {
    ClaimerState s = Cell(kA, kCosts, std::nullopt);
    s.draw_seed = DrawSeed(seed, "c1");
    const auto a = ChooseClaim(on, w, s);
    const auto b = ChooseClaim(on, w, s);
    ASSERT_TRUE(a && b);
    EXPECT_EQ(a->rule, "claim.block_entry");
    EXPECT_EQ(a->trial_id, b->trial_id);  // same inputs, same choice
    picked.insert(a->trial_id);
  }
  EXPECT_GE(picked.size(), 6u) << "the entry draw should reach most of the block";
  EXPECT_NE(DrawSeed(1, "c1"), DrawSeed(1, "c2"));
  EXPECT_NE(DrawSeed(1, "c1"), DrawSeed(2, "c1"));
}

// ---- property: simulated campaigns
//
// A plan of trials over `configs` fixture settings drawn at random (the
// plan's order is the sampler's), `cells` cells, each trial taking
// `trial_s` plus the change from the cell's mounting. Cells claim with the
// chooser whenever idle (event order by time, ties by cell).
struct SimRun {
  double change_s = 0;
  double makespan_s = 0;
  std::map<int, std::map<int, int>> per_config_cell;  // config -> cell -> trials
  std::map<int, std::set<int>> per_config_hour;       // config -> hours it ran in
  std::vector<std::int64_t> order;                    // trial ids in claim order
};

SimRun Simulate(const SchedulingOptions& options, std::uint64_t seed, int trials, int configs,
                int cells, double trial_s) {
  std::mt19937_64 rng(seed);
  std::vector<Fixtures> config_fixtures;
  for (int k = 0; k < configs; ++k) {  // finger x pusher x object, all combinations
    config_fixtures.push_back({"finger" + std::to_string(k % 2),
                               "pusher" + std::to_string(k / 2 % 2),
                               "object" + std::to_string(k / 4)});
  }
  std::vector<int> config_of(trials);
  for (auto& c : config_of) c = static_cast<int>(rng() % configs);
  std::vector<bool> taken(trials, false);
  struct SimCell {
    double free_at = 0;
    std::optional<Fixtures> mounted;
    std::optional<std::int64_t> last_block;
  };
  std::vector<SimCell> sim(cells);
  SimRun run;
  for (int done = 0; done < trials; ++done) {
    int who = 0;
    for (int i = 1; i < cells; ++i)
      if (sim[i].free_at < sim[who].free_at) who = i;
    std::vector<ClaimCandidate> window;
    for (int i = 0; i < trials && static_cast<int>(window.size()) < kMaxSchedulingWindow; ++i)
      if (!taken[i]) window.push_back({i, i, config_fixtures[config_of[i]]});
    ClaimerState st;
    st.mounted = sim[who].mounted;
    st.costs = ChangeCosts{30, 5, 10};
    st.last_block = sim[who].last_block;
    st.draw_seed = DrawSeed(seed, "cell" + std::to_string(who));
    const auto choice = ChooseClaim(options, window, st);
    EXPECT_TRUE(choice.has_value());
    if (!choice) break;
    const int t = static_cast<int>(choice->trial_id);
    taken[t] = true;
    run.order.push_back(t);
    run.change_s += choice->change_s;
    const double start = sim[who].free_at;
    sim[who].free_at += choice->change_s + trial_s;
    sim[who].mounted = config_fixtures[config_of[t]];
    sim[who].last_block = choice->block;
    ++run.per_config_cell[config_of[t]][who];
    run.per_config_hour[config_of[t]].insert(static_cast<int>(start / 3600));
    run.makespan_s = std::max(run.makespan_s, sim[who].free_at);
  }
  return run;
}

TEST(ClaimChooserProperty, SavesChangeTimeAndKeepsConditionsSpread) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const int trials = 720, configs = 8, cells = 3;
    const SimRun plan = Simulate({false, 16}, seed, trials, configs, cells, 60);
    const SimRun aware = Simulate({true, 16}, seed, trials, configs, cells, 60);
    EXPECT_LT(aware.change_s, 0.6 * plan.change_s) << "change-aware should save change time";
    EXPECT_LT(aware.makespan_s, plan.makespan_s);
    ASSERT_GT(aware.makespan_s, 3 * 3600.0) << "the campaign must span hours to test them";
    for (const auto& [config, by_cell] : aware.per_config_cell) {
      int total = 0, most = 0;
      for (const auto& [cell, n] : by_cell) {
        total += n;
        most = std::max(most, n);
      }
      // Not all on one cell: every cell runs some of every condition, and
      // none runs more than 60 % of it (3 cells: 33 % each when balanced).
      EXPECT_EQ(by_cell.size(), static_cast<std::size_t>(cells)) << "config " << config;
      EXPECT_LE(most, 0.6 * total) << "config " << config;
      // Not all in one hour: it runs in every hour the campaign lasts, as the plan spreads it.
      EXPECT_GE(aware.per_config_hour.at(config).size(),
                static_cast<std::size_t>(aware.makespan_s / 3600) - 1)
          << "config " << config;
    }
  }
}

TEST(ClaimChooserProperty, NoTrialRunsFarFromItsPlanPosition) {
  // The block bounds how far the order may drift: claim position and plan
  // index differ by less than two windows (one block, plus cells in flight).
  const int window = 16;
  const SimRun aware = Simulate({true, window}, 3, 480, 8, 3, 20);
  for (std::size_t pos = 0; pos < aware.order.size(); ++pos)
    EXPECT_LT(std::abs(static_cast<long>(pos) - static_cast<long>(aware.order[pos])), 2 * window)
        << "trial " << aware.order[pos] << " claimed at position " << pos;
}

TEST(ClaimChooserProperty, SameInputsSameClaims) {
  const SimRun a = Simulate({true, 16}, 11, 200, 8, 3, 20);
  const SimRun b = Simulate({true, 16}, 11, 200, 8, 3, 20);
  EXPECT_EQ(a.order, b.order);
}

TEST(SchedulingBlock, DefaultsOnAndOffSwitchAndClearErrors) {
  const SchedulingOptions d = ReadScheduling(R"({"name": "c", "seed": 1})");
  EXPECT_TRUE(d.change_aware);
  EXPECT_EQ(d.window, 16);
  const SchedulingOptions off = ReadScheduling(R"({"scheduling": {"change_aware": false}})");
  EXPECT_FALSE(off.change_aware);
  EXPECT_EQ(ReadScheduling(R"({"scheduling": {"window": 64}})").window, 64);
  auto field_of = [](const char* text) {
    try {
      ReadScheduling(text);
    } catch (const CampaignError& e) {
      return e.field() + ": " + e.reason();
    }
    return std::string("no error");
  };
  EXPECT_EQ(field_of(R"({"scheduling": {"window": 0}})").rfind("scheduling.window: ", 0), 0u);
  EXPECT_EQ(field_of(R"({"scheduling": {"window": 257}})").rfind("scheduling.window: ", 0), 0u);
  EXPECT_EQ(field_of(R"({"scheduling": {"window": 2.5}})").rfind("scheduling.window: ", 0), 0u);
  EXPECT_EQ(
      field_of(R"({"scheduling": {"change_aware": "yes"}})").rfind("scheduling.change_aware: ", 0),
      0u);
  EXPECT_EQ(field_of(R"({"scheduling": {"batch": 3}})").rfind("scheduling.batch: ", 0), 0u);
  EXPECT_EQ(field_of(R"({"scheduling": 3})").rfind("scheduling: ", 0), 0u);
}

}  // namespace
}  // namespace arena::orchestrator
