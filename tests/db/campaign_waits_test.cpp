// Issue 26 in the store (migration 18): what the claim gate reads of the
// planned trials, and a waiting campaign skipped by every claim until its
// wait is cleared. Pins: before the gate, a campaign no cell could host was
// claimed trial after trial.
#include <gtest/gtest.h>

#include <map>
#include <optional>
#include <vector>

#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeTrials;
using testing::TempDir;
using K = StoreError::Kind;

TEST(CampaignWaits, AWaitingCampaignIsNotClaimedUntilCleared) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c1", {"point", "line", "patch"});
  const auto high = store->CreateCampaign(MakeCampaign("high", 5), MakeTrials(3));
  const auto low = store->CreateCampaign(MakeCampaign("low", 0), MakeTrials(2));
  // What the gate reads: each active campaign's planned trials, alike grouped.
  std::map<std::int64_t, std::int64_t> planned;
  for (const auto& n : store->PlannedNeeds()) {
    planned[n.campaign_id] += n.trials;
    EXPECT_NE(n.contact_mask, 0);
  }
  EXPECT_EQ(planned[high], 3);
  EXPECT_EQ(planned[low], 2);

  store->SetCampaignWait(high, "pusher_speed", "no live cell can push at 0.8 m/s",
                         "claim_gate.waits");
  const auto waits = store->ListCampaignWaits();
  ASSERT_EQ(waits.size(), 1u);
  EXPECT_EQ(waits[0].campaign_id, high);
  EXPECT_EQ(waits[0].kind, "pusher_speed");
  EXPECT_EQ(waits[0].rule, "claim_gate.waits");
  // The higher-priority campaign waits: the claim takes the other one's trial.
  auto claim = store->ClaimNextTrial("c1");
  ASSERT_TRUE(claim.has_value());
  EXPECT_EQ(claim->campaign_id, low);
  for (const auto& t : store->ClaimWindow("c1", 10)) EXPECT_EQ(t.campaign_id, low);
  // Cleared: dispatch resumes with it.
  EXPECT_TRUE(store->ClearCampaignWait(high));
  EXPECT_FALSE(store->ClearCampaignWait(high));
  EXPECT_TRUE(store->ListCampaignWaits().empty());
  claim = store->ClaimNextTrial("c1");
  ASSERT_TRUE(claim.has_value());
  EXPECT_EQ(claim->campaign_id, high);
}

// The gate's allow list (the CI race of stop 34): a campaign submitted after
// the gate last ran was claimed before the gate saw it, and its trials went
// to a cell that refused them. Claims now take only from the campaigns the
// gate opened; ActiveCampaignIds is how the service notices a new one.
TEST(CampaignWaits, ClaimsTakeOnlyFromTheCampaignsTheGateOpened) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  store->UpsertCell("c1", {"point", "line", "patch"});
  store->RestrictClaimsTo(std::vector<std::int64_t>{});  // before the gate ran: nothing
  const auto first = store->CreateCampaign(MakeCampaign("first", 0), MakeTrials(2));
  EXPECT_EQ(store->ActiveCampaignIds(), std::vector<std::int64_t>{first});
  EXPECT_FALSE(store->ClaimNextTrial("c1").has_value());
  EXPECT_FALSE(store->PeekNextTrial("c1").has_value());
  EXPECT_TRUE(store->ClaimWindow("c1", 10).empty());
  store->RestrictClaimsTo(std::vector<std::int64_t>{first});
  const auto later = store->CreateCampaign(MakeCampaign("later", 9), MakeTrials(2));
  EXPECT_EQ(store->ActiveCampaignIds(), (std::vector<std::int64_t>{first, later}));
  // The later campaign has the higher priority, but the gate has not seen it.
  for (const auto& t : store->ClaimWindow("c1", 10)) EXPECT_EQ(t.campaign_id, first);
  const auto window = store->ClaimWindow("c1", 10);
  ASSERT_FALSE(window.empty());
  auto claim = store->ClaimNextTrial("c1");
  ASSERT_TRUE(claim.has_value());
  EXPECT_EQ(claim->campaign_id, first);
  // ClaimTrial by id refuses a trial of a campaign outside the list.
  std::int64_t later_trial = 0;
  for (const auto& t : store->ListTrials(later)) later_trial = t.id;
  EXPECT_FALSE(store->ClaimTrial("c1", later_trial, "claim.plan_order").has_value());
  // Lifted: every active campaign again.
  store->RestrictClaimsTo(std::nullopt);
  claim = store->ClaimNextTrial("c1");
  ASSERT_TRUE(claim.has_value());
  EXPECT_EQ(claim->campaign_id, later);
}

TEST(CampaignWaits, BadInputRefusedNothingStored) {
  TempDir dir;
  auto store = Store::Open(dir.File("s.db"));
  const auto id = store->CreateCampaign(MakeCampaign("c"), MakeTrials(1));
  auto expect_error = [](const auto& call, K kind) {
    try {
      call();
      ADD_FAILURE() << "expected a StoreError";
    } catch (const StoreError& e) {
      EXPECT_EQ(static_cast<int>(e.kind()), static_cast<int>(kind)) << e.what();
    }
  };
  expect_error([&] { store->SetCampaignWait(id, "weather", "why", "r"); }, K::kBadInput);
  expect_error([&] { store->SetCampaignWait(id, "defects", "", "r"); }, K::kBadInput);
  expect_error([&] { store->SetCampaignWait(99, "defects", "why", "r"); }, K::kNotFound);
  EXPECT_TRUE(store->ListCampaignWaits().empty());
}

}  // namespace
}  // namespace arena::db
