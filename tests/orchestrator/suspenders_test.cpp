// The suspenders at run time (suspenders.hpp) with the service's watch
// (service_watch.hpp) on a real SQLite store and a fake clock: each condition
// fires (recorded: why, evidence, when; dispatch held), holds, lifts (by its
// rule), `arena resume` lifts at once, and a condition that keeps firing is
// set aside (a cell quarantined, a campaign's planned trials failed with the
// reason) while the rest goes on. Every step is an event in service_events.
#include "arena/orchestrator/suspenders.hpp"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "db/db_test_util.hpp"
#include "service_watch.hpp"

namespace arena::orchestrator {
namespace {

using C = Condition;

struct Fixture {
  std::string dir;
  std::unique_ptr<db::Store> store;
  ServiceOptions options;
  double now = 1000;
  std::unique_ptr<Suspenders> suspenders;
  std::unique_ptr<ServiceWatch> watch;

  explicit Fixture(SuspenderConfig config) {
    char tmpl[] = "/tmp/arena-suspenders-XXXXXX";
    dir = mkdtemp(tmpl);
    options.db_path = dir + "/s.db";
    store = db::Store::Open(options.db_path);
    options.suspenders = config;
    suspenders = std::make_unique<Suspenders>(config, [this] { return now; });
    watch = std::make_unique<ServiceWatch>(*store, options, *suspenders, nullptr);
  }
  ~Fixture() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  std::vector<db::Suspension> Active() const { return store->ListSuspensions(true); }
  std::vector<std::string> EventKinds() const {
    std::vector<std::string> out;
    for (const auto& e : store->ListEvents()) out.push_back(e.kind);
    return out;
  }
};

// Free space never fires in these tests (0 bytes is never below the threshold).
SuspenderConfig Quick() {
  SuspenderConfig c;
  for (C k : kConditions) {
    c[k].hold_s = 10;
    c[k].window = 4;
    c[k].min_evidence = 3;
    c[k].budget = 2;
  }
  c[C::kStoreFreeSpace].threshold = 0;
  c[C::kStoreFreeSpace].budget = 0;
  c[C::kCellSilence].threshold = 5;
  return c;
}

TEST(Suspenders, ResetFailuresFireHoldLiftAndAreRecorded) {
  Fixture f(Quick());
  f.watch->Poll();
  for (bool ok : {true, false, true}) f.suspenders->OnReset("c1", 1, ok, true, 0.001);
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty()) << "1 of 3 failed: 0.33 is within 0.5";
  f.suspenders->OnReset("c1", 1, false, false, 0);
  f.suspenders->OnReset("c1", 1, false, false, 0);
  f.watch->Poll();
  ASSERT_EQ(f.Active().size(), 1u);
  const db::Suspension s = f.Active()[0];
  EXPECT_EQ(s.condition, "reset_failure_rate");
  EXPECT_EQ(s.scope, "cell");
  EXPECT_EQ(s.cell_id, "c1");
  EXPECT_EQ(s.rule, "reset_failure_rate.fired");
  EXPECT_EQ(s.evidence, "0.75 > 0.5 failed over the last 4 resets");
  EXPECT_STREQ(f.suspenders->DispatchGate("c1"), "gate.cell_suspended");
  EXPECT_EQ(f.suspenders->DispatchGate("c2"), nullptr) << "another cell goes on";
  f.now += 9;
  f.watch->Poll();
  EXPECT_EQ(f.Active().size(), 1u) << "held for hold_s";
  f.now += 1;
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty());
  EXPECT_EQ(f.suspenders->DispatchGate("c1"), nullptr);
  const auto all = f.store->ListSuspensions(false);
  ASSERT_EQ(all.size(), 1u);
  ASSERT_TRUE(all[0].lifted_at.has_value());
  EXPECT_EQ(all[0].lifted_by, "reset_failure_rate.hold_elapsed");
  EXPECT_EQ(f.EventKinds(), (std::vector<std::string>{"suspension_fired", "suspension_lifted"}));
  const auto fired = nlohmann::json::parse(f.store->ListEvents()[0].event_json);
  EXPECT_EQ(fired["event"], "suspension_fired");
  EXPECT_EQ(fired["cell"], "c1");
  EXPECT_EQ(fired["detail"]["condition"], "reset_failure_rate");
  // The window started empty after the fire: the old failures do not fire it again.
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty());
}

TEST(Suspenders, ArenaResumeLiftsAtOnceAndResetsTheHoldAndBudget) {
  Fixture f(Quick());
  f.store->UpsertCell("c1", {"point"});
  const auto campaign =
      f.store->CreateCampaign(db::testing::MakeCampaign(), db::testing::MakeTrials(2));
  for (int i = 0; i < 4; ++i) f.suspenders->OnStream("c1", campaign, 100, 50);
  f.watch->Poll();
  ASSERT_EQ(f.Active().size(), 1u);
  EXPECT_EQ(f.Active()[0].condition, "sample_drop_rate");
  // `arena resume 1 --cell c1`, from another process.
  const auto lifted = f.store->ResumeSuspended(campaign, std::string("c1"));
  ASSERT_EQ(lifted.size(), 1u);
  f.watch->Poll();
  EXPECT_EQ(f.suspenders->DispatchGate("c1"), nullptr) << "lifted within one pass";
  const auto all = f.store->ListSuspensions(false);
  EXPECT_EQ(all[0].lifted_by, "arena resume");
  EXPECT_EQ(f.EventKinds().back(), "suspension_lifted");
  EXPECT_NE(f.store->ListEvents().back().message.find("arena resume"), std::string::npos);
  // Budget reset: two more fires are suspensions, not a set aside.
  for (int round = 0; round < 2; ++round) {
    for (int i = 0; i < 4; ++i) f.suspenders->OnStream("c1", campaign, 100, 50);
    f.watch->Poll();
    ASSERT_EQ(f.Active().size(), 1u) << "round " << round;
    f.now += 10;
    f.watch->Poll();
    ASSERT_TRUE(f.Active().empty());
  }
  // A third: the budget (2) is used up, the condition is set aside: the cell is quarantined.
  for (int i = 0; i < 4; ++i) f.suspenders->OnStream("c1", campaign, 100, 50);
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty());
  EXPECT_EQ(f.store->GetCell("c1").state, db::CellState::kQuarantined)
      << "a set-aside cell condition quarantines the cell";
  EXPECT_NE(f.store->GetCell("c1").quarantine_reason.find("set aside: sample_drop_rate"),
            std::string::npos)
      << f.store->GetCell("c1").quarantine_reason;
  EXPECT_STREQ(f.suspenders->DispatchGate("c1"), "gate.cell_set_aside");
  const auto kinds = f.EventKinds();
  EXPECT_NE(std::find(kinds.end() - 2, kinds.end(), "condition_set_aside"), kinds.end());
  EXPECT_EQ(kinds.back(), "cell_quarantined");
}

TEST(Suspenders, StartPoseDriftCountsObservedResetsOnly) {
  Fixture f(Quick());
  f.store->UpsertCell("c1", {"point"});
  for (int i = 0; i < 5; ++i) f.suspenders->OnReset("c1", 1, true, false, 0.5);  // not observed
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty());
  for (int i = 0; i < 3; ++i) f.suspenders->OnReset("c1", 1, true, true, 0.008);
  f.watch->Poll();
  ASSERT_EQ(f.Active().size(), 1u);
  EXPECT_EQ(f.Active()[0].condition, "start_pose_drift");
  f.now += 10;
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty());
}

TEST(Suspenders, CellSilenceLiftsOnlyAfterTheCellIsBackForTheHold) {
  Fixture f(Quick());
  f.suspenders->OnCellAlive("c1", true);
  f.watch->Poll();
  f.suspenders->OnCellAlive("c1", false);
  f.now += 4;
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty()) << "4 s is within the 5 s threshold";
  f.now += 2;
  f.watch->Poll();
  ASSERT_EQ(f.Active().size(), 1u);
  EXPECT_EQ(f.Active()[0].condition, "cell_silence");
  f.now += 60;  // still gone: holds however long
  f.watch->Poll();
  EXPECT_EQ(f.Active().size(), 1u);
  f.suspenders->OnCellAlive("c1", true);
  f.watch->Poll();
  f.now += 9;
  f.watch->Poll();
  EXPECT_EQ(f.Active().size(), 1u) << "back for 9 s of a 10 s hold";
  f.now += 1;
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty());
  EXPECT_EQ(f.store->ListSuspensions(false)[0].lifted_by, "cell_silence.cleared");
}

TEST(Suspenders, DeadlineMissesPauseTheCampaignAndSetAsideItsPlannedTrials) {
  Fixture f(Quick());
  const auto a =
      f.store->CreateCampaign(db::testing::MakeCampaign("a"), db::testing::MakeTrials(4));
  const auto b =
      f.store->CreateCampaign(db::testing::MakeCampaign("b"), db::testing::MakeTrials(4));
  for (int round = 0; round < 2; ++round) {
    for (int i = 0; i < 3; ++i) f.suspenders->OnClosedLoop("c1", a, 500, 200);
    f.watch->Poll();
    ASSERT_EQ(f.Active().size(), 1u);
    EXPECT_EQ(f.Active()[0].scope, "campaign");
    EXPECT_EQ(f.store->GetCampaign(a).state, db::CampaignState::kPaused);
    EXPECT_EQ(
        f.store->GetCampaign(a).state_reason.rfind("suspended: deadline_misses: 0.4 > 0.2", 0), 0u)
        << f.store->GetCampaign(a).state_reason;
    EXPECT_EQ(f.store->GetCampaign(b).state, db::CampaignState::kActive) << "b goes on";
    EXPECT_EQ(f.suspenders->DispatchGate("c1"), nullptr) << "the cell still serves b";
    f.now += 10;
    f.watch->Poll();
    EXPECT_TRUE(f.Active().empty());
    EXPECT_EQ(f.store->GetCampaign(a).state, db::CampaignState::kActive);
  }
  for (int i = 0; i < 3; ++i) f.suspenders->OnClosedLoop("c1", a, 500, 200);
  f.watch->Poll();
  EXPECT_EQ(f.store->GetCampaign(a).state, db::CampaignState::kActive);
  for (const auto& t : f.store->ListTrials(a)) {
    EXPECT_EQ(t.state, db::TrialState::kFailed);
    const auto rows = f.store->ListTransitions(t.id);
    EXPECT_EQ(rows.back().rule, "deadline_misses.set_aside");
    EXPECT_EQ(rows.back().reason.rfind("set aside: deadline_misses: ", 0), 0u)
        << rows.back().reason;
  }
  for (const auto& t : f.store->ListTrials(b)) EXPECT_EQ(t.state, db::TrialState::kPlanned);
}

TEST(Suspenders, AnOperatorsPauseIsNotResumedByALift) {
  Fixture f(Quick());
  const auto a =
      f.store->CreateCampaign(db::testing::MakeCampaign("a"), db::testing::MakeTrials(4));
  f.store->PauseCampaign(a);
  for (int i = 0; i < 3; ++i) f.suspenders->OnClosedLoop("c1", a, 500, 200);
  f.watch->Poll();
  ASSERT_EQ(f.Active().size(), 1u);
  f.now += 10;
  f.watch->Poll();
  EXPECT_TRUE(f.Active().empty());
  EXPECT_EQ(f.store->GetCampaign(a).state, db::CampaignState::kPaused);
  EXPECT_EQ(f.store->GetCampaign(a).state_reason, "paused by operator");
}

TEST(Suspenders, StoreFreeSpaceHoldsEveryCell) {
  SuspenderConfig c = Quick();
  c[C::kStoreFreeSpace].threshold = 1e15;  // more than any disk here
  Fixture f(c);
  f.watch->Poll();
  ASSERT_EQ(f.Active().size(), 1u);
  EXPECT_EQ(f.Active()[0].scope, "service");
  EXPECT_STREQ(f.suspenders->DispatchGate("c1"), "gate.service_suspended");
  EXPECT_STREQ(f.suspenders->DispatchGate("c9"), "gate.service_suspended");
  f.now += 100;
  f.watch->Poll();
  EXPECT_EQ(f.Active().size(), 1u) << "still short of space";
}

TEST(Suspenders, AFailureRateAboveItsThresholdIsToldOnce) {
  Fixture f(Quick());
  const auto a =
      f.store->CreateCampaign(db::testing::MakeCampaign("a"), db::testing::MakeTrials(12));
  f.store->SetAsideTrials(a, "set aside: a test", "test.set_aside");
  for (int i = 0; i < 12; ++i) {
    f.watch->Poll();
    f.now += 1;
  }
  const auto kinds = f.EventKinds();
  EXPECT_EQ(std::count(kinds.begin(), kinds.end(), "failure_rate_high"), 1);
  const auto events = f.store->ListEvents();
  const auto it = std::find_if(events.begin(), events.end(), [](const db::EventRecord& e) {
    return e.kind == "failure_rate_high";
  });
  ASSERT_NE(it, events.end());
  EXPECT_EQ(it->campaign_id, a);
  EXPECT_EQ(it->message, "campaign 1: 12 of 12 finished trials failed");
}

TEST(Suspenders, ARestartedServiceAdoptsTheStoresSuspensions) {
  Fixture f(Quick());
  for (int i = 0; i < 4; ++i) f.suspenders->OnReset("c1", 1, false, false, 0);
  f.watch->Poll();
  ASSERT_EQ(f.Active().size(), 1u);
  // A new service on the same store.
  Suspenders again(Quick(), [&f] { return f.now; });
  ServiceWatch watch(*f.store, f.options, again, nullptr);
  watch.Poll();
  EXPECT_STREQ(again.DispatchGate("c1"), "gate.cell_suspended");
  f.now += 10;
  watch.Poll();
  EXPECT_EQ(again.DispatchGate("c1"), nullptr);
  EXPECT_TRUE(f.Active().empty());
}

}  // namespace
}  // namespace arena::orchestrator
