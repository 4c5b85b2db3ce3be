// The support's friction against closed forms (issue 30): the wrench a
// support gives must be the one its pressure distribution gives (the limit
// surface), not whatever a rigid solver picks among coplanar points.
//
// Set-up (the push dataset's, in the table frame: x, y on the table, z up,
// gravity -z): a square prism of side 2a = 90 mm, 13 mm thick, mass m, on
// a support of friction μ with uniform pressure; a frictionless sphere
// pusher (radius 4.75 mm) at mid-height, starting 5 mm from the -x face and
// moving +x at speed V.
//
//          y
//          ^     +-----------+
//          |     |           |
//   pusher o-->  |     c     |   a face-centred push: e = 0
//     (e)  |     |           |   off-centre: the pusher at y = e
//          |     +-----------+
//          +---------------------> x
#include <cmath>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/mechanics/support.hpp"
#include "support_stage.hpp"

namespace arena::mechanics {
namespace {

constexpr double kHalf = 0.045;      // a (m)
constexpr double kHeight = 0.013;    // m
constexpr double kMass = 0.8374;     // kg
constexpr double kG = 9.81;          // m/s²
constexpr double kMu = 0.3;          // support friction
constexpr double kRadius = 0.00475;  // pusher sphere (m)

Scene FreePush(double offset, double speed, double duration) {
  Scene s;
  s.object.shape = ObjectShape::kPrism;
  s.object.polygon = {{-kHalf, -kHalf}, {kHalf, -kHalf}, {kHalf, kHalf}, {-kHalf, kHalf}};
  s.object.height = kHeight;
  s.object.mass = kMass;
  s.object.pose.position = {0, 0, kHeight / 2};
  s.gravity = {0, 0, -kG};
  s.duration = duration;
  s.grip_force = 0;
  PusherSpec p;
  p.name = "pusher";
  p.type = ContactType::kPoint;
  p.radius = kRadius;
  p.position = {-kHalf - 0.005, offset, kHeight / 2};
  p.normal = {1, 0, 0};
  p.mu = 0;
  p.motion.velocity = {speed, 0, 0};
  s.pusher = p;
  SupportSpec support;
  support.mu = kMu;
  s.support = support;
  s.model.dt = 0.002;
  return s;
}

// (a) A face-centred push: by symmetry the object translates along x, and
// quasi-statically (after the impulse that brings it to the pusher's speed)
// the pusher's force balances the support's sliding friction, which for a
// pure translation is μ N whatever the pressure: F = μ m g, along x.
TEST(Support, FaceCentredPushNeedsMuMgAndTranslatesStraight) {
  const double V = 0.02;
  Scene s = FreePush(0, V, 0.6);
  ValidateScene(s);
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_EQ(r.model.dof, 3);
  EXPECT_LT(r.residuals.force_balance, 1e-9);
  EXPECT_LT(r.residuals.complementarity, 1e-9);
  // Contact at t = 5 mm / V = 0.25 s; by 0.4 s the object moves with the pusher.
  for (const auto& sample : r.samples) {
    if (sample.t < 0.4) continue;
    EXPECT_NEAR(sample.pusher_force.x(), kMu * kMass * kG, 1e-9 * kMass * kG) << sample.t;
    EXPECT_NEAR(sample.pusher_force.y(), 0, 1e-9 * kMass * kG);
    EXPECT_NEAR(sample.velocity.x(), V, 1e-9 * V);
    EXPECT_NEAR(sample.velocity.y(), 0, 1e-12);
    EXPECT_NEAR(sample.angular_velocity.z(), 0, 1e-9);
  }
  // Before contact nothing moves (the support holds it; no force).
  EXPECT_EQ(r.samples.at(25).position, r.samples.front().position);
  EXPECT_NEAR(r.samples.back().position.x(), V * (0.6 - 0.25), 2 * V * s.model.dt);
}

// (b) A disk spun in place: each point at radius r slides tangentially and
// carries μ p(r) dA of friction at arm r, so the torque is
//   τ = μ (m g / π R²) ∫_0^R r · 2π r dr = (2/3) μ m g R.
// No scene applies a pure couple (the pusher is one contact), so the
// closed form is checked on the support stage the planar step uses: its
// sampled direction of pure spin must carry exactly that torque and no
// force, and so must the exact limit-surface wrench it reports.
TEST(Support, DiskSpunInPlaceNeedsTwoThirdsMuMgR) {
  const double R = 0.0525;
  Scene s = FreePush(0, 0.01, 0.1);
  s.object.shape = ObjectShape::kCylinder;
  s.object.polygon.clear();
  s.object.radius = R;
  s.pusher->position = {-R - 0.005, 0, kHeight / 2};
  ValidateScene(s);
  SupportStage stage;
  ASSERT_EQ(
      stage.Setup(s, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()),
      "");
  Eigen::Matrix<double, 3, Eigen::Dynamic> D;
  const Eigen::Vector3d c(0, 0, kHeight / 2);
  stage.Columns(Eigen::Matrix3d::Identity(), c, c, Eigen::Vector3d(0, 0, 1), &D);
  const double torque = 2.0 / 3.0 * kMu * kMass * kG * R;
  // The last column is the previous twist's: a pure spin (+z) here.
  const Eigen::Vector3d spin = stage.limit() * D.col(D.cols() - 1);
  EXPECT_NEAR(spin.z(), -torque, 1e-12 * torque);
  EXPECT_NEAR(spin.head<2>().norm(), 0, 1e-12 * kMu * kMass * kG);
  const Eigen::Vector3d exact = stage.Exact(Eigen::Vector3d(0, 0, -3.0));
  EXPECT_NEAR(exact.z(), torque, 1e-12 * torque);
  EXPECT_NEAR(exact.head<2>().norm(), 0, 1e-12 * kMu * kMass * kG);
}

// An independent integration of Coulomb friction over the square footprint
// (uniform pressure m g / 4a²): the midpoint rule on an n × n grid of
// cells, for the twist (vx, vy, ω) about the centre. Returns (Fx, Fy, τ).
Eigen::Vector3d IntegrateSquare(double vx, double vy, double w, int n) {
  const double h = 2 * kHalf / n;
  const double p = kMu * kMass * kG / (n * n);  // μ times each cell's load
  double fx = 0, fy = 0, tau = 0;
  for (int i = 0; i < n; ++i) {
    const double x = -kHalf + (i + 0.5) * h;
    for (int j = 0; j < n; ++j) {
      const double y = -kHalf + (j + 0.5) * h;
      const double ux = vx - w * y, uy = vy + w * x;
      const double u = std::hypot(ux, uy);
      if (u == 0) continue;
      fx -= p * ux / u;
      fy -= p * uy / u;
      tau -= p * (x * uy - y * ux) / u;
    }
  }
  return {fx, fy, tau};
}

// (c) An off-centre push: a frictionless pusher at y = e presses along the
// face normal d, through its contact point r (object frame, about the
// centre). Quasi-statically the support's friction balances it: the
// friction wrench W(ν) = (Wx, Wy, τ) is -λ (d, r × d) for some λ > 0, so
//   d⊥ · (Wx, Wy) = 0   and   τ - (r × d) (d · (Wx, Wy)) = 0.
// The twist (1, vy, ω) (object frame, about the centre) that solves these
// is found by Newton's method on the integral above; its centre of rotation
// is (-vy/ω, 1/ω). The model's twist at the same instant, taken into the
// object frame, must put the centre of rotation there (within 0.25 % of
// the side; measured 0.11 mm = 0.12 %), and the pusher's force must be
// λ = -d · (Wx, Wy) (within 0.1 %; measured 0.006 %): the model's ~400-point
// quadrature against this 400 × 400 grid, and the object's inertia, which
// this slow push makes small.
TEST(Support, OffCentrePushTurnsAboutTheIntegratedCentreOfRotation) {
  const double e = 0.02, V = 0.01;
  Scene s = FreePush(e, V, 0.8);
  ValidateScene(s);
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_EQ(r.model.dof, 3);
  EXPECT_LT(r.residuals.complementarity, 1e-9);
  for (const double t : {0.55, 0.7, 0.8}) {
    const auto& sample = r.samples.at(static_cast<size_t>(std::lround(t * kSampleRateHz)));
    const Eigen::Matrix3d R_GO = sample.orientation.toRotationMatrix();
    // The pusher's contact point and force direction in the object frame.
    const auto& pusher = sample.contacts.back();
    ASSERT_TRUE(pusher.touching) << t;
    const Eigen::Vector2d rp = pusher.point.head<2>();
    const Eigen::Vector2d d = (R_GO.transpose() * sample.pusher_force).head<2>().normalized();
    const double m = rp.x() * d.y() - rp.y() * d.x();
    const int n = 400;
    auto residual = [&](const Eigen::Vector2d& q) {
      const Eigen::Vector3d W = IntegrateSquare(1, q.x(), q.y(), n) / (kMu * kMass * kG);
      return Eigen::Vector2d(-d.y() * W.x() + d.x() * W.y(),
                             W.z() - m * (W.x() * d.x() + W.y() * d.y()));
    };
    Eigen::Vector2d x(0, -10);  // a push above the centre turns it clockwise
    for (int it = 0; it < 30 && residual(x).norm() > 1e-13; ++it) {
      const Eigen::Vector2d f = residual(x);
      Eigen::Matrix2d J;
      for (int k = 0; k < 2; ++k) {
        Eigen::Vector2d dx = x;
        const double step = 1e-6 * std::max(1.0, std::abs(x[k]));
        dx[k] += step;
        J.col(k) = (residual(dx) - f) / step;
      }
      x -= J.lu().solve(f);
    }
    ASSERT_LT(residual(x).norm(), 1e-9);
    const Eigen::Vector2d cor_integrated(-x.x() / x.y(), 1.0 / x.y());
    // The model's twist in the object frame (O's origin is the centre).
    const Eigen::Vector2d v_O = (R_GO.transpose() * sample.velocity).head<2>();
    const double w = sample.angular_velocity.z();
    ASSERT_GT(std::abs(w), 0);
    const Eigen::Vector2d cor_model(-v_O.y() / w, v_O.x() / w);
    EXPECT_NEAR((cor_model - cor_integrated).norm(), 0, 0.0025 * 2 * kHalf)
        << "t " << t << ": model " << cor_model.transpose() << ", integrated "
        << cor_integrated.transpose();
    const Eigen::Vector3d W = IntegrateSquare(1, x.x(), x.y(), n);
    EXPECT_NEAR(sample.pusher_force.norm(), -(W.x() * d.x() + W.y() * d.y()),
                0.001 * kMu * kMass * kG)
        << t;
  }
}

// The support is refused, naming it, where it cannot hold: the full 6-DOF
// model (the support's load is fixed by the pressure, so only the planar
// model is exact) and a scene that is not planar about the table.
TEST(Support, RefusedWhereTheModelCannotHoldIt) {
  Scene s = FreePush(0, 0.01, 0.1);
  s.model.reduce = Reduce::kFull;
  const SimulationResult full = Simulate(s);
  EXPECT_EQ(full.status, SimulationStatus::kInvalidScene);
  EXPECT_EQ(full.error.rfind("support", 0), 0u) << full.error;
  s = FreePush(0, 0.01, 0.1);
  s.pusher->motion.velocity = {0.01, 0, 0.001};  // lifts off the table plane
  const SimulationResult lifted = Simulate(s);
  EXPECT_EQ(lifted.status, SimulationStatus::kInvalidScene);
  EXPECT_EQ(lifted.error.rfind("support", 0), 0u) << lifted.error;
}

}  // namespace
}  // namespace arena::mechanics
