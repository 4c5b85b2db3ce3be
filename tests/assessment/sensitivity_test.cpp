// Sensitivity and stability against cases whose answers are known.
//
// Sliding push (fingers at +-x hold a box, the pusher pushes it up along +z
// and it slides in the grasp):
//
//        pusher ^ v        each finger: normal force N (grip_force), friction mu N
//   |  +-----+  |          against the motion; gravity m g down:
//   |->|  m  |<-|            F_pusher = 2 mu N + m g
//   |  +-----+  |          so dF/dmu_i = N per finger (2N for a common mu),
//         ^                   dF/dN = 2 mu, dF/dm = g.
//
// Pivoting push: the pusher pushes at an offset d from the axis through two
// point fingers (no torsional friction), so the object turns about that axis:
// for a small angle, theta = v T / d, dtheta/dv = T / d.
//
// Stick/slip threshold: gravity only, 2 mu N = m g exactly: any grip force
// below it lets the object slide down, any above holds it -- unstable; with
// 2 mu N = 3 m g it is well inside sticking -- stable.
#include <gtest/gtest.h>

#include <cmath>

#include <nlohmann/json.hpp>

#include "arena/assessment/campaign_sensitivity.hpp"
#include "arena/assessment/noise.hpp"
#include "arena/assessment/sensitivity.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/reset/reset.hpp"

namespace arena::assessment {
namespace {

using mechanics::Scene;

Scene Box(double mass, double grip, double mu, Eigen::Vector3d size) {
  Scene s;
  s.object.shape = mechanics::ObjectShape::kBox;
  s.object.size = size;
  s.object.mass = mass;
  s.grip_force = grip;
  s.duration = 0.2;
  mechanics::ContactSpec left, right;
  left.name = "left";
  left.position = {-size.x() / 2, 0, 0};
  left.normal = {1, 0, 0};
  left.mu = mu;
  right.name = "right";
  right.position = {size.x() / 2, 0, 0};
  right.normal = {-1, 0, 0};
  right.mu = mu;
  s.fingers = {left, right};
  return s;
}

Scene SlidingPush() {
  Scene s = Box(0.2, 10, 0.5, {0.05, 0.03, 0.1});
  s.gravity = {0, 0, -9.81};
  mechanics::PusherSpec p;
  p.name = "pusher";
  p.position = {0, 0, -0.05};
  p.normal = {0, 0, 1};
  p.mu = 0.3;
  p.motion.velocity = {0, 0, 0.01};
  s.pusher = p;
  mechanics::ValidateScene(s);
  return s;
}

Scene PivotPush(double speed) {
  Scene s = Box(0.1, 10, 0.8, {0.05, 0.04, 0.01});
  mechanics::PusherSpec p;
  p.name = "pusher";
  p.position = {0, 0.01, -0.005};  // d = 10 mm off the finger axis (x)
  p.normal = {0, 0, 1};
  p.mu = 0.3;
  p.motion.velocity = {0, 0, speed};
  s.pusher = p;
  mechanics::ValidateScene(s);
  return s;
}

Scene Hold(double grip_over_threshold) {
  const double m = 0.2, g = 9.81, mu = 0.5;
  Scene s = Box(m, grip_over_threshold * m * g / (2 * mu), mu, {0.05, 0.03, 0.1});
  s.gravity = {0, 0, -g};
  mechanics::ValidateScene(s);
  return s;
}

const ParameterSensitivity& Find(const SensitivityReport& r, const std::string& name) {
  for (const auto& p : r.parameters) {
    if (p.parameter.name == name) return p;
  }
  throw std::runtime_error("no parameter " + name);
}

double D(const ParameterSensitivity& p, Quantity q) {
  return p.derivatives[static_cast<size_t>(q)].value;
}

SensitivityOptions DerivativesOnly(std::vector<std::string> params) {
  SensitivityOptions o;
  o.params = std::move(params);
  o.check_stability = false;
  o.threads = 2;
  return o;
}

TEST(SensitivityKnownDerivatives, SlidingPushForceIsTwoMuNPlusMg) {
  const Scene scene = SlidingPush();
  const auto r = AnalyseScene(scene, DerivativesOnly({"grip_force", "friction", "mass"}));
  ASSERT_TRUE(r.nominal.ok) << r.nominal.error;
  // The object slides in the grasp the whole push: both fingers slide.
  ASSERT_EQ(r.nominal.modes[0], std::vector{mechanics::ContactMode::kSlide});
  ASSERT_EQ(r.nominal.modes[1], std::vector{mechanics::ContactMode::kSlide});
  const double N = 10, mu = 0.5, m = 0.2, g = 9.81;
  EXPECT_NEAR(r.nominal.value(Quantity::kPusherForce), 2 * mu * N + m * g, 0.01 * (2 * mu * N));

  const auto& dN = Find(r, "grip_force");
  EXPECT_TRUE(dN.differentiable) << dN.note;
  EXPECT_NEAR(D(dN, Quantity::kPusherForce), 2 * mu, 0.01 * 2 * mu);
  // The fingers' common mu: d/dmu = 2N.
  const auto& dmu = Find(r, "fingers.mu");
  EXPECT_TRUE(dmu.differentiable) << dmu.note;
  EXPECT_NEAR(D(dmu, Quantity::kPusherForce), 2 * N, 0.01 * 2 * N);
  // Every mu scaled together: d/dscale = 2 mu N (the pusher's own friction
  // does no work: nothing slides across it).
  const auto& dscale = Find(r, "mu_scale");
  EXPECT_NEAR(D(dscale, Quantity::kPusherForce) / mu, 2 * N, 0.01 * 2 * N);
  EXPECT_NEAR(D(Find(r, "pusher.mu"), Quantity::kPusherForce), 0, 1e-3);
  EXPECT_NEAR(D(Find(r, "object.mass"), Quantity::kPusherForce), g, 0.02 * g);
  // Normalised: 1 % of grip force moves the pusher force by 2 mu N / F %.
  EXPECT_NEAR(dN.derivatives[static_cast<size_t>(Quantity::kPusherForce)].normalised,
              2 * mu * N / (2 * mu * N + m * g), 0.01);
}

TEST(SensitivityKnownDerivatives, PivotAngleAgainstPusherSpeed) {
  const double v = 0.002, T = 0.2, d = 0.01;
  const Scene scene = PivotPush(v);
  const auto r = AnalyseScene(scene, DerivativesOnly({"push_speed"}));
  ASSERT_TRUE(r.nominal.ok) << r.nominal.error;
  // theta = v T / d (small angle: 0.04 rad here).
  EXPECT_NEAR(r.nominal.value(Quantity::kRotation), v * T / d, 0.05 * v * T / d);
  const auto& dv = Find(r, "push_speed");
  EXPECT_TRUE(dv.differentiable) << dv.note;
  EXPECT_NEAR(D(dv, Quantity::kRotation), T / d, 0.05 * T / d);
  // Rotation is linear in the speed: normalised sensitivity ~1 (% per %).
  EXPECT_NEAR(dv.derivatives[static_cast<size_t>(Quantity::kRotation)].normalised, 1.0, 0.05);
}

TEST(SensitivityStability, ExactlyAtStickSlipThresholdIsUnstable) {
  SensitivityOptions o;
  o.params = {"grip_force", "friction", "mass"};
  o.threads = 2;
  o.stability.relative_tolerance = 0.02;
  const Scene scene = Hold(1.0);
  const auto r = AnalyseScene(scene, o);
  ASSERT_TRUE(r.nominal.ok) << r.nominal.error;
  EXPECT_TRUE(r.stability.unstable);
  ASSERT_TRUE(r.stability.nearest.has_value());
  // The boundary is right at the nominal: well within one tolerance.
  EXPECT_LT(r.stability.nearest->tolerances, 0.5) << r.stability.nearest->parameter;
  EXPECT_NE(r.stability.nearest->change.find("stick"), std::string::npos)
      << r.stability.nearest->change;
  // Grip force is not differentiable here (a mode changes within one step).
  EXPECT_FALSE(Find(r, "grip_force").differentiable);
}

TEST(SensitivityStability, WellInsideSticking_IsStable) {
  SensitivityOptions o;
  o.params = {"grip_force", "friction", "mass"};
  o.threads = 2;
  o.stability.relative_tolerance = 0.02;
  const auto r = AnalyseScene(Hold(3.0), o);
  ASSERT_TRUE(r.nominal.ok) << r.nominal.error;
  EXPECT_FALSE(r.stability.unstable) << (r.stability.reasons.empty() ? "" : r.stability.reasons[0]);
  EXPECT_TRUE(r.nominal.grasp_kept);
  for (const auto& p : r.parameters) EXPECT_TRUE(p.differentiable) << p.parameter.name << p.note;
  // The search found no boundary within 4 tolerances (the threshold is at -67 % grip).
  EXPECT_FALSE(r.stability.nearest.has_value());
}

TEST(SensitivityStability, NoiseTolerancesComeFromTheDefectProfile) {
  const ActuationNoise n = ParseActuationNoise(
      R"({"actuation_noise": {"velocity_scale_std": 0.02, "velocity_offset_std": [0, 0, 0.0002]},
          "friction_variability": {"mu_scale_std": 0.1}, "latency_ms": 5})");
  StabilityOptions o;
  o.relative_tolerance = 0;
  o.noise = n;
  o.noise_sigmas = 2;
  const Scene scene = SlidingPush();
  for (const auto& p : SceneParameters(scene)) {
    const double t = ToleranceFor(p, o).first;
    if (p.name == "mu_scale") {
      EXPECT_DOUBLE_EQ(t, 0.2);
    } else if (p.name == "push_speed") {
      EXPECT_DOUBLE_EQ(t, 2 * 0.02 * 0.01);
    } else if (p.name == "pusher.velocity.z") {
      EXPECT_DOUBLE_EQ(t, 0.0004);
    } else {
      EXPECT_EQ(t, 0) << p.name;
    }
  }
  EXPECT_THROW(ParseActuationNoise(R"({"friction_variability": {"mu_scale_std": -1}})"),
               NoiseError);
  try {
    ParseActuationNoise(R"({"actuation_noise": {"velocity_offset_std": [0, "x", 0]}})");
    FAIL();
  } catch (const NoiseError& e) {
    EXPECT_EQ(e.field(), "actuation_noise.velocity_offset_std[1]");
  }
}

TEST(SensitivityParameters, FiltersPerturbationsAndBadInput) {
  const Scene scene = SlidingPush();
  const auto all = SceneParameters(scene);
  EXPECT_EQ(SelectParameters(all, {"left"}).size(), 3u);  // mu, 2 positions
  // 3 contacts x 2 positions, the fingers' and the pusher's normals x 2
  EXPECT_EQ(SelectParameters(all, {"kinematics"}).size(), 10u);
  EXPECT_THROW(SelectParameters(all, {"gripforce"}), std::invalid_argument);
  // A tilted line keeps its axis perpendicular to the normal; a contact moved
  // along its face stays on the surface.
  for (const auto& p : SelectParameters(all, {"kinematics"})) {
    EXPECT_NO_THROW(PerturbScene(scene, p, 0.02 * p.scale)) << p.name;
  }
  // Off the face: refused, never silently clamped.
  const auto pos = SelectParameters(all, {"left.position.t1"});
  EXPECT_THROW(PerturbScene(scene, pos[0], 0.2), mechanics::SceneError);
  const auto grip = SelectParameters(all, {"grip_force"});
  EXPECT_THROW(PerturbScene(scene, grip[0], -11), mechanics::SceneError);
  SensitivityOptions o;
  o.stability.tolerances["no.such"] = 1;
  EXPECT_THROW(AnalyseScene(scene, o), std::invalid_argument);
}

// A recorded path has no velocity to perturb (its velocity field is unused,
// zero): no velocity parameters, and a perturbation asked for anyway is
// refused naming the path, never applied to the unused field.
TEST(SensitivityParameters, ARecordedPathHasNoVelocityToPerturb) {
  const Scene constant = SlidingPush();
  Scene s = constant;
  mechanics::PusherPath path;
  path.t = {0, 0.5, 1.0};
  path.position = {s.pusher->position, s.pusher->position + Eigen::Vector3d(0, 0, 0.005),
                   s.pusher->position + Eigen::Vector3d(0, 0, 0.01)};
  s.pusher->motion.velocity.setZero();
  s.pusher->path = path;
  mechanics::ValidateScene(s);
  const auto all = SceneParameters(s);
  EXPECT_THROW(SelectParameters(all, {"velocity"}), std::invalid_argument);
  EXPECT_THROW(SelectParameters(all, {"angular_velocity"}), std::invalid_argument);
  EXPECT_EQ(SelectParameters(all, {"pusher.mu"}).size(), 1u);
  const auto speed = SelectParameters(SceneParameters(constant), {"push_speed"});
  ASSERT_EQ(speed.size(), 1u);
  try {
    PerturbScene(s, speed[0], 0.001);
    ADD_FAILURE() << "a path pusher's speed was perturbed";
  } catch (const mechanics::SceneError& e) {
    EXPECT_EQ(e.field(), "pusher.motion.path");
  }
}

TEST(SensitivityReportJson, RankedAndComplete) {
  SensitivityOptions o = DerivativesOnly({"grip_force", "friction", "velocity"});
  const Scene scene = SlidingPush();
  const auto r = AnalyseScene(scene, o);
  for (size_t i = 1; i < r.parameters.size(); ++i) {
    EXPECT_GE(r.parameters[i - 1].score, r.parameters[i].score);
  }
  const auto j = ToJson(r, scene);
  EXPECT_EQ(j["parameters"].size(), r.parameters.size());
  EXPECT_EQ(j["nominal"]["modes"]["left"], "slide");
  EXPECT_EQ(j["quantity_units"]["pusher_force"], "N");
  EXPECT_GT(j["model_runs"].get<long>(), 4 * 3);
  EXPECT_FALSE(j.contains("stability"));
}

TEST(CampaignSpread, VerdictsAndSpread) {
  EXPECT_EQ(SpreadVerdict(0.001, 0.001, 4, 1e-6), "matches");
  EXPECT_EQ(SpreadVerdict(0.01, 0.001, 4, 1e-6), "model_underestimates");
  EXPECT_EQ(SpreadVerdict(0.00001, 0.001, 4, 1e-6), "model_overestimates");
  EXPECT_EQ(SpreadVerdict(0.001, 0.001, 1, 1e-6), "too_few_replicates");
  EXPECT_EQ(SpreadVerdict(0.0, 0.0, 3, 1e-6), "matches");
  const auto [lo, hi] = ChiSquare95(3);
  EXPECT_NEAR(lo, 0.216, 1e-3);
  EXPECT_NEAR(hi, 9.348, 1e-3);
  const auto [lo30, hi30] = ChiSquare95(30);  // tables: 16.791, 46.979
  EXPECT_NEAR(lo30, 16.791, 0.1);
  EXPECT_NEAR(hi30, 46.979, 0.1);
  EXPECT_NEAR(*Spread({{0, 0, 0}, {0, 0, 2}}), std::sqrt(2.0), 1e-12);
  EXPECT_FALSE(Spread({{1, 2, 3}}).has_value());
}

TEST(CampaignSpread, EnsembleDrawsFollowTheProfile) {
  ActuationNoise n;
  n.mu_scale_std = 0.1;
  n.velocity_scale_std = 0.02;
  std::mt19937_64 rng(3);
  double s1 = 0, s2 = 0;
  const int k = 4000;
  for (int i = 0; i < k; ++i) {
    const auto d = DrawNoise(n, &rng);
    ASSERT_GT(d.mu_scale, 0);
    s1 += d.mu_scale - 1;
    s2 += (d.mu_scale - 1) * (d.mu_scale - 1);
  }
  EXPECT_NEAR(s1 / k, 0, 0.01);
  EXPECT_NEAR(std::sqrt(s2 / k), 0.1, 0.01);
  const Scene s = ApplyNoise(SlidingPush(), {1.1, 0.5, {0, 0, 0.001}});
  EXPECT_NEAR(s.fingers[0].mu, 0.55, 1e-12);
  EXPECT_NEAR(s.pusher->motion.velocity.z(), 0.006, 1e-12);
}

// The ensemble's start pose comes from the distribution the simulated cell
// draws it from (reset::PlacementForTrial): same spread, the same
// truncation by verification (a placement seen out of tolerance is placed
// again), read from the profile the cell records.
TEST(CampaignSpread, EnsembleStartPoseIsTheResetsPlacement) {
  const StartPoseNoise n = ParseStartPoseNoise(R"({
      "emulated": true,
      "pose_noise": {"position_std": [0.0005, 0.0002, 0.0001], "rotation_std": 0.004},
      "reset": {"placement_position_std": 0.0012, "placement_angle_std": 0.01,
                "position_tolerance": 0.002, "angle_tolerance": 0.02, "max_attempts": 3}})");
  EXPECT_DOUBLE_EQ(n.sensing_position_std, 0.0005);
  EXPECT_DOUBLE_EQ(n.sensing_angle_std, 0.004);
  ASSERT_TRUE(n.any());
  reset::ResetParams p;
  p.placement_position_std = 0.0012;
  p.placement_angle_std = 0.01;
  p.sensing_position_std = 0.0005;
  p.sensing_angle_std = 0.004;
  const int k = 6000;
  std::mt19937_64 rng(11);
  double ours = 0, cells = 0, ours_angle = 0, cells_angle = 0;
  reset::Pose target;
  for (int i = 0; i < k; ++i) {
    const StartPoseDraw d = DrawStartPose(n, &rng);
    ours += d.offset.squaredNorm();
    ours_angle += d.rotation.squaredNorm();
    const reset::Placement c = reset::PlacementForTrial(target, p, 5000 + i);
    cells += c.true_pose.position.squaredNorm();
    const double a = reset::AngleBetween(c.true_pose.orientation, target.orientation);
    cells_angle += a * a;
  }
  // |offset| of 1.2 mm per axis is often beyond the 2 mm tolerance: the
  // truncation is visible (RMS below the untruncated sqrt(3) 1.2 mm).
  EXPECT_LT(std::sqrt(cells / k), 0.95 * std::sqrt(3.0) * 0.0012);
  EXPECT_NEAR(std::sqrt(ours / k), std::sqrt(cells / k), 0.03 * std::sqrt(cells / k));
  EXPECT_NEAR(std::sqrt(ours_angle / k), std::sqrt(cells_angle / k),
              0.03 * std::sqrt(cells_angle / k));

  // The scene starts there with the fingers closed onto the object.
  StartPoseDraw d;
  d.offset = {0.0, 0.0005, 0.0003};
  d.rotation = {0.0, 0.0, 0.01};
  const Scene moved = ApplyStartPose(SlidingPush(), d);
  EXPECT_TRUE(moved.object.pose.position.isApprox(Eigen::Vector3d(0, 0.0005, 0.0003)));
  EXPECT_NEAR(moved.object.pose.rpy.z(), 0.01, 1e-12);

  // A robot or recording (not emulated) keeps its own start; no reset
  // object: a cell at the reset defaults; bad fields named.
  EXPECT_FALSE(ParseStartPoseNoise(R"({"emulated": false})").any());
  EXPECT_DOUBLE_EQ(ParseStartPoseNoise("{}").position_std,
                   reset::ResetParams{}.placement_position_std);
  EXPECT_DOUBLE_EQ(ParseStartPoseNoise("{}").angle_std, reset::ResetParams{}.placement_angle_std);
  try {
    ParseStartPoseNoise(R"({"reset": {"placement_angle_std": -1}})");
    FAIL();
  } catch (const NoiseError& e) {
    EXPECT_EQ(e.field(), "reset.placement_angle_std");
  }
}

}  // namespace
}  // namespace arena::assessment
