// Issue 26, "what a lab reads must be right": every failure has a reason a
// person can read (grouped, counted, blamed on the cell, the driver or the
// predictor), a finished campaign's rate stays what it was, unit slips are
// blamed on the field written. Each test names the behaviour it pins.
#include <algorithm>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/db/export.hpp"
#include "arena/db/query.hpp"
#include "arena/db/store.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "db/db_test_util.hpp"
#include "deadline_report.hpp"
#include "failure_reasons.hpp"
#include "plot_map.hpp"
#include "status_cells.hpp"

namespace arena::cli {
namespace {

using db::testing::MakeCampaign;
using db::testing::MakeTrials;
using db::testing::RunTrialToDone;
using db::testing::TempDir;

// Pins: before issue 26 a retry and a failed trial were counted (or not even
// that) without their reason; the reason was only in the service log.
TEST(FailureReasons, GroupedByReasonAndSourceWithCounts) {
  TempDir dir;
  const std::string path = dir.File("f.db");
  std::int64_t id = 0;
  {
    auto store = db::Store::Open(path);
    store->UpsertCell("sim1-3fa2c1", {"point"});
    store->UpsertCell("sim2-3fa2c1", {"point"});
    id = store->CreateCampaign(MakeCampaign(), MakeTrials(4));
    // Trial 1: a start-up race, retried, then done.
    auto t = store->ClaimNextTrial("sim1-3fa2c1");
    store->RetryTrial(t->trial_id, t->attempt,
                      "cell sim1-3fa2c1 failed: no command for 0.25 s after sample 0", 3, 0);
    t = store->ClaimNextTrial("sim1-3fa2c1");
    ASSERT_EQ(t->attempt, 2);
    RunTrialToDone(*store, *t, 5);
    // Trials 2 and 3: refused by two different cells for the same reason.
    t = store->ClaimNextTrial("sim1-3fa2c1");
    store->FailTrial(t->trial_id, t->attempt,
                     "refused by cell sim1-3fa2c1: pusher.motion: pushing for 500 s moves the "
                     "object outside the workspace",
                     arena::db::TrialEnd::kRefused);
    t = store->ClaimNextTrial("sim2-3fa2c1");
    store->FailTrial(t->trial_id, t->attempt,
                     "refused by cell sim2-3fa2c1: pusher.motion: pushing for 480.5 s moves the "
                     "object outside the workspace",
                     arena::db::TrialEnd::kRefused);
    // Trial 4: the robot driver gave up.
    t = store->ClaimNextTrial("sim2-3fa2c1");
    store->FailTrial(t->trial_id, t->attempt,
                     "cell sim2-3fa2c1: driver exited with status 3 before its first sample",
                     arena::db::TrialEnd::kFailed);
  }
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(path, ro);
  const FailureReport r = CampaignFailures(*store, id);
  EXPECT_EQ(r.failed_trials, 3);
  ASSERT_EQ(r.failures.size(), 2u);
  EXPECT_EQ(r.failures[0].count, 2);  // two cells, two durations: one reason
  EXPECT_EQ(r.failures[0].source, "cell");
  EXPECT_NE(r.failures[0].example.find("pushing for"), std::string::npos);
  EXPECT_EQ(r.failures[1].count, 1);
  EXPECT_EQ(r.failures[1].source, "driver");
  EXPECT_EQ(r.retried_attempts, 1);
  ASSERT_EQ(r.retries.size(), 1u);
  EXPECT_NE(r.retries[0].example.find("no command for 0.25 s"), std::string::npos);
  const std::string text = FormatFailures(r, "  ");
  EXPECT_NE(text.find("failed trials by reason (3)"), std::string::npos) << text;
  EXPECT_NE(text.find("2 x cell: refused by cell"), std::string::npos) << text;
  EXPECT_NE(text.find("1 x driver: "), std::string::npos) << text;
  EXPECT_NE(text.find("retried attempts by reason (1)"), std::string::npos) << text;
  const auto j = FailuresJson(r);
  EXPECT_EQ(j["failed"][0]["count"], 2);
  EXPECT_EQ(j["retried"][0]["source"], "cell");
}

// Pins: failures were grouped by reading their text (the word "driver" made
// a driver's failure); now by the typed kind the store keeps -- the rule
// that decided the transition (trial_transitions.rule), the trial's backend
// for who is to blame, the prediction's status -- with the text as detail.
// Two texts of one kind are one group; one text of two kinds is two.
TEST(FailureReasons, GroupedByTheTypedKindWithTheTextAsDetail) {
  TempDir dir;
  const std::string path = dir.File("k.db");
  std::int64_t id = 0;
  {
    auto store = db::Store::Open(path);
    store->UpsertCell("robot1", {"point"});
    id = store->CreateCampaign(MakeCampaign(), MakeTrials(4));
    // Trials 1 and 2: the exec: backend failed, in two different words (no
    // "driver" in either), and the retry rule gave up.
    for (const char* why : {"backend exec:./arm.py: arm stalled at joint 3",
                            "backend exec:./arm.py: gripper did not open"}) {
      auto t = store->ClaimNextTrial("robot1");
      store->RecordExecution(t->trial_id, t->attempt, "exec:./arm.py", "robot", "{}");
      store->RetryTrial(t->trial_id, t->attempt, why, 1, 0, "execute.cell_failure");
    }
    // Trial 3: the same words as trial 1, but the cell refused the trial.
    auto t = store->ClaimNextTrial("robot1");
    store->RecordExecution(t->trial_id, t->attempt, "exec:./arm.py", "robot", "{}");
    store->RetryTrial(t->trial_id, t->attempt, "backend exec:./arm.py: arm stalled at joint 3", 1,
                      0, "execute.refused_by_cell");
    // Trial 4: done, with a prediction whose solver failed.
    t = store->ClaimNextTrial("robot1");
    auto ingest = store->BeginIngest(t->trial_id, t->attempt, db::testing::SceneSites());
    for (int i = 0; i < 5; ++i) ingest->Add(db::testing::MakeSample(i));
    ingest->Finish(db::TrialEnd::kOk);
    store->BeginReset(t->trial_id, t->attempt);
    db::ResetReport reset;
    reset.ok = true;
    store->CompleteReset(t->trial_id, t->attempt, reset);
    db::Prediction p;
    p.model_key = "g8_k3_dt0.004_auto";
    p.status = db::PredictionStatus::kSolverFailure;
    p.detail_json = R"({"error": "step 12: LCP did not converge"})";
    store->RecordPrediction(t->trial_id, t->attempt, p);
    store->FinishTrial(t->trial_id, t->attempt);
  }
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(path, ro);
  const FailureReport r = CampaignFailures(*store, id);
  EXPECT_EQ(r.failed_trials, 3);
  ASSERT_EQ(r.failures.size(), 2u);
  EXPECT_EQ(r.failures[0].kind, "execute.cell_failure");
  EXPECT_EQ(r.failures[0].source, "driver");  // the backend is a robot driver: typed, not read
  EXPECT_EQ(r.failures[0].count, 2);
  EXPECT_EQ(r.failures[0].texts, 2);
  EXPECT_EQ(r.failures[1].kind, "execute.refused_by_cell");
  EXPECT_EQ(r.failures[1].count, 1);
  ASSERT_EQ(r.predictions.size(), 1u);
  EXPECT_EQ(r.predictions[0].kind, "solver_failure");
  EXPECT_EQ(r.predictions[0].example, "step 12: LCP did not converge");
  const std::string text = FormatFailures(r, "  ");
  EXPECT_NE(text.find("2 x driver, the cell's backend failed [execute.cell_failure]: backend "
                      "exec:./arm.py: arm stalled at joint 3"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("(e.g. trial 1; 2 different texts)"), std::string::npos) << text;
  EXPECT_NE(text.find("1 x driver, the cell refused the trial [execute.refused_by_cell]"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("1 x predictor, the prediction solver_failure [solver_failure]: step 12"),
            std::string::npos)
      << text;
  const auto j = FailuresJson(r);
  EXPECT_EQ(j["failed"][0]["kind"], "execute.cell_failure");
  EXPECT_EQ(j["failed"][0]["texts"], 2);
  EXPECT_EQ(KindOfRule("execute.cell_failure retry.attempts_exhausted", "model").source, "cell");
  EXPECT_EQ(KindOfRule("fail.unnamed", "model").kind, "");  // names no cause: by text
}

// Issue 26: two reasons with the same count were listed in the order their
// rows were written (predictions: whichever finished first), so the same
// campaign printed them in another order from run to run and a doc could not
// quote its summary. Pins: ties go to the reason met first in trial order.
TEST(FailureReasons, TiesInTrialOrderWhateverOrderTheRowsWereWritten) {
  TempDir dir;
  const std::string path = dir.File("ties.db");
  std::int64_t id = 0;
  {
    auto store = db::Store::Open(path);
    store->UpsertCell("c1", {"point"});
    id = store->CreateCampaign(MakeCampaign(), MakeTrials(2));
    std::vector<db::ClaimedTrial> trials;
    for (int k = 0; k < 2; ++k) {
      auto t = store->ClaimNextTrial("c1");
      auto ingest = store->BeginIngest(t->trial_id, t->attempt, db::testing::SceneSites());
      for (int i = 0; i < 5; ++i) ingest->Add(db::testing::MakeSample(i));
      ingest->Finish(db::TrialEnd::kOk);
      store->BeginReset(t->trial_id, t->attempt);
      db::ResetReport reset;
      reset.ok = true;
      store->CompleteReset(t->trial_id, t->attempt, reset);
      trials.push_back(*t);
    }
    // The later trial's prediction is written first.
    const std::pair<db::PredictionStatus, const char*> outcome[2] = {
        {db::PredictionStatus::kSolverFailure, "step 3: LCP did not converge"},
        {db::PredictionStatus::kDiverged, "diverged: the object turned 92 deg"}};
    for (int k : {1, 0}) {
      db::Prediction p;
      p.model_key = "g8_k3_dt0.004_auto";
      p.status = outcome[k].first;
      p.detail_json = nlohmann::json{{"error", outcome[k].second}}.dump();
      store->RecordPrediction(trials[k].trial_id, trials[k].attempt, p);
      store->FinishTrial(trials[k].trial_id, trials[k].attempt);
    }
  }
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(path, ro);
  const FailureReport r = CampaignFailures(*store, id);
  ASSERT_EQ(r.predictions.size(), 2u);
  EXPECT_EQ(r.predictions[0].kind, "solver_failure");
  EXPECT_EQ(r.predictions[1].kind, "diverged");
}

TEST(FailureReasons, KeyIgnoresCellIdsAndNumbersOnly) {
  EXPECT_EQ(ReasonKey("cell a1: 500 s at 1e-3 m/s", "a1"),
            ReasonKey("cell b7: 2.5 s at 4 m/s", "b7"));
  EXPECT_NE(ReasonKey("cell a1: timeout", "a1"), ReasonKey("cell a1: refused", "a1"));
  EXPECT_EQ(ReasonSource("exec driver: exited"), "driver");
  EXPECT_EQ(ReasonSource("refused by cell c1: x"), "cell");
  EXPECT_EQ(ReasonSource("service restarted"), "service");
}

// Pins: a finished campaign's rate decayed as the clock moved on (12,791/h,
// later 200/h); now it is the rate it ran at, whenever status is asked.
TEST(StatusRate, FrozenOnceTheCampaignIsFinished) {
  TempDir dir;
  double now = 10000;
  db::StoreOptions o;
  o.clock = [&] { return now; };
  auto store = db::Store::Open(dir.File("r.db"), o);
  store->UpsertCell("c", {"point"});
  store->CreateCampaign(MakeCampaign(), MakeTrials(4));
  for (int i = 0; i < 4; ++i) {
    auto t = store->ClaimNextTrial("c");
    now += 10;
    RunTrialToDone(*store, *t, 5);
  }
  store->CompleteFinishedCampaigns();
  const double rate = store->Status().campaigns.at(0).rate_per_hour;
  EXPECT_NEAR(rate, 4 * 3600.0 / 40, 1e-6);  // 4 trials from the first dispatch to the last finish
  now += 3600;
  EXPECT_NEAR(store->Status().campaigns.at(0).rate_per_hour, rate, 1e-9);
  EXPECT_FALSE(store->Status().campaigns.at(0).eta_s);
}

// Pins: cells of earlier runs piled up as `gone` for ever in the cell table.
TEST(StatusCells, GoneForADayFoldedIntoACount) {
  std::vector<db::CellInfo> cells(3);
  cells[0].id = "live";
  cells[0].last_seen = 1e6;
  cells[1].id = "old1";
  cells[1].state = db::CellState::kGone;
  cells[1].last_seen = 1e6 - 2 * 86400;
  cells[2].id = "recent-gone";
  cells[2].state = db::CellState::kGone;
  cells[2].last_seen = 1e6 - 60;
  std::vector<CellActivity> activity(3);
  activity[0].backend = "mujoco";
  activity[0].phase = "execute";
  activity[0].trial_id = 42;
  activity[0].in_phase_s = 3;
  const std::string folded = FormatCellTable(cells, activity, 1e6, false);
  EXPECT_EQ(folded.find("old1"), std::string::npos) << folded;
  EXPECT_NE(folded.find("recent-gone"), std::string::npos) << folded;
  EXPECT_NE(folded.find("1 cell gone for more than a day (arena status --all lists them)"),
            std::string::npos)
      << folded;
  EXPECT_NE(folded.find("mujoco"), std::string::npos) << folded;
  EXPECT_NE(folded.find("execute"), std::string::npos) << folded;
  EXPECT_NE(folded.find("42"), std::string::npos) << folded;
  const std::string all = FormatCellTable(cells, activity, 1e6, true);
  EXPECT_NE(all.find("old1"), std::string::npos) << all;
  EXPECT_EQ(all.find("more than a day"), std::string::npos) << all;
}

// Pins: `arena query` printed timestamps as 1.79581e+09.
TEST(QueryTable, TimestampsKeepTheirDigits) {
  TempDir dir;
  db::StoreOptions o;
  o.clock = [] { return 1795810000.125; };
  const std::string path = dir.File("q.db");
  db::Store::Open(path, o)->CreateCampaign(MakeCampaign(), MakeTrials(1));
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(path, ro);
  const std::string table =
      db::FormatTable(db::RunQuery(*store, "SELECT created_at, 0.000123456789 AS s FROM trials"));
  EXPECT_NE(table.find("1795810000.125"), std::string::npos) << table;
  EXPECT_EQ(table.find("e+09"), std::string::npos) << table;
  EXPECT_NE(table.find("0.000123457"), std::string::npos) << table;  // small ones as before
}

// Pins: the export manifest's `parameters` left out grip_force and
// finger_type, the variations written into the scene's own columns.
TEST(ExportManifest, ParametersNameEveryVariation) {
  TempDir dir;
  const std::string path = dir.File("e.db");
  {
    auto store = db::Store::Open(path);
    store->UpsertCell("c", {"point"});
    db::NewCampaign c = MakeCampaign();
    c.spec_json =
        R"({"name": "c", "variations": {"grip_force": {"choices": [5, 6]},
            "finger_type": "point", "pivot_offset": 0.0}})";
    auto trials = MakeTrials(2);
    for (auto& t : trials) t.params_json = R"({"pivot_offset": 0.0})";
    store->CreateCampaign(c, trials);
    for (int i = 0; i < 2; ++i) RunTrialToDone(*store, *store->ClaimNextTrial("c"), 5);
  }
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(path, ro);
  db::ExportOptions eo;
  eo.campaign_id = 1;
  eo.format = db::ExportFormat::kCsv;
  eo.out_dir = dir.File("out");
  eo.scene_facts = [](const std::string&) { return db::testing::SceneFactsFor(); };
  db::ExportCampaign(*store, eo);
  std::ifstream in(eo.out_dir + "/manifest.json");
  const auto manifest = nlohmann::json::parse(in);
  std::vector<std::string> parameters = manifest["parameters"];
  for (const char* name : {"grip_force", "finger_type", "pivot_offset"})
    EXPECT_NE(std::find(parameters.begin(), parameters.end(), name), parameters.end())
        << name << " missing from " << manifest["parameters"].dump();
}

// Pins: map plots drew conditions that share a point side by side with no
// label saying which is which.
TEST(MapPlot, ConditionsSharingAPointAreLabelled) {
  MapData m;
  m.x_label = "grip_force (N)";
  m.y_label = "pivot_offset (m)";
  m.metric_label = "rotation (rad)";
  for (int k = 0; k < 3; ++k) {
    MapPoint p;
    p.condition = k;
    p.x = 8;
    p.y = k < 2 ? 0.0 : 0.01;
    p.value = 0.1 * k;
    p.label = std::string("finger_type=") + (k == 0 ? "point" : k == 1 ? "line" : "patch");
    m.points.push_back(p);
  }
  const std::string svg = RenderMapSvg(m);
  EXPECT_NE(svg.find(">finger_type=point</text>"), std::string::npos) << svg;
  EXPECT_NE(svg.find(">finger_type=line</text>"), std::string::npos) << svg;
  // A condition alone at its point needs no label.
  EXPECT_EQ(svg.find(">finger_type=patch</text>"), std::string::npos) << svg;
}

std::string Smoke(const std::string& variation, const std::string& value) {
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/smoke.json");
  auto doc = nlohmann::json::parse(in);
  doc["variations"][variation] = nlohmann::json::parse(value);
  return doc.dump();
}

std::string FieldOf(const std::string& text) {
  try {
    orchestrator::ParseCampaign(text);
  } catch (const orchestrator::CampaignError& e) {
    return e.field() + ": " + e.reason();
  }
  return "accepted";
}

// Pins: `push_speed: 10` (meant mm/s) was blamed on model.dt.
TEST(Plausibility, PushSpeedSlipBlamesPushSpeed) {
  const std::string why = FieldOf(Smoke("push_speed", "10"));
  EXPECT_EQ(why.rfind("variations.push_speed:", 0), 0u) << why;
  EXPECT_NE(why.find("10 mm/s is 0.01"), std::string::npos) << why;
}

// Pins: `push_distance: 5` (meant mm) was accepted as a 250 s push that
// every trial then failed.
TEST(Plausibility, PushDistanceSlipRefused) {
  const std::string why = FieldOf(Smoke("push_distance", "5"));
  EXPECT_EQ(why.rfind("variations.push_distance:", 0), 0u) << why;
  EXPECT_NE(why.find("5 mm is 0.005"), std::string::npos) << why;
  EXPECT_EQ(FieldOf(Smoke("push_distance", "1.5")).rfind("variations.push_distance:", 0), 0u);
  EXPECT_EQ(FieldOf(Smoke("push_distance", "0.02")), "accepted");
}

// Pins: a grip in kilonewtons on a 0.2 kg object was accepted.
TEST(Plausibility, GripInKilonewtonsRefused) {
  const std::string why = FieldOf(Smoke("grip_force", R"({"min": 8, "max": 2000, "levels": 2})"));
  EXPECT_EQ(why.rfind("variations.grip_force:", 0), 0u) << why;
  EXPECT_NE(why.find("times the weight"), std::string::npos) << why;
  EXPECT_EQ(FieldOf(Smoke("grip_force", "40")), "accepted");
}

// Pins: a push shorter than one predictor step was blamed on prediction.dt
// ("model.dt: must be <= duration"), not on the push written.
TEST(Plausibility, PushShorterThanAStepBlamesThePush) {
  // 0.05 mm at the smoke campaign's 20 mm/s: 2.5 ms, under its 4 ms step.
  const std::string why = FieldOf(Smoke("push_distance", "0.00005"));
  EXPECT_EQ(why.rfind("variations.push_distance:", 0), 0u) << why;
  EXPECT_NE(why.find("shorter than one model step (4 ms)"), std::string::npos) << why;
}

TEST(Plausibility, SpeedLimitIsTheCampaignProfiles) {
  auto doc = nlohmann::json::parse(Smoke("push_speed", "0.8"));
  doc["variations"]["push_distance"] = 0.02;
  EXPECT_EQ(FieldOf(doc.dump()).rfind("variations.push_speed:", 0), 0u);
  doc["defects"]["max_pusher_speed"] = 1.0;
  EXPECT_EQ(FieldOf(doc.dump()), "accepted");
}

// Pins: "8 of 9 trial attempts missed control deadlines: 0 of 3384 samples
// held" read as a contradiction: the attempts missed by a loop p99 above the
// period (late commands, none held while the cell waited) were not counted
// apart. The line now says how many were late and how many samples held.
TEST(Deadlines, HeldAndLateAttemptsCountedApart) {
  DeadlineReport r;
  r.runs = 9;
  r.samples = 3384;
  r.held = 0;
  r.runs_missing = 8;
  r.runs_late = 8;
  r.p50_ms = 0.268;
  r.worst_p99_ms = 6.91;
  const std::string line = FormatDeadlines(r, "  ");
  EXPECT_EQ(line,
            "  closed loop: 8 of 9 trial attempts missed control deadlines: 0 of 3384 samples "
            "held (0-0 per attempt); 8 with loop latency p99 above the 4 ms period (p99 up to "
            "6.91 ms), loop latency p50 0.268 ms\n");
  EXPECT_EQ(DeadlinesJson(r)["attempts_late"], 8);
  EXPECT_EQ(FormatDeadlines(DeadlineReport{}, ""), "");  // open loop: nothing
}

}  // namespace
}  // namespace arena::cli
