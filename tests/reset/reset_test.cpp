// Reset planning and the simulated reset executor.
#include <gtest/gtest.h>

#include "arena/reset/reset.hpp"
#include "arena/reset/rng.hpp"

namespace arena::reset {
namespace {

Pose At(double x, double y, double z, double yaw = 0) {
  Pose p;
  p.position = Eigen::Vector3d(x, y, z);
  p.orientation = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ());
  return p;
}

std::vector<PrimitiveKind> Kinds(const std::vector<Primitive>& plan) {
  std::vector<PrimitiveKind> k;
  for (const auto& p : plan) k.push_back(p.kind);
  return k;
}

TEST(ResetPlan, NothingToDoWithinTolerance) {
  ResetParams params;
  EXPECT_TRUE(PlanReset(At(0.0005, 0, 0), At(0, 0, 0), false, params).empty());
}

TEST(ResetPlan, TranslationRotationAndPusherSwap) {
  ResetParams params;
  using K = PrimitiveKind;
  EXPECT_EQ(Kinds(PlanReset(At(0.01, 0, 0), At(0, 0, 0), false, params)),
            (std::vector<K>{K::kRelease, K::kTranslate, K::kRegrasp}));
  EXPECT_EQ(Kinds(PlanReset(At(0, 0, 0, 0.3), At(0, 0, 0), false, params)),
            (std::vector<K>{K::kRelease, K::kRotate, K::kRegrasp}));
  const auto plan = PlanReset(At(0.02, 0, 0, 0.3), At(0, 0, 0), true, params);
  EXPECT_EQ(Kinds(plan),
            (std::vector<K>{K::kSwapPusher, K::kRelease, K::kRotate, K::kTranslate, K::kRegrasp}));
  // Durations follow from distances and speeds: 0.02 m at 0.05 m/s + a grasp.
  EXPECT_NEAR(plan[3].duration_s, params.grasp_time + 0.02 / params.translate_speed, 1e-12);
  EXPECT_NEAR(plan[2].duration_s, params.grasp_time + 0.3 / params.rotate_speed, 1e-9);
  EXPECT_TRUE(plan.back().target.position.isApprox(Eigen::Vector3d::Zero()));
}

// The same pusher placed elsewhere is moved by the arm (distance over the
// translate speed), not swapped; a swap already places the new pusher.
TEST(ResetPlan, APusherMovedRatherThanSwappedCostsItsTravel) {
  ResetParams params;
  using K = PrimitiveKind;
  const auto moved = PlanReset(At(0, 0, 0), At(0, 0, 0), false, params, 0.005);
  ASSERT_EQ(Kinds(moved), (std::vector<K>{K::kMovePusher}));
  EXPECT_NEAR(moved[0].duration_s, 0.005 / params.translate_speed, 1e-12);
  EXPECT_LT(moved[0].duration_s, params.swap_time);
  EXPECT_EQ(Kinds(PlanReset(At(0.01, 0, 0), At(0, 0, 0), true, params, 0.005)),
            (std::vector<K>{K::kSwapPusher, K::kRelease, K::kTranslate, K::kRegrasp}));
  ResetRequest r;
  r.target = At(0, 0, 0);
  r.observed_end = r.true_end = At(0.01, 0, 0);
  const ResetOutcome plain = ExecuteReset(r, params, 7, 1);
  r.pusher_move_m = 0.005;
  const ResetOutcome with_move = ExecuteReset(r, params, 7, 1);
  ASSERT_TRUE(plain.success && with_move.success);
  EXPECT_NEAR(with_move.time_s - plain.time_s, 0.005 / params.translate_speed, 1e-12);
  EXPECT_EQ(with_move.final_true.position,
            plain.final_true.position)  // the placement is the trial's
      << "a pusher move must not change where the object is placed";
}

TEST(ResetExecute, SucceedsWithinToleranceAndReportsTime) {
  ResetParams params;
  ResetRequest r;
  r.observed_end = At(0.01, 0.002, 0.0, 0.1);
  r.true_end = r.observed_end;
  r.target = At(0, 0, 0);
  const ResetOutcome out = ExecuteReset(r, params, 1, 2);
  ASSERT_TRUE(out.success) << out.failure;
  EXPECT_EQ(out.attempts, 1);
  EXPECT_LE(out.position_error, params.position_tolerance);
  EXPECT_LE(out.angle_error, params.angle_tolerance);
  double planned = 0;
  for (const auto& p : out.plan) planned += p.duration_s;
  EXPECT_DOUBLE_EQ(out.time_s, planned);
  EXPECT_TRUE(out.failure.empty());
}

TEST(ResetExecute, ObjectOutsideTheWorkspaceFailsWithoutRetry) {
  ResetParams params;
  ResetRequest r;
  r.true_end = At(0.4, 0, 0);
  r.observed_end = r.true_end;
  const ResetOutcome out = ExecuteReset(r, params, 1, 2);
  EXPECT_FALSE(out.success);
  EXPECT_FALSE(out.retryable);
  EXPECT_NE(out.failure.find("left the workspace"), std::string::npos) << out.failure;
}

TEST(ResetExecute, AlwaysFailingResetIsRetriedThenReported) {
  ResetParams params;
  params.failure_probability = 1.0;
  params.max_attempts = 4;
  ResetRequest r;
  r.true_end = At(0.01, 0, 0);
  r.observed_end = r.true_end;
  const ResetOutcome out = ExecuteReset(r, params, 3, 4);
  EXPECT_FALSE(out.success);
  EXPECT_TRUE(out.retryable);
  EXPECT_EQ(out.attempts, 4);
  EXPECT_NE(out.failure.find("after 4 attempts"), std::string::npos) << out.failure;
  EXPECT_NE(out.failure.find("slipped"), std::string::npos) << out.failure;
  EXPECT_GT(out.time_s, 0);
}

TEST(ResetExecute, NoisySensingNeedsRetriesAtTheRateTheToleranceImplies) {
  // Verification sees the pose with 1 mm noise per axis against a 2 mm
  // tolerance: |e| of a 3-D Gaussian (sigma 1 mm) exceeds 2 mm with
  // probability ~0.26 (chi with 3 dof), so about a quarter of the first
  // attempts fail verification.
  ResetParams params;
  params.sensing_position_std = 0.001;
  params.placement_position_std = 0;
  params.placement_angle_std = 0;
  params.max_attempts = 1;
  int failed = 0;
  const int n = 2000;
  for (int trial = 0; trial < n; ++trial) {
    ResetRequest r;
    r.true_end = At(0.01, 0, 0);
    r.observed_end = r.true_end;
    // The verification draws belong to the prepared trial: one seed each.
    failed += ExecuteReset(r, params, static_cast<std::uint64_t>(trial), 9).success ? 0 : 1;
  }
  EXPECT_NEAR(failed / static_cast<double>(n), 0.2615, 0.03);
}

TEST(ResetExecute, DeterministicFromSeedAndTrial) {
  ResetParams params;
  params.failure_probability = 0.5;
  ResetRequest r;
  r.true_end = At(0.01, 0.01, 0, 0.2);
  r.observed_end = r.true_end;
  const ResetOutcome a = ExecuteReset(r, params, 42, 7);
  const ResetOutcome b = ExecuteReset(r, params, 42, 7);
  EXPECT_EQ(a.success, b.success);
  EXPECT_EQ(a.attempts, b.attempts);
  EXPECT_EQ(a.final_true.position, b.final_true.position);
  EXPECT_EQ(a.time_s, b.time_s);
}

// The class of bug this guards against: a trial's start pose depended on
// which cell prepared it and what that cell ran before (its previous end
// pose, the id of the trial just executed, a pusher swap, slips). The start
// pose must be a pure function of the prepared trial's seed, its target and
// the reset parameters.
TEST(ResetExecute, WhereTheObjectEndsBelongsToThePreparedTrialAlone) {
  ResetParams params;
  params.failure_probability = 0.3;
  params.sensing_position_std = 8e-4;  // some verifications fail: retries happen
  params.placement_position_std = 5e-4;
  params.placement_angle_std = 5e-3;
  const Pose target = At(0.001, -0.002, 0.0, 0.05);
  int successes = 0, retried = 0;
  for (std::uint64_t seed = 1; seed <= 300; ++seed) {
    const Placement pure = PlacementForTrial(target, params, seed);
    EXPECT_EQ(pure.true_pose.position, PlacementForTrial(target, params, seed).true_pose.position);
    // Two different histories: another previous end, trial just run, swap.
    ResetRequest a, b;
    a.true_end = a.observed_end = At(0.03, 0.01, 0, 0.4);
    b.true_end = b.observed_end = At(-0.02, 0.0, 0.0, -1.0);
    a.target = b.target = target;
    b.swap_pusher = true;
    const ResetOutcome ra = ExecuteReset(a, params, seed, 11);
    const ResetOutcome rb = ExecuteReset(b, params, seed, 4242);
    for (const ResetOutcome* r : {&ra, &rb}) {
      if (!r->success) continue;
      ++successes;
      retried += r->attempts > 1;
      EXPECT_EQ(r->final_true.position, pure.true_pose.position) << "seed " << seed;
      EXPECT_EQ(r->final_true.orientation.coeffs(), pure.true_pose.orientation.coeffs());
      EXPECT_EQ(r->final_observed.position, pure.observed.position);
      EXPECT_TRUE(pure.verified);
    }
  }
  EXPECT_GT(successes, 450);
  EXPECT_GT(retried, 50);  // slips and failed verifications were exercised
}

TEST(ResetExecute, NothingToMoveStillEndsAtTheTrialsPlacementInNoTime) {
  ResetParams params;
  ResetRequest r;
  r.target = At(0, 0, 0);
  r.true_end = r.observed_end = At(0.0005, 0, 0);  // within tolerance: empty plan
  const ResetOutcome out = ExecuteReset(r, params, 77, 3);
  ASSERT_TRUE(out.success) << out.failure;
  EXPECT_TRUE(out.plan.empty());
  EXPECT_EQ(out.time_s, 0.0);
  EXPECT_EQ(out.final_true.position, PlacementForTrial(r.target, params, 77).true_pose.position);
  EXPECT_NE(out.final_true.position, r.true_end.position);
}

TEST(ResetPlacement, SpreadIsThePlacementAccuracy) {
  // Without sensing noise and with tolerances 6-7 sigma wide nearly every
  // placement verifies at the first draw: the start pose is target +
  // N(0, placement_position_std) per axis.
  ResetParams params;
  params.placement_position_std = 3e-4;
  params.placement_angle_std = 4e-3;
  const Pose target = At(0.01, 0.0, 0.0, 0.2);
  const int n = 4000;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum2 = Eigen::Vector3d::Zero();
  double angle2 = 0;
  int placed_again = 0;
  for (int k = 0; k < n; ++k) {
    const Placement p = PlacementForTrial(target, params, static_cast<std::uint64_t>(k) + 1000);
    ASSERT_TRUE(p.verified);
    placed_again += p.placements > 1;
    const Eigen::Vector3d d = p.true_pose.position - target.position;
    sum += d;
    sum2 += d.cwiseProduct(d);
    const double a = AngleBetween(p.true_pose.orientation, target.orientation);
    angle2 += a * a;
  }
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(sum[i] / n, 0, 3e-4 * 0.06);
    EXPECT_NEAR(std::sqrt(sum2[i] / n), 3e-4, 3e-4 * 0.05);
  }
  EXPECT_LE(placed_again, 3);  // a 5-sigma rotation now and then
  // |rotation vector|^2 is sigma^2 chi^2(3): mean 3 sigma^2.
  EXPECT_NEAR(std::sqrt(angle2 / n / 3), 4e-3, 4e-3 * 0.05);
}

TEST(ResetParams, BadFieldsAreNamed) {
  ResetParams p;
  p.max_attempts = 0;
  try {
    ValidateResetParams(p);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()).rfind("reset.max_attempts:", 0), 0u) << e.what();
  }
}

TEST(Rng, NormalHasUnitVarianceAndStreamsDiffer) {
  Rng a(1, 2, StreamPurpose::kPoseNoise), b(1, 2, StreamPurpose::kDrops);
  double sum = 0, sum2 = 0;
  int same = 0;
  const int n = 100000;
  for (int i = 0; i < n; ++i) {
    const double x = a.Normal();
    sum += x;
    sum2 += x * x;
    same += a.Next() == b.Next();
  }
  EXPECT_NEAR(sum / n, 0, 0.015);
  EXPECT_NEAR(sum2 / n, 1, 0.015);
  EXPECT_EQ(same, 0);
}

}  // namespace
}  // namespace arena::reset
