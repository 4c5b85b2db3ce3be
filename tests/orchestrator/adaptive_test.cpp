// The adaptive samplers' pure rules and their store round trip: boundary
// points by the nearest-neighbour margin rule (bisection in 1-D), replicates
// by confidence interval, campaign parsing of "sampler": {"adaptive": ...},
// and PlanAdaptiveRound's conditional write.
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <csignal>
#include <filesystem>
#include <functional>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/adaptive.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/outcome.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/orchestrator/submit.hpp"

namespace arena::orchestrator {
namespace {

// Runs the boundary rule against a known classifier until it stops;
// returns the labelled points.
std::vector<LabelledPoint> RunBoundary(int dims, double resolution, int batch,
                                       const std::function<bool(const std::vector<double>&)>& truth,
                                       int* rounds) {
  std::vector<LabelledPoint> labelled;
  std::int64_t id = 0;
  for (const auto& u : CoarseGrid(dims, DefaultCoarseLevels(dims)))
    labelled.push_back({u, truth(u), ++id});
  *rounds = 0;
  for (;;) {
    const auto proposals = ProposeBoundaryPoints(labelled, {}, dims, resolution, batch);
    if (proposals.empty()) break;
    ++*rounds;
    for (const auto& p : proposals) labelled.push_back({p.u, truth(p.u), ++id});
    if (*rounds > 500) ADD_FAILURE() << "no convergence";
    if (*rounds > 500) break;
  }
  return labelled;
}

// The coarse batch is no finer than 8 x resolution (>= 3 levels) and no
// finer than the per-dimension default.
TEST(BoundaryRule, CoarseLevelsFollowTheResolution) {
  EXPECT_EQ(DefaultCoarseLevels(2, 0.25), 3);
  EXPECT_EQ(DefaultCoarseLevels(2, 0.125), 3);
  EXPECT_EQ(DefaultCoarseLevels(2, 0.0625), 3);
  EXPECT_EQ(DefaultCoarseLevels(2, 0.05), 4);
  EXPECT_EQ(DefaultCoarseLevels(2, 0.01), 4);
  EXPECT_EQ(DefaultCoarseLevels(1, 0.03), 5);
  EXPECT_EQ(DefaultCoarseLevels(1, 0.05), 4);
  EXPECT_EQ(DefaultCoarseLevels(3, 0.01), 3);
}

TEST(BoundaryRule, OneDimensionIsBisectionToTheResolution) {
  // Class changes at x = 0.3141: coarse points 0, .25, .5, .75, 1, then
  // bisection of [0.25, 0.5] until the bracket is within the resolution.
  const double edge = 0.3141, resolution = 0.01;
  int rounds = 0;
  const auto points = RunBoundary(
      1, resolution, 1, [&](const auto& u) { return u[0] > edge; }, &rounds);
  double below = 0, above = 1;
  for (const auto& p : points) {
    if (p.positive) above = std::min(above, p.u[0]);
    if (!p.positive) below = std::max(below, p.u[0]);
  }
  EXPECT_LE(below, edge);
  EXPECT_GT(above, edge);
  // Stop rule: the midpoint's distance to the evidence is <= resolution.
  EXPECT_LE((above - below) / 2, resolution + 1e-9);
  // log2(0.25 / 0.02) = 3.6: four bisections, each one trial (a grid would need 101).
  EXPECT_LE(rounds, 5);
  EXPECT_EQ(points.size(), 5u + static_cast<size_t>(rounds));
}

TEST(BoundaryRule, NoClassChangeProposesNothing) {
  std::vector<LabelledPoint> same;
  for (const auto& u : CoarseGrid(2, 4)) same.push_back({u, false, 1});
  double uncertainty = -1;
  EXPECT_TRUE(ProposeBoundaryPoints(same, {}, 2, 0.05, 4, &uncertainty).empty());
  EXPECT_EQ(uncertainty, 0);
}

TEST(BoundaryRule, TwoDimensionsTraceACurvedBoundaryWithFewPoints) {
  // A quarter circle of radius 0.6 about the origin: positive outside.
  auto truth = [](const std::vector<double>& u) { return std::hypot(u[0], u[1]) > 0.6; };
  int rounds = 0;
  const double resolution = 0.04;
  const auto points = RunBoundary(2, resolution, 4, truth, &rounds);
  // Every lattice point the 1-NN classifier of the samples gets wrong lies
  // near the true boundary (within ~2 resolutions).
  double worst = 0;
  for (int i = 0; i <= 100; ++i) {
    for (int j = 0; j <= 100; ++j) {
      const std::vector<double> u = {i / 100.0, j / 100.0};
      double best = 1e9;
      bool cls = false;
      for (const auto& p : points) {
        const double d = std::hypot(p.u[0] - u[0], p.u[1] - u[1]);
        if (d < best) {
          best = d;
          cls = p.positive;
        }
      }
      if (cls != truth(u)) worst = std::max(worst, std::abs(std::hypot(u[0], u[1]) - 0.6));
    }
  }
  EXPECT_LE(worst, 2 * resolution);
  // A grid of that resolution has 26 x 26 = 676 points.
  EXPECT_LT(points.size(), 676u / 4);
}

TEST(BoundaryRule, ABatchSpreadsAlongTheBoundaryAndIsDeterministic) {
  std::vector<LabelledPoint> labelled;
  std::int64_t id = 0;
  for (const auto& u : CoarseGrid(2, 4)) labelled.push_back({u, u[0] > 0.5, ++id});
  const auto a = ProposeBoundaryPoints(labelled, {}, 2, 0.02, 4);
  const auto b = ProposeBoundaryPoints(labelled, {}, 2, 0.02, 4);
  ASSERT_EQ(a.size(), 4u);
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].u, b[i].u);
  for (size_t i = 0; i < a.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      EXPECT_GT(std::hypot(a[i].u[0] - a[j].u[0], a[i].u[1] - a[j].u[1]), 0.02);
  // All on the estimated boundary x = 0.5 (between the columns 1/3 and 2/3).
  for (const auto& p : a) EXPECT_NEAR(p.u[0], 0.5, 0.03);
}

TEST(ReplicateRule, StudentIntervalMatchesTables) {
  // Half-width = t * s / sqrt(n); values {0, 1} have s = 0.7071, n = 2.
  EXPECT_NEAR(ConfidenceHalfWidth({0, 1}, 0.95), 12.706 * 0.70711 / std::sqrt(2.0), 1e-3);
  // n = 5, t(0.975, 4) = 2.776.
  const std::vector<double> v = {1, 2, 3, 4, 5};
  EXPECT_NEAR(ConfidenceHalfWidth(v, 0.95), 2.776 * 1.5811 / std::sqrt(5.0), 2e-3);
  // n = 31, t(0.975, 30) = 2.042.
  std::vector<double> w;
  for (int i = 0; i < 31; ++i) w.push_back(i % 2);
  double mean = 15.0 / 31, ss = 0;
  for (double x : w) ss += (x - mean) * (x - mean);
  EXPECT_NEAR(ConfidenceHalfWidth(w, 0.95), 2.042 * std::sqrt(ss / 30) / std::sqrt(31.0), 1e-3);
  EXPECT_TRUE(std::isinf(ConfidenceHalfWidth({1.0}, 0.95)));
}

TEST(ReplicateRule, OnlyWideConditionsGetMoreAndTheWidestFirst) {
  AdaptiveSpec spec;
  spec.kind = AdaptiveKind::kReplicates;
  spec.ci_position = 1e-3;
  spec.max_replicates = 5;
  ConditionOutcomes tight{0, {{0, 0, 0}, {1e-5, 0, 0}, {2e-5, 0, 0}}, {0, 0, 0}, 3};
  ConditionOutcomes wide{1, {{0, 0, 0}, {3e-3, 0, 0}, {6e-3, 0, 0}}, {0, 0, 0}, 3};
  ConditionOutcomes wider{2, {{0, 0, 0}, {9e-3, 0, 0}, {1e-2, 0, 0}}, {0, 0, 0}, 3};
  ConditionOutcomes capped{3, {{0, 0, 0}, {9e-3, 0, 0}, {1e-2, 0, 0}}, {0, 0, 0}, 5};
  const auto p = ProposeReplicates({tight, wide, wider, capped}, spec, 4);
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p[0].condition, 2);
  EXPECT_EQ(p[1].condition, 1);
  EXPECT_EQ(ProposeReplicates({tight, wide, wider}, spec, 1).size(), 1u);
}

TEST(OutcomeFunctions, ClassifyFromTrajectory) {
  std::vector<mechanics::TrajectorySample> s(10);
  for (size_t i = 0; i < s.size(); ++i) {
    s[i].position = Eigen::Vector3d(0, 0, 0.001 * static_cast<double>(i));
    s[i].orientation = Eigen::AngleAxisd(0.02 * static_cast<double>(i), Eigen::Vector3d::UnitX());
    s[i].contacts.resize(3);
    s[i].contacts[0].mode = i < 3 ? mechanics::ContactMode::kStick : mechanics::ContactMode::kSlide;
    s[i].contacts[1].mode = mechanics::ContactMode::kStick;
    s[i].contacts[2].mode = mechanics::ContactMode::kSlide;  // the pusher: not counted
  }
  const TrialOutcome o = ComputeOutcome(s, 2);
  EXPECT_NEAR(o.rotation, 0.18, 1e-9);
  EXPECT_NEAR(o.displacement, 0.009, 1e-12);
  EXPECT_NEAR(o.finger_slide_fraction, 7.0 / 20.0, 1e-12);
  EXPECT_TRUE(Classify(OutcomeKind::kPivoted, 0.1, o));
  EXPECT_FALSE(Classify(OutcomeKind::kPivoted, 0.2, o));
  EXPECT_FALSE(Classify(OutcomeKind::kFingerSlip, 0.5, o));
  EXPECT_TRUE(Classify(OutcomeKind::kGraspKept, 0.01, o));
  s.back().contacts[1].mode = mechanics::ContactMode::kSeparate;
  EXPECT_FALSE(Classify(OutcomeKind::kGraspKept, 0.01, ComputeOutcome(s, 2)));
}

std::string Canonical() {
  return std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json";
}

std::string BoundaryCampaign(const std::string& sampler_extra = "") {
  return R"({"name": "b", "seed": 3, "scene": ")" + Canonical() + R"(",
    "variations": {"grip_force": {"min": 2, "max": 20}, "pivot_offset": {"min": 0, "max": 0.01}},
    "sampler": {"adaptive": "boundary", "outcome": "pivoted", "resolution": 0.1,
                "batch": 2)" +
         sampler_extra + "}}";
}

TEST(AdaptiveCampaign, ParsesBoundaryAndReplicates) {
  const Campaign b = ParseCampaign(BoundaryCampaign());
  ASSERT_TRUE(b.adaptive);
  EXPECT_EQ(b.adaptive->kind, AdaptiveKind::kBoundary);
  EXPECT_EQ(b.adaptive->outcome, OutcomeKind::kPivoted);
  EXPECT_DOUBLE_EQ(b.adaptive->threshold, 0.05);
  EXPECT_EQ(b.conditions, 0);
  EXPECT_EQ(SampledVariations(b), (std::vector<std::string>{"grip_force", "pivot_offset"}));
  const PlannedTrial t = PlanTrialAt(b, {0.5, 1.0}, 0, 0, 0);
  EXPECT_DOUBLE_EQ(t.scene.grip_force, 11);
  EXPECT_THROW(PlanTrialAt(b, {0.5}, 0, 0, 0), std::invalid_argument);
  EXPECT_THROW(PlanTrialAt(b, {0.5, 1.5}, 0, 0, 0), std::invalid_argument);

  const Campaign r = ParseCampaign(R"({"name": "r", "seed": 3, "scene": ")" + Canonical() + R"(",
    "variations": {"grip_force": {"min": 2, "max": 20, "levels": 3}},
    "sampler": {"adaptive": "replicates", "base": "grid", "min_replicates": 3,
                "max_replicates": 9, "ci_position": 0.0002}})");
  ASSERT_TRUE(r.adaptive);
  EXPECT_EQ(r.conditions, 3);
  EXPECT_EQ(r.replicates, 3);
  EXPECT_EQ(PlanReplicate(r, 2, 7, 0).scene.grip_force, 20);
}

TEST(AdaptiveCampaign, RefusesBadSamplerObjects) {
  auto field_of = [](const std::string& text) {
    try {
      ParseCampaign(text);
    } catch (const CampaignError& e) {
      return e.field();
    }
    return std::string("(accepted)");
  };
  EXPECT_EQ(field_of(BoundaryCampaign(R"(, "outcome": "wobbly")")), "sampler.outcome");
  EXPECT_EQ(field_of(BoundaryCampaign(R"(, "resolution": 0)")), "sampler.resolution");
  EXPECT_EQ(field_of(BoundaryCampaign(R"(, "frobnicate": 1)")), "sampler.frobnicate");
  EXPECT_EQ(field_of(BoundaryCampaign(R"(, "batch": 0)")), "sampler.batch");
  EXPECT_EQ(field_of(R"({"name": "b", "seed": 3, "scene": ")" + Canonical() +
                     R"(", "variations": {"grip_force": {"min": 2, "max": 20}},
                     "replicates": 3, "sampler": {"adaptive": "boundary", "outcome": "pivoted"}})"),
            "replicates");
  EXPECT_EQ(field_of(R"({"name": "b", "seed": 3, "scene": ")" + Canonical() +
                     R"(", "variations": {"finger_type": {"choices": ["point", "line"]}},
                     "sampler": {"adaptive": "boundary", "outcome": "pivoted"}})"),
            "variations.finger_type");
  EXPECT_EQ(field_of(R"({"name": "b", "seed": 3, "scene": ")" + Canonical() +
                     R"(", "sampler": {"adaptive": "annealing"}})"),
            "sampler.adaptive");
}

class StoreFile : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = std::filesystem::temp_directory_path() /
            ("arena-adaptive-" + std::to_string(getpid()) + "-" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name() + ".db");
    std::filesystem::remove(path_);
  }
  void TearDown() override {
    for (const char* suffix : {"", "-wal", "-shm"})
      std::filesystem::remove(path_.string() + suffix);
  }
  std::filesystem::path path_;
};

TEST_F(StoreFile, SubmitPlansTheCoarseRoundWithADecisionEach) {
  auto store = db::Store::Open(path_.string());
  const Campaign c = ParseCampaign(BoundaryCampaign());
  const std::int64_t id = SubmitCampaign(*store, c);
  const auto trials = store->ListTrials(id);
  ASSERT_EQ(trials.size(), 9u);  // 3 x 3 coarse grid (resolution 0.1: DefaultCoarseLevels)
  const auto decisions = store->ListDecisions(id);
  ASSERT_EQ(decisions.size(), 9u);
  EXPECT_EQ(*decisions[0].trial_id, trials[0].id);
  EXPECT_NE(decisions[0].reason.find("coarse grid point 1 of 9"), std::string::npos);
  const auto campaign = store->GetCampaign(id);
  EXPECT_TRUE(campaign.sampler_open);
  // Not done although... its trials are not finished; and while they run
  // the next round is not decided.
  EXPECT_TRUE(store->CompleteFinishedCampaigns().empty());
  EXPECT_EQ(AdvanceCampaign(*store, id, c, 4), 0);
  const auto progress = ReadAdaptiveProgress(campaign);
  ASSERT_TRUE(progress);
  EXPECT_EQ(progress->sampler, "boundary");
  EXPECT_NE(progress->refining.find("grip_force x pivot_offset"), std::string::npos);
}

TEST_F(StoreFile, PlanAdaptiveRoundWritesOnlyFromTheStateItRead) {
  auto store = db::Store::Open(path_.string());
  db::NewCampaign nc;
  nc.name = "x";
  nc.spec_json = "{}";
  nc.sampler_open = true;
  const std::int64_t id = store->CreateCampaign(nc, std::vector<db::PlannedTrial>{});
  db::AdaptiveRound round;
  round.round = 0;
  round.open = false;
  round.stop_reason = "nothing to do";
  round.sampler_state_json = R"({"round": 0})";
  EXPECT_FALSE(store->PlanAdaptiveRound(id, R"({"round": 7})", round));  // stale state
  EXPECT_TRUE(store->GetCampaign(id).sampler_open);
  EXPECT_TRUE(store->PlanAdaptiveRound(id, "{}", round));
  EXPECT_FALSE(store->GetCampaign(id).sampler_open);
  EXPECT_FALSE(store->PlanAdaptiveRound(id, R"({"round": 0})", round));  // closed
  const auto d = store->ListDecisions(id);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_FALSE(d[0].trial_id);
  EXPECT_EQ(d[0].reason, "nothing to do");
  EXPECT_EQ(store->CompleteFinishedCampaigns(), std::vector<std::int64_t>{id});
  db::AdaptiveRound bad;
  bad.trials.resize(1);
  EXPECT_THROW(store->PlanAdaptiveRound(id, "{}", bad), db::StoreError);  // no reason per trial
}

// A pipelined round is written while the round before it runs, but only
// when the rounds it was based on are finished; and a later round's trials
// get their parameter columns in the result views like round 0's, also for a
// name round 0 did not have.
TEST_F(StoreFile, LaterRoundsArePipelinedAndRegisterTheirParameters) {
  auto store = db::Store::Open(path_.string());
  const Campaign c = ParseCampaign(BoundaryCampaign());
  const std::int64_t id = SubmitCampaign(*store, c);
  const std::string state = store->GetCampaign(id).sampler_state_json;
  db::AdaptiveRound round;
  round.round = 1;
  round.sampler_state_json = R"({"round": 1})";
  PlannedTrial t = PlanTrialAt(c, {0.25, 0.75}, 9, 9, 0);
  nlohmann::json params = nlohmann::json::parse(t.parameters_json);
  params["extra_knob"] = 0.125;
  db::PlannedTrial p;
  p.seed = t.seed;
  p.scene_json = mechanics::SceneToJson(t.scene);
  p.facts = SceneFactsOf(t.scene);
  p.params_json = params.dump();
  round.trials = {p};
  round.reasons = {"test"};
  round.bases_json = {"{}"};
  round.known_through_round = 0;  // round 0 is still planned: not final
  EXPECT_FALSE(store->PlanAdaptiveRound(id, state, round));
  round.known_through_round.reset();  // every trial: not finished either
  EXPECT_FALSE(store->PlanAdaptiveRound(id, state, round));
  round.known_through_round = -1;  // based on nothing finished (round 0 pending)
  ASSERT_TRUE(store->PlanAdaptiveRound(id, state, round));
  ASSERT_EQ(store->ListTrials(id).size(), 10u);
  EXPECT_EQ(store->ListDecisions(id).back().round, 1);

  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(path_.c_str(), &raw), SQLITE_OK);
  auto column = [&](const std::string& sql) {
    sqlite3_stmt* s = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(raw, sql.c_str(), -1, &s, nullptr), SQLITE_OK) << sql;
    std::vector<std::string> out;
    while (s && sqlite3_step(s) == SQLITE_ROW)
      out.push_back(sqlite3_column_type(s, 0) == SQLITE_NULL
                        ? "NULL"
                        : reinterpret_cast<const char*>(sqlite3_column_text(s, 0)));
    sqlite3_finalize(s);
    return out;
  };
  const auto knob = column("SELECT extra_knob FROM trial_results ORDER BY trial_id");
  ASSERT_EQ(knob.size(), 10u);
  EXPECT_EQ(knob[0], "NULL");  // round 0 did not vary it
  EXPECT_EQ(knob[9], "0.125");
  const auto offset = column("SELECT pivot_offset FROM trial_results ORDER BY trial_id");
  ASSERT_EQ(offset.size(), 10u);
  EXPECT_NE(offset[9], "NULL");
  EXPECT_NEAR(std::stod(offset[9]), params["pivot_offset"].get<double>(), 1e-12);
  sqlite3_close(raw);
}

// Submit writes an adaptive campaign and its round 0 in one transaction: a
// fault after the campaign row was written and before its round (an
// interrupt, a round the store refuses, the process killed there) leaves
// nothing; with two transactions the campaign would stay without trials.
// Pipelined rounds are the default for new campaigns, and the value is stored
// with the campaign at submit: a campaign stored without the key (submitted
// before the default changed) stays synchronous, so a service upgrade never
// changes a running campaign's sequence.
TEST_F(StoreFile, SubmitStoresThePipelineChoiceWithTheCampaign) {
  auto store = db::Store::Open(path_.string());
  const std::int64_t by_default = SubmitCampaign(*store, ParseCampaign(BoundaryCampaign()));
  const std::int64_t off =
      SubmitCampaign(*store, ParseCampaign(BoundaryCampaign(R"(, "pipeline": false)")));
  auto stored = [&](std::int64_t id) {
    return nlohmann::json::parse(store->GetCampaign(id).spec_json)["sampler"];
  };
  EXPECT_EQ(stored(by_default)["pipeline"], true);
  EXPECT_EQ(stored(off)["pipeline"], false);
  EXPECT_TRUE(ParseCampaign(store->GetCampaign(by_default).spec_json).adaptive->pipeline);
  EXPECT_FALSE(ParseCampaign(store->GetCampaign(off).spec_json).adaptive->pipeline);
  EXPECT_FALSE(ParseCampaign(BoundaryCampaign()).adaptive->pipeline)
      << "a stored campaign without the key was submitted synchronous";
}

TEST_F(StoreFile, AdaptiveSubmitIsOneTransaction) {
  const Campaign c = ParseCampaign(BoundaryCampaign());
  auto nothing_stored = [&] {
    auto store = db::Store::Open(path_.string());
    EXPECT_TRUE(store->ListCampaigns().empty());
    EXPECT_TRUE(store->ListDecisions(1).empty());
    EXPECT_TRUE(store->ListTrials(1).empty());
  };
  {
    // Interrupted after round 0 was decided (the campaign row is written).
    auto store = db::Store::Open(path_.string());
    int asked = 0;
    EXPECT_THROW(SubmitCampaign(*store, c, [&] { return ++asked > 0; }), SubmitInterrupted);
    EXPECT_EQ(asked, 1);
  }
  nothing_stored();
  {
    // The round's write fails (a trial's scene the store refuses).
    auto store = db::Store::Open(path_.string());
    db::NewCampaign row;
    row.name = "b";
    row.spec_json = "{}";
    row.sampler_open = true;
    EXPECT_THROW(store->CreateAdaptiveCampaign(row,
                                               [](std::int64_t) {
                                                 db::AdaptiveRound r;
                                                 r.trials.resize(1);
                                                 r.trials[0].scene_json = "not json";
                                                 r.reasons = {"x"};
                                                 r.bases_json = {"{}"};
                                                 return r;
                                               }),
                 db::StoreError);
  }
  nothing_stored();
  {
    // Killed between the campaign row and its round: a real SIGKILL.
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      auto store = db::Store::Open(path_.string());
      db::NewCampaign row;
      row.name = "b";
      row.spec_json = "{}";
      row.sampler_open = true;
      store->CreateAdaptiveCampaign(row, [](std::int64_t) -> db::AdaptiveRound {
        raise(SIGKILL);
        _exit(3);  // not reached
      });
      _exit(4);  // not reached
    }
    int status = 0;
    ASSERT_EQ(waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  }
  nothing_stored();
  // And without a fault: both, the campaign never seen without its round.
  auto store = db::Store::Open(path_.string());
  const std::int64_t id = SubmitCampaign(*store, c);
  EXPECT_EQ(store->ListTrials(id).size(), 9u);
  EXPECT_EQ(store->ListDecisions(id).size(), 9u);
  EXPECT_TRUE(store->CheckInvariants().empty());
}

// finger_slip from the per-contact outcomes the store computed at ingest
// (issue 15): they agree with the stream-derived outcome, and the sampler
// reads them -- a stored slide fraction changed behind the stream's back
// changes its decision (which the stream alone could not).
db::Sample StickSample(int i) {
  db::Sample s;
  s.t = i / 250.0;
  s.object_pose = {0, 0, 0.0001 * i, 1, 0, 0, 0};
  s.pusher_pose = {0, 0, -0.05 + 0.0001 * i, 1, 0, 0, 0};
  for (int c = 0; c < 3; ++c) {
    db::ContactWrench w;
    w.force = {c == 0 ? 5.0 : c == 1 ? -5.0 : 0.0, 0, c == 2 ? 2.0 : 1.0};
    w.mode = db::ContactMode::kStick;
    s.contacts.push_back(w);
  }
  return s;
}

void RunAllToDone(db::Store& store) {
  while (auto t = store.ClaimNextTrial("c")) {
    auto ingest =
        store.BeginIngest(t->trial_id, t->attempt, SceneFactsOfJson(t->scene_json).contacts);
    for (int i = 0; i < 20; ++i) ingest->Add(StickSample(i));
    ingest->Finish();
    store.BeginReset(t->trial_id, t->attempt);
    db::ResetReport r;
    r.ok = true;
    r.observed_pose = {0, 0, 0, 1, 0, 0, 0};
    store.CompleteReset(t->trial_id, t->attempt, r);
    db::Prediction p;
    p.model_key = "g8";
    p.final_position_error = 0.001;
    p.final_angle_error = 0.01;
    p.force_error = 0.2;
    p.mode_agreement = 1;
    p.wall_s = 0.001;
    store.RecordPrediction(t->trial_id, t->attempt, p);
    store.FinishTrial(t->trial_id, t->attempt);
  }
}

TEST_F(StoreFile, BoundaryReadsFingerSlipFromTheStoredContactOutcomes) {
  const Campaign c = ParseCampaign(R"({"name": "s", "seed": 3, "scene": ")" + Canonical() + R"(",
    "variations": {"grip_force": {"min": 2, "max": 20}},
    "sampler": {"adaptive": "boundary", "outcome": "finger_slip", "resolution": 0.05,
                "batch": 2}})");
  std::int64_t id = 0;
  std::vector<db::Trial> trials;
  {
    auto store = db::Store::Open(path_.string());
    store->UpsertCell("c", {"point", "line", "patch"});
    id = SubmitCampaign(*store, c);
    RunAllToDone(*store);
    trials = store->ListTrials(id);
    ASSERT_GE(trials.size(), 3u);
    // Stored and stream-derived agree (here: all stick, no rotation).
    const auto stored = store->ReadTrialOutcomes(id);
    ASSERT_EQ(stored.size(), trials.size());
    for (const auto& t : trials) {
      const auto from_store = FromStoredOutcome(stored.at(t.id));
      ASSERT_TRUE(from_store);
      const auto from_stream = ComputeOutcome(store->ReadGroundTruth(t.id).samples, 2);
      EXPECT_DOUBLE_EQ(from_store->finger_slide_fraction, from_stream.finger_slide_fraction);
      EXPECT_NEAR(from_store->rotation, from_stream.rotation, 1e-12);
      EXPECT_NEAR(from_store->displacement, from_stream.displacement, 1e-12);
    }
  }
  // Control: the same store untouched -- every finger stuck, the sampler stops.
  const std::string control = path_.string() + ".control";
  std::filesystem::copy_file(path_, control, std::filesystem::copy_options::overwrite_existing);
  {
    auto store = db::Store::Open(control);
    EXPECT_EQ(AdvanceCampaign(*store, id, c, 2), 0);
    EXPECT_FALSE(store->GetCampaign(id).sampler_open);
    EXPECT_NE(store->ListDecisions(id).back().reason.find("no class change"), std::string::npos);
  }
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(control + suffix);

  // The fingers of the trials below 11 N slid, says the stored outcome (the
  // samples still say stick).
  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(path_.c_str(), &raw), SQLITE_OK);
  const std::string sql =
      "UPDATE contact_outcomes SET slide_fraction = 1, stick_fraction = 0 WHERE role = 'finger'"
      " AND trial_id IN (SELECT id FROM trials WHERE grip_force < 11 AND campaign_id = " +
      std::to_string(id) + ")";
  ASSERT_EQ(sqlite3_exec(raw, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK);
  EXPECT_GT(sqlite3_changes(raw), 0);
  sqlite3_close(raw);

  auto store = db::Store::Open(path_.string());
  // (All-stick samples alone: no class change, the sampler would stop.)
  ASSERT_GT(AdvanceCampaign(*store, id, c, 2), 0);
  const auto state = nlohmann::json::parse(store->GetCampaign(id).sampler_state_json);
  EXPECT_GT(state["positives"].get<int>(), 0);
  EXPECT_LT(state["positives"].get<int>(), static_cast<int>(trials.size()));
  const auto decisions = store->ListDecisions(id);
  EXPECT_NE(decisions.back().reason.find("(slide)"), std::string::npos) << decisions.back().reason;
}

}  // namespace
}  // namespace arena::orchestrator
