// The stored sensitivity runs (migration 8): round trip, refusals (nothing
// stored on bad input), read-only stores, the latest-run view.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "arena/db/query.hpp"
#include "arena/db/sensitivity.hpp"
#include "db/db_test_util.hpp"

namespace arena::db {
namespace {

class SensitivityStore : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/arena-sens-store-XXXXXX";
    dir_ = mkdtemp(tmpl);
    path_ = dir_ + "/s.db";
    store_ = Store::Open(path_);
    campaign_ = store_->CreateCampaign(testing::MakeCampaign(), testing::MakeTrials(4));
  }
  void TearDown() override {
    store_.reset();
    if (!HasFailure()) std::filesystem::remove_all(dir_);
  }
  SensitivityCondition Row(int condition) {
    SensitivityCondition c;
    c.condition = condition;
    c.params_json = R"({"grip_force": 5})";
    c.replicates = 2;
    c.ensemble = 16;
    c.predicted_position_spread = 1e-4;
    c.observed_position_spread = 2e-4;
    c.verdict = "matches";
    c.unstable = condition == 1;
    c.boundary_parameter = c.unstable ? "mu_scale" : "";
    if (c.unstable) {
      c.boundary_offset = -0.01;
      c.boundary_tolerances = 0.05;
    }
    return c;
  }
  std::string dir_, path_;
  std::unique_ptr<Store> store_;
  std::int64_t campaign_ = 0;
};

TEST_F(SensitivityStore, RoundTripAndLatestView) {
  const auto first = RecordSensitivityRun(*store_, campaign_, R"({"ensemble": 16})",
                                          R"({"conditions": 2})", {Row(0), Row(1)});
  const auto second = RecordSensitivityRun(*store_, campaign_, "{}", "{}", {Row(0)});
  EXPECT_GT(second, first);
  const auto runs = ListSensitivityRuns(*store_, campaign_);
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[0].settings_json, R"({"ensemble": 16})");
  const auto rows = ListSensitivityConditions(*store_, first);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[1].boundary_parameter, "mu_scale");
  EXPECT_DOUBLE_EQ(*rows[1].boundary_offset, -0.01);
  EXPECT_FALSE(rows[0].boundary_offset.has_value());
  EXPECT_FALSE(rows[0].observed_rotation_spread.has_value());
  EXPECT_TRUE(rows[1].unstable);
  EXPECT_THROW(ListSensitivityConditions(*store_, 99), StoreError);
  store_.reset();
  StoreOptions ro;
  ro.read_only = true;
  auto reader = Store::Open(path_, ro);
  const auto latest = RunQuery(*reader, "SELECT count(*) FROM sensitivity_latest");
  EXPECT_EQ(std::get<std::int64_t>(latest.rows[0][0]), 1);  // only the second run's row
  EXPECT_THROW(RecordSensitivityRun(*reader, campaign_, "{}", "{}", {Row(0)}), StoreError);
}

TEST_F(SensitivityStore, BadInputIsRefusedAndNothingStored) {
  auto nan = Row(0);
  nan.predicted_position_spread = std::numeric_limits<double>::quiet_NaN();
  auto expect_refused = [&](const std::vector<SensitivityCondition>& rows, std::int64_t campaign,
                            StoreError::Kind kind, const std::string& words) {
    try {
      RecordSensitivityRun(*store_, campaign, "{}", "{}", rows);
      FAIL() << "accepted";
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), kind) << e.what();
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  expect_refused({nan}, campaign_, StoreError::Kind::kBadInput, "predicted_position_spread");
  expect_refused({Row(0), Row(0)}, campaign_, StoreError::Kind::kBadInput, "appears twice");
  auto bad_json = Row(2);
  bad_json.params_json = "[1]";
  expect_refused({bad_json}, campaign_, StoreError::Kind::kBadInput, "params_json");
  expect_refused({Row(0)}, 777, StoreError::Kind::kNotFound, "no campaign 777");
  EXPECT_TRUE(ListSensitivityRuns(*store_, campaign_).empty());
  EXPECT_TRUE(store_->CheckInvariants().empty());
}

TEST_F(SensitivityStore, CellProfilesAreThoseRecordedAtDispatch) {
  EXPECT_TRUE(AppliedDefectProfiles(*store_, campaign_).empty());  // nothing dispatched
  store_->UpsertCell("c1", {"point"}, "{}", R"({"friction_variability": {"mu_scale_std": 0.1}})");
  const auto claimed = store_->ClaimNextTrial("c1");
  ASSERT_TRUE(claimed.has_value());
  const auto profiles = AppliedDefectProfiles(*store_, campaign_);
  ASSERT_EQ(profiles.size(), 1u);
  EXPECT_NE(profiles.at(claimed->trial_id).find("mu_scale_std"), std::string::npos);
}

}  // namespace
}  // namespace arena::db
