// Issue 26 item 4 with several cells: every executed trial stores the start
// state its cell measured (trials.start_*), the pose its predictions start
// from. `arena run` starts the service and three simulated cells as
// processes over DDS on a test-unique domain.
#include <sqlite3.h>

#include <array>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "service_support.hpp"

namespace arena::test {
namespace {

struct StartRow {
  std::int64_t trial_id = 0;
  std::string cell_id, state;
  bool has_start = false;
  std::array<double, 7> start{};
  double position_error = NAN, angle_error = NAN;
  std::string prediction_detail;  // the prediction of the trial's last attempt ("": none)
};

std::vector<StartRow> ReadStarts(const std::string& path) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  EXPECT_EQ(sqlite3_prepare_v2(
                db,
                "SELECT t.id, t.cell_id, t.state, t.start_x IS NOT NULL, t.start_x, t.start_y,"
                " t.start_z, t.start_qw, t.start_qx, t.start_qy, t.start_qz,"
                " t.start_position_error, t.start_angle_error,"
                " (SELECT p.detail_json FROM predictions p WHERE p.trial_id = t.id"
                "  AND p.attempt = t.attempt LIMIT 1)"
                " FROM trials t ORDER BY t.id",
                -1, &s, nullptr),
            SQLITE_OK)
      << sqlite3_errmsg(db);
  std::vector<StartRow> rows;
  while (sqlite3_step(s) == SQLITE_ROW) {
    StartRow r;
    r.trial_id = sqlite3_column_int64(s, 0);
    auto text = [&](int i) {
      const auto* p = sqlite3_column_text(s, i);
      return p ? std::string(reinterpret_cast<const char*>(p)) : std::string();
    };
    r.cell_id = text(1);
    r.state = text(2);
    r.has_start = sqlite3_column_int(s, 3) != 0;
    for (int k = 0; k < 7; ++k) r.start[k] = sqlite3_column_double(s, 4 + k);
    if (sqlite3_column_type(s, 11) != SQLITE_NULL) r.position_error = sqlite3_column_double(s, 11);
    if (sqlite3_column_type(s, 12) != SQLITE_NULL) r.angle_error = sqlite3_column_double(s, 12);
    r.prediction_detail = text(13);
    rows.push_back(std::move(r));
  }
  sqlite3_finalize(s);
  sqlite3_close(db);
  return rows;
}

// Pins: with several cells only the trials whose cell's last reset had been
// aimed at them got a start state (22 of 36 here before): a cell's first
// trial had no reset before it, and a trial that another cell's reset had
// been aimed at -- the cells looked up the same next trial while they
// executed, one of them claimed it -- started where the simulated cell placed
// it without the service storing that start. Now every done trial has the
// start its cell measured: the first sample of its stream (the sensors'
// view, or the sample's pose when they dropped it), the very start its stored
// prediction took (detail_json "start").
TEST(StartStateEndToEnd, EveryDoneTrialOfThreeCellsHasItsMeasuredStart) {
  TempDir dir;
  const std::string db = dir / "start.db";
  // Paced at a twentieth of wall-clock time, so all three cells take trials.
  const int rc = RunArena(
      {"run", std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/smoke.json", "--db", db,
       "--cells", "3", "--speed", "0.05", "--domain", std::to_string(TestDomain(1)), "--quiet"},
      dir / "run.out", std::chrono::seconds(150));
  ASSERT_EQ(rc, 0) << ReadFile(dir / "run.out") << ReadFile(db + ".log");
  ExpectCampaignConsistent(db, 1, 36);
  auto store = OpenReadOnly(db);
  const std::vector<StartRow> rows = ReadStarts(db);
  ASSERT_EQ(rows.size(), 36u);
  std::set<std::string> cells;
  int done = 0;
  for (const StartRow& r : rows) {
    if (r.state != "done") continue;
    ++done;
    cells.insert(r.cell_id);
    SCOPED_TRACE("trial " + std::to_string(r.trial_id) + " on " + r.cell_id);
    ASSERT_TRUE(r.has_start) << "a done trial without the start its cell measured";
    // The start is the stream's first sample as the cell measured it.
    const auto truth = store->ReadGroundTruth(r.trial_id);
    ASSERT_FALSE(truth.samples.empty());
    const db::Sample& first = truth.samples.front();
    const auto& measured = first.observed_valid ? first.observed_object_pose : first.object_pose;
    for (int k = 0; k < 7; ++k) EXPECT_DOUBLE_EQ(r.start[k], measured[k]) << "component " << k;
    // ... the start the trial's prediction took, and its errors the same offsets.
    ASSERT_FALSE(r.prediction_detail.empty());
    const auto start = nlohmann::json::parse(r.prediction_detail).at("start");
    EXPECT_EQ(start.at("from"), "measured");
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(r.start[k], start.at("position_m")[k].get<double>(), 1e-12);
    EXPECT_NEAR(r.position_error, start.at("offset_m").get<double>(), 1e-12);
    EXPECT_NEAR(r.angle_error, start.at("offset_rad").get<double>(), 1e-9);
    EXPECT_GT(r.position_error, 0.0);  // the reset and the sensors never place exactly
  }
  EXPECT_EQ(done, 36) << ReadFile(db + ".log");
  EXPECT_EQ(cells.size(), 3u) << "the case of several cells was not exercised";
  // The drift view counts every done trial (its cells' reset bias).
  int drift_trials = 0;
  for (const auto& d : store->Drift(1)) drift_trials += static_cast<int>(d.trials);
  EXPECT_EQ(drift_trials, done);
  // `arena status` says what its drift is of.
  ASSERT_EQ(RunArena({"status", "--db", db}, dir / "status.out", std::chrono::seconds(30)), 0);
  const std::string status = ReadFile(dir / "status.out");
  EXPECT_NE(status.find("start-state drift (the start each trial's cell measured - nominal)"),
            std::string::npos)
      << status;
}

}  // namespace
}  // namespace arena::test
