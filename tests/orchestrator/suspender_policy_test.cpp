// The suspenders' rules (suspender_policy.hpp) as one table: for each
// condition, a reading against its limit in each state (watching, suspended
// within and past its hold, signal clear and not, budget used up, set
// aside, switched off), the step, the rule's name and the state after it.
#include "arena/orchestrator/suspender_policy.hpp"

#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace arena::orchestrator {
namespace {

using C = Condition;
using St = SuspenderStep;

struct Row {
  const char* what;
  C condition;
  SuspenderState state;
  Reading reading;
  double now;
  St step;
  std::string rule;
  bool suspended_after;
  bool set_aside_after;
  int fires_after;
};

SuspenderState Watching(int fires = 0) { return {false, false, 0, -1, fires}; }
SuspenderState Suspended(double fired_at, int fires = 1, double clear_since = -1) {
  return {true, false, fired_at, clear_since, fires};
}
SuspenderState SetAside() { return {false, true, 0, -1, 3}; }

// Limits used by every row: threshold 0.5 (a rate), 10 m... see Limits().
SuspenderLimits Limits(C c) {
  SuspenderLimits l;
  l.window = 4;
  l.min_evidence = 3;
  l.hold_s = 10;
  l.budget = 2;
  switch (c) {
    case C::kStartPoseDrift:
      l.threshold = 0.005;
      break;
    case C::kCellSilence:
      l.threshold = 5;
      break;
    case C::kStoreFreeSpace:
      l.threshold = 1000;
      l.budget = 0;
      break;
    default:
      l.threshold = 0.5;
  }
  return l;
}

std::vector<Row> Table() {
  std::vector<Row> t;
  // Outcome conditions (a rate over trials): the same rows for each.
  for (C c : {C::kResetFailureRate, C::kSampleDropRate, C::kDeadlineMisses}) {
    const std::string n = ToString(c);
    auto rule = [n](const char* suffix) { return n + suffix; };
    t.push_back({"no evidence yet",
                 c,
                 Watching(),
                 {false, 0, 0},
                 100,
                 St::kNone,
                 "suspender.clear",
                 false,
                 false,
                 0});
    t.push_back({"too few trials to judge",
                 c,
                 Watching(),
                 {true, 1.0, 2},
                 100,
                 St::kNone,
                 "suspender.clear",
                 false,
                 false,
                 0});
    t.push_back({"at the threshold is not past it",
                 c,
                 Watching(),
                 {true, 0.5, 3},
                 100,
                 St::kNone,
                 "suspender.clear",
                 false,
                 false,
                 0});
    t.push_back({"past it: fires",
                 c,
                 Watching(),
                 {true, 0.75, 4},
                 100,
                 St::kFire,
                 rule(".fired"),
                 true,
                 false,
                 1});
    t.push_back({"second fire within the budget",
                 c,
                 Watching(1),
                 {true, 0.75, 4},
                 100,
                 St::kFire,
                 rule(".fired"),
                 true,
                 false,
                 2});
    t.push_back({"budget used up: set aside",
                 c,
                 Watching(2),
                 {true, 0.75, 4},
                 100,
                 St::kSetAside,
                 rule(".set_aside"),
                 false,
                 true,
                 2});
    t.push_back({"holds within hold_s",
                 c,
                 Suspended(95),
                 {false, 0, 0},
                 100,
                 St::kHold,
                 rule(".holding"),
                 true,
                 false,
                 1});
    t.push_back({"lifts once hold_s passed (the next trials probe)",
                 c,
                 Suspended(90),
                 {false, 0, 0},
                 100,
                 St::kLift,
                 rule(".hold_elapsed"),
                 false,
                 false,
                 1});
    t.push_back({"a full clean window gives the budget back",
                 c,
                 Watching(2),
                 {true, 0.25, 4},
                 100,
                 St::kNone,
                 rule(".clean_window"),
                 false,
                 false,
                 0});
    t.push_back({"a partial clean window keeps the budget",
                 c,
                 Watching(2),
                 {true, 0.0, 3},
                 100,
                 St::kNone,
                 "suspender.clear",
                 false,
                 false,
                 2});
    t.push_back({"set aside: never again",
                 c,
                 SetAside(),
                 {true, 1.0, 4},
                 100,
                 St::kNone,
                 "suspender.set_aside",
                 false,
                 true,
                 3});
  }
  {
    const C c = C::kStartPoseDrift;
    t.push_back({"drift within limit",
                 c,
                 Watching(),
                 {true, 0.004, 5},
                 100,
                 St::kNone,
                 "suspender.clear",
                 false,
                 false,
                 0});
    t.push_back({"drift past limit",
                 c,
                 Watching(),
                 {true, 0.006, 3},
                 100,
                 St::kFire,
                 "start_pose_drift.fired",
                 true,
                 false,
                 1});
    t.push_back({"drift hold elapsed",
                 c,
                 Suspended(80),
                 {true, 0.006, 3},
                 100,
                 St::kLift,
                 "start_pose_drift.hold_elapsed",
                 false,
                 false,
                 1});
  }
  {
    const C c = C::kCellSilence;
    t.push_back(
        {"alive", c, Watching(), {true, 0, 1}, 100, St::kNone, "suspender.clear", false, false, 0});
    t.push_back({"silent past the threshold fires",
                 c,
                 Watching(),
                 {true, 6, 1},
                 100,
                 St::kFire,
                 "cell_silence.fired",
                 true,
                 false,
                 1});
    t.push_back({"still silent: holds however long",
                 c,
                 Suspended(0),
                 {true, 100, 1},
                 100,
                 St::kHold,
                 "cell_silence.still_past",
                 true,
                 false,
                 1});
    t.push_back({"back, not yet clear for hold_s",
                 c,
                 Suspended(0, 1, 95),
                 {true, 0, 1},
                 100,
                 St::kHold,
                 "cell_silence.holding",
                 true,
                 false,
                 1});
    t.push_back({"back and clear for hold_s: lifts",
                 c,
                 Suspended(0, 1, 90),
                 {true, 0, 1},
                 100,
                 St::kLift,
                 "cell_silence.cleared",
                 false,
                 false,
                 1});
    t.push_back({"back just now: the clear time starts",
                 c,
                 Suspended(0),
                 {true, 0, 1},
                 100,
                 St::kHold,
                 "cell_silence.holding",
                 true,
                 false,
                 1});
    t.push_back({"flapping cell: fires past the budget",
                 c,
                 Watching(2),
                 {true, 6, 1},
                 100,
                 St::kSetAside,
                 "cell_silence.set_aside",
                 false,
                 true,
                 2});
    t.push_back({"clear for window x hold_s: budget back",
                 c,
                 {false, false, 0, 50, 2},
                 {true, 0, 1},
                 100,
                 St::kNone,
                 "cell_silence.clean_window",
                 false,
                 false,
                 0});
  }
  {
    const C c = C::kStoreFreeSpace;
    t.push_back({"plenty of space",
                 c,
                 Watching(),
                 {true, 5000, 1},
                 100,
                 St::kNone,
                 "suspender.clear",
                 false,
                 false,
                 0});
    t.push_back({"below the threshold fires",
                 c,
                 Watching(),
                 {true, 999, 1},
                 100,
                 St::kFire,
                 "store_free_space.fired",
                 true,
                 false,
                 1});
    t.push_back({"budget 0: never set aside",
                 c,
                 Watching(50),
                 {true, 999, 1},
                 100,
                 St::kFire,
                 "store_free_space.fired",
                 true,
                 false,
                 51});
    t.push_back({"unreadable while suspended: holds",
                 c,
                 Suspended(0),
                 {false, 0, 0},
                 100,
                 St::kHold,
                 "store_free_space.holding",
                 true,
                 false,
                 1});
    t.push_back({"freed and clear for hold_s: lifts",
                 c,
                 Suspended(0, 1, 85),
                 {true, 5000, 1},
                 100,
                 St::kLift,
                 "store_free_space.cleared",
                 false,
                 false,
                 1});
    t.push_back({"clear, but the hold since firing is not over",
                 c,
                 Suspended(95, 1, 50),
                 {true, 5000, 1},
                 100,
                 St::kHold,
                 "store_free_space.holding",
                 true,
                 false,
                 1});
  }
  return t;
}

TEST(SuspenderPolicy, EveryRowOfTheTable) {
  for (const Row& r : Table()) {
    const SuspenderDecision d =
        DecideSuspender(r.condition, Limits(r.condition), r.state, r.reading, r.now);
    SCOPED_TRACE(std::string(ToString(r.condition)) + ": " + r.what);
    EXPECT_EQ(d.step, r.step);
    EXPECT_EQ(std::string(d.rule), r.rule);
    EXPECT_EQ(d.next.suspended, r.suspended_after);
    EXPECT_EQ(d.next.set_aside, r.set_aside_after);
    EXPECT_EQ(d.next.fires, r.fires_after);
    if (d.step == St::kFire) {
      EXPECT_EQ(d.next.fired_at, r.now);
      EXPECT_FALSE(d.evidence.empty());
    }
  }
}

TEST(SuspenderPolicy, TheTableCoversEveryConditionFiringAndLifting) {
  std::set<std::pair<C, St>> seen;
  for (const Row& r : Table()) seen.insert({r.condition, r.step});
  for (C c : kConditions) {
    EXPECT_TRUE(seen.count({c, St::kFire})) << ToString(c);
    EXPECT_TRUE(seen.count({c, St::kLift})) << ToString(c);
  }
}

TEST(SuspenderPolicy, SwitchedOffNeverFiresAndLiftsWhatItHeld) {
  SuspenderLimits off = Limits(C::kResetFailureRate);
  off.enabled = false;
  auto d = DecideSuspender(C::kResetFailureRate, off, Watching(), {true, 1.0, 4}, 100);
  EXPECT_EQ(d.step, St::kNone);
  d = DecideSuspender(C::kResetFailureRate, off, Suspended(99), {true, 1.0, 4}, 100);
  EXPECT_EQ(d.step, St::kLift);
  EXPECT_STREQ(d.rule, "suspender.disabled");
}

TEST(SuspenderPolicy, EvidenceSaysTheReadingAndItsLimit) {
  const auto d = DecideSuspender(C::kResetFailureRate, Limits(C::kResetFailureRate), Watching(),
                                 {true, 0.75, 4}, 1);
  EXPECT_EQ(d.evidence, "0.75 > 0.5 failed over the last 4 resets");
  const auto f =
      DecideSuspender(C::kStoreFreeSpace, Limits(C::kStoreFreeSpace), Watching(), {true, 10, 1}, 1);
  EXPECT_EQ(f.evidence, "10 bytes < 1000 bytes free in the store's folder");
}

TEST(SuspenderPolicy, ResumeByTheOperatorResetsHoldAndBudget) {
  const SuspenderState s = ResumedByOperator();
  EXPECT_FALSE(s.suspended);
  EXPECT_EQ(s.fires, 0);
  EXPECT_FALSE(s.set_aside);
}

TEST(SuspenderPolicy, ScopesAndTheDispatchGate) {
  EXPECT_EQ(ScopeOf(C::kResetFailureRate), Scope::kCell);
  EXPECT_EQ(ScopeOf(C::kCellSilence), Scope::kCell);
  EXPECT_EQ(ScopeOf(C::kDeadlineMisses), Scope::kCampaign);
  EXPECT_EQ(ScopeOf(C::kStoreFreeSpace), Scope::kService);
  EXPECT_EQ(DispatchGate({}, "c1"), nullptr);
  const std::vector<ActiveSuspension> cell = {{C::kSampleDropRate, "c2", 0}};
  EXPECT_EQ(DispatchGate(cell, "c1"), nullptr);
  EXPECT_STREQ(DispatchGate(cell, "c2"), "gate.cell_suspended");
  // A campaign's suspension is its store state: the gate lets the cell claim (other campaigns).
  EXPECT_EQ(DispatchGate({{C::kDeadlineMisses, "", 4}}, "c1"), nullptr);
  EXPECT_STREQ(DispatchGate({{C::kStoreFreeSpace, "", 0}}, "c1"), "gate.service_suspended");
}

TEST(SuspenderPolicy, ParsingNamesTheFieldAndKeepsDefaults) {
  const SuspenderConfig d;
  EXPECT_EQ(d[C::kResetFailureRate].threshold, 0.5);
  const auto c = ParseSuspenders(nlohmann::json::parse(
      R"({"cell_silence": {"threshold": 2, "hold_s": 1}, "sample_drop_rate": {"enabled": false}})"));
  EXPECT_EQ(c[C::kCellSilence].threshold, 2);
  EXPECT_EQ(c[C::kCellSilence].hold_s, 1);
  EXPECT_EQ(c[C::kCellSilence].budget, d[C::kCellSilence].budget);
  EXPECT_FALSE(c[C::kSampleDropRate].enabled);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {R"([])", "suspenders: must be a JSON object"},
      {R"({"reset_rate": {}})", "suspenders.reset_rate: unknown condition"},
      {R"({"cell_silence": {"hold_s": -1}})", "suspenders.cell_silence.hold_s: must be"},
      {R"({"cell_silence": {"hold": 1}})", "suspenders.cell_silence.hold: unknown field"},
      {R"({"sample_drop_rate": {"threshold": 1.5}})", "suspenders.sample_drop_rate.threshold"},
      {R"({"reset_failure_rate": {"window": 2.5}})", "suspenders.reset_failure_rate.window"},
      {R"({"reset_failure_rate": {"window": 2, "min_evidence": 3}})",
       "suspenders.reset_failure_rate.min_evidence: must be <= window"},
      {R"({"store_free_space": {"budget": 2}})", "suspenders.store_free_space.budget: must be 0"},
      {R"({"start_pose_drift": {"enabled": 1}})", "suspenders.start_pose_drift.enabled"},
  };
  for (const auto& [text, message] : bad) {
    try {
      ParseSuspenders(nlohmann::json::parse(text));
      ADD_FAILURE() << text << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  }
  // Round trip.
  const auto again = ParseSuspenders(ToJson(c));
  EXPECT_EQ(ToJson(again), ToJson(c));
}

// docs/operations.md quotes the defaults in a table: each row must be the code's.
TEST(SuspenderPolicy, TheDefaultsDocsOperationsQuotesAreTheCodes) {
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/docs/operations.md");
  ASSERT_TRUE(in) << "docs/operations.md missing";
  const SuspenderConfig d;
  std::set<std::string> rows;
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("| `", 0) != 0) continue;
    std::vector<std::string> cells;
    std::stringstream ss(line.substr(1));
    std::string cell;
    while (std::getline(ss, cell, '|')) {
      const auto b = cell.find_first_not_of(' '), e = cell.find_last_not_of(' ');
      cells.push_back(b == std::string::npos ? "" : cell.substr(b, e - b + 1));
    }
    if (cells.size() < 9) continue;
    const auto c = ParseCondition(cells[0].substr(1, cells[0].size() - 2));
    if (!c) continue;
    rows.insert(ToString(*c));
    const SuspenderLimits& l = d[*c];
    EXPECT_EQ(cells[1], ToString(ScopeOf(*c))) << line;
    EXPECT_EQ(cells[3], *c == C::kStoreFreeSpace ? "below" : "above") << line;
    EXPECT_DOUBLE_EQ(std::stod(cells[4]), l.threshold) << line;
    EXPECT_EQ(std::stoi(cells[5]), l.window) << line;
    EXPECT_EQ(std::stoi(cells[6]), l.min_evidence) << line;
    EXPECT_DOUBLE_EQ(std::stod(cells[7]), l.hold_s) << line;
    EXPECT_EQ(std::stoi(cells[8]), l.budget) << line;
  }
  EXPECT_EQ(rows.size(), kConditions.size()) << "a condition is missing from the table";
}

}  // namespace
}  // namespace arena::orchestrator
