// Issue 29 in the store: the claim window and claiming a chosen trial
// (change-aware scheduling), and the fixture changes table (migration 17).
#include <gtest/gtest.h>

#include <sqlite3.h>

#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeTrials;
using testing::TempDir;
using K = StoreError::Kind;

#define EXPECT_STORE_ERROR(stmt, kind_)                                           \
  do {                                                                            \
    try {                                                                         \
      stmt;                                                                       \
      ADD_FAILURE() << "expected StoreError from " #stmt;                         \
    } catch (const StoreError& e) {                                               \
      EXPECT_EQ(static_cast<int>(e.kind()), static_cast<int>(kind_)) << e.what(); \
    }                                                                             \
  } while (0)

TEST(ClaimWindow, PlanOrderOfTheFirstCampaignWithWork) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("all", {"point", "line", "patch"});
  store->UpsertCell("points-only", {"point"});
  const auto low = store->CreateCampaign(MakeCampaign("low", 0), MakeTrials(6));
  const auto high = store->CreateCampaign(MakeCampaign("high", 5), MakeTrials(3, "patch"));
  auto w = store->ClaimWindow("all", 10);
  ASSERT_EQ(w.size(), 3u);  // the high-priority campaign only
  for (std::size_t i = 0; i < w.size(); ++i) {
    EXPECT_EQ(w[i].campaign_id, high);
    EXPECT_EQ(w[i].index, static_cast<std::int64_t>(i));
    EXPECT_FALSE(w[i].scene_json.empty());
  }
  // Contact types filter as ClaimNextTrial does.
  auto p = store->ClaimWindow("points-only", 4);
  ASSERT_EQ(p.size(), 4u);
  EXPECT_EQ(p.front().campaign_id, low);
  EXPECT_EQ(p.back().index, 3);
  EXPECT_EQ(store->PeekNextTrial("points-only")->trial_id, p.front().trial_id);
  EXPECT_STORE_ERROR(store->ClaimWindow("all", 0), K::kBadInput);
  EXPECT_STORE_ERROR(store->ClaimWindow("nobody", 5), K::kNotFound);
}

TEST(ClaimTrial, ClaimsTheChosenOneOnceAndNamesTheRule) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c1", {"point"});
  store->UpsertCell("c2", {"point"});
  store->UpsertCell("patches", {"patch"});
  const auto cid = store->CreateCampaign(MakeCampaign("c"), MakeTrials(4));
  auto w = store->ClaimWindow("c1", 4);
  ASSERT_EQ(w.size(), 4u);
  const auto chosen = w[2];
  auto t = store->ClaimTrial("c1", chosen.trial_id, "claim.least_change");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->trial_id, chosen.trial_id);
  EXPECT_EQ(t->campaign_id, cid);
  EXPECT_EQ(t->index, 2);
  const Trial stored = store->GetTrial(chosen.trial_id);
  EXPECT_EQ(stored.state, TrialState::kDispatched);
  EXPECT_EQ(stored.cell_id, "c1");
  EXPECT_EQ(store->ListTransitions(chosen.trial_id).back().rule, "dispatch.claimed");
  EXPECT_EQ(store->ListTransitions(chosen.trial_id).back().reason, "claimed by claim.least_change");
  // Taken: another cell cannot have it; nor can a cell without its contact type.
  EXPECT_FALSE(store->ClaimTrial("c2", chosen.trial_id, "claim.least_change"));
  EXPECT_FALSE(store->ClaimTrial("patches", w[0].trial_id, "claim.block_entry"));
  // A paused campaign's trials and a quarantined cell get nothing.
  store->PauseCampaign(cid);
  EXPECT_FALSE(store->ClaimTrial("c2", w[0].trial_id, "claim.block_entry"));
  EXPECT_TRUE(store->ClaimWindow("c2", 4).empty());
  store->ResumeCampaign(cid);
  store->QuarantineCell("c2", "test");
  EXPECT_FALSE(store->ClaimTrial("c2", w[0].trial_id, "claim.block_entry"));
  EXPECT_STORE_ERROR(store->ClaimTrial("nobody", w[0].trial_id, "x"), K::kNotFound);
  EXPECT_EQ(store->ClaimWindow("c1", 10).size(), 3u);
}

TEST(FixtureChanges, RecordedListedAndBadInputRefused) {
  TempDir dir;
  const std::string path = dir.File("s.db");
  auto store = Store::Open(path);
  store->UpsertCell("c1", {"point"});
  const auto a = store->CreateCampaign(MakeCampaign("a"), MakeTrials(2));
  const auto b = store->CreateCampaign(MakeCampaign("b"), MakeTrials(1));
  const auto ta = store->ClaimWindow("c1", 5);
  ASSERT_FALSE(ta.empty());
  FixtureChangeRecord r;
  r.trial_id = ta[0].trial_id;
  r.cell_id = "c1";
  r.phase = "execute";
  r.what = "finger";
  r.from_key = "";
  r.to_key = "point r=0.01 mu=0.3 k=0";
  r.seconds = 20;
  FixtureChangeRecord p = r;
  p.phase = "reset";
  p.what = "pusher";
  p.from_key = "point r=0 mu=0.3 n=(0,0,1)";
  p.to_key = "line l=0.02 mu=0.3 n=(0,0,1) a=(1,0,0)";
  p.seconds = 5;
  store->RecordFixtureChanges({r, p});
  const auto list = store->ListFixtureChanges(ta[0].campaign_id);
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].what, "finger");
  EXPECT_EQ(list[0].from_key, "");
  EXPECT_EQ(list[1].phase, "reset");
  EXPECT_DOUBLE_EQ(list[1].seconds, 5);
  EXPECT_GT(list[1].at, 0);
  EXPECT_EQ(store->ListFixtureChanges(0).size(), 2u);
  EXPECT_TRUE(store->ListFixtureChanges(ta[0].campaign_id == a ? b : a).empty());
  // Bad input: nothing stored, the whole batch refused.
  auto bad = r;
  bad.what = "gripper";
  EXPECT_STORE_ERROR(store->RecordFixtureChanges({r, bad}), K::kBadInput);
  bad = r;
  bad.phase = "idle";
  EXPECT_STORE_ERROR(store->RecordFixtureChanges({bad}), K::kBadInput);
  bad = r;
  bad.seconds = -1;
  EXPECT_STORE_ERROR(store->RecordFixtureChanges({bad}), K::kBadInput);
  bad.seconds = std::nan("");
  EXPECT_STORE_ERROR(store->RecordFixtureChanges({bad}), K::kBadInput);
  bad = r;
  bad.trial_id = 999;
  EXPECT_STORE_ERROR(store->RecordFixtureChanges({r, bad}), K::kNotFound);
  bad = r;
  bad.cell_id = "nobody";
  EXPECT_STORE_ERROR(store->RecordFixtureChanges({bad}), K::kNotFound);
  EXPECT_EQ(store->ListFixtureChanges(0).size(), 2u);
  EXPECT_EQ(store->IntegrityCheck(), "ok");
  EXPECT_GE(Store::SchemaVersion(), 17);
}

}  // namespace
}  // namespace arena::db
