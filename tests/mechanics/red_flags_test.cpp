// Issue 31 item 6: the numerical red flags of arena's model, each a scene or
// a problem where the model used to give an answer it had no right to give.
// Each test states what the answer is (or why the model must refuse).
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "arena/mechanics/lcp.hpp"
#include "arena/mechanics/model.hpp"
#include "arena/mechanics/simulate.hpp"
#include "scenes.hpp"

namespace arena::mechanics {
namespace {

// A slender rhombus prism (half-diagonals a along x, b along y) held by two
// point fingers closing along ±x at y = b/2: each presses on a face whose
// normal is b/√(a² + b²) from perpendicular to its closing direction.
Scene GrazingGrasp(double b) {
  Scene s;
  const double a = 0.025;
  s.object.shape = ObjectShape::kPrism;
  s.object.polygon = {{-a, 0}, {0, -b}, {a, 0}, {0, b}};
  s.object.height = 0.05;
  s.object.mass = 0.2;
  s.duration = 0.02;
  s.grip_force = 10;
  s.fingers.push_back(
      testing::Finger("left", ContactType::kPoint, {-a / 2, b / 2, 0}, {1, 0, 0}, 0.5));
  s.fingers.push_back(
      testing::Finger("right", ContactType::kPoint, {a / 2, b / 2, 0}, {-1, 0, 0}, 0.5));
  s.model.dt = 0.001;
  return s;
}

// A point pad keeps pressing by travelling along its closing direction onto
// the surface: gap / cos, where cos = n · c is the grazing factor. It was
// allowed down to 1e-6, amplifying the gap (and every rounding in it) up to
// 10⁶ times; at cos 1e-4 the pads jumped by metres in one step and the run
// reported ok. A face that close to parallel to the closing direction is
// one the pad cannot press on as the model has it (its force along the
// face normal, nearly across the jaw): a typed refusal naming the finger.
TEST(RedFlags, APointPadOnAGrazingFaceIsRefusedNamingTheFinger) {
  const SimulationResult r = Simulate(GrazingGrasp(2.5e-6));
  EXPECT_EQ(r.status, SimulationStatus::kSolverFailure)
      << "final x " << r.samples.back().position.transpose();
  EXPECT_NE(r.error.find("fingers[0] 'left'"), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("grazing"), std::string::npos) << r.error;
  // The same grasp on a face 45° from the closing direction is modelled.
  const SimulationResult ok = Simulate(GrazingGrasp(0.025));
  EXPECT_EQ(ok.status, SimulationStatus::kOk) << ok.error;
}

// A thin box (1.6 mm across the plane of the planar model, x-z) pushed by
// a point that starts 1 mm inside its bottom: the nearest face is the side
// across the plane (0.8 mm away), whose normal is the plane's own. Its
// friction had no in-plane direction and was dropped without a word (its
// normal force, out of the plane, too): here the LCP left then ended on a
// ray, an error naming the wrong cause; where the rest solves, a silent
// wrong answer. Now the step is refused naming the cause and the remedy
// (the full model, which has the tangent, runs the scene's step).
TEST(RedFlags, APlanarContactWithoutAnInPlaneTangentIsRefused) {
  Scene s = testing::HeldBox(0.2, 10, 0.5);
  s.object.size = {0.05, 0.0016, 0.1};
  s.gravity = {0, 0, 0};
  s.duration = 0.01;
  s.model.dt = 0.001;
  PusherSpec p;
  p.name = "pusher";
  p.position = {0, 0, -0.049};
  p.normal = {0, 0, 1};
  p.mu = 0.5;
  p.motion.velocity = {0, 0, 0.01};
  s.pusher = p;
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.model.dof, 3) << "the scene must run planar";
  EXPECT_EQ(r.status, SimulationStatus::kSolverFailure);
  EXPECT_NE(r.error.find("leaves the plane of the planar model"), std::string::npos) << r.error;
  s.model.reduce = Reduce::kFull;
  const SimulationResult full = Simulate(s);
  EXPECT_EQ(full.error.find("leaves the plane"), std::string::npos) << full.error;
}

// A 1 g box held at 10 N by point fingers (μ 0.5), pushed up from below
// by a sticking pusher at 1e-8 m/s, no gravity: the fingers slide along z
// at the pusher's speed (nothing else moves the object), whatever that
// speed. The slide threshold was 1e-9 of the solve's velocity scale
// Fs dt / m = 40 m/s here, 4e-8 m/s: the fingers were reported sticking
// while sliding. Now it is 1e-9 of the scene's own speeds (floored at
// rounding of the solve's scale), and the same scene at 1e-2 m/s agrees.
TEST(RedFlags, ASlowSlideOfALightObjectIsReportedSliding) {
  for (double speed : {1e-8, 1e-2}) {
    Scene s = testing::HeldBox(0.001, 10, 0.5);
    s.gravity = {0, 0, 0};
    s.duration = 0.04;
    PusherSpec p;
    p.name = "pusher";
    p.position = {0, 0, -0.05};
    p.normal = {0, 0, 1};
    p.mu = 0.5;
    p.motion.velocity = {0, 0, speed};
    s.pusher = p;
    const SimulationResult r = Simulate(s);
    ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
    const TrajectorySample& end = r.samples.back();
    EXPECT_NEAR(end.velocity.z(), speed, 1e-6 * speed);
    EXPECT_EQ(end.contacts[0].mode, ContactMode::kSlide) << "speed " << speed;
    EXPECT_EQ(end.contacts[1].mode, ContactMode::kSlide) << "speed " << speed;
    EXPECT_EQ(end.contacts[2].mode, ContactMode::kStick) << "speed " << speed;
  }
}

// Lemke's near-singular basis check (kMinBasisRcond in lcp.cpp): a basis
// whose refactored block has a reciprocal condition number under 1e-13 is
// refused with the typed kSingularBasis, not used because its inverse is
// finite. The LCP (covering vector c = (K, 1), K = 1e3, delta > 0):
//   A = [[-K, K], [-1 - delta/2, 1 + delta]],  b = (-K, -1 - delta/2).
// It has no solution: w1 = K (z2 - z1 - 1) >= 0 needs z2 >= 1 + z1 > 0, so
// w2 = 0, i.e. z2 = (1 + delta/2)(1 + z1) / (1 + delta) < 1 + z1. Lemke's
// path: z0 enters at row 2 (b/c: -1 - delta/2 < -1), z0 = 1 + delta/2,
// w1 = K delta/2; z2 enters (column -(K, 1 + delta)), w1 leaves first
// (ratio 1/2 against about 1); z1 enters with no positive entry in its
// column, a ray. The basis there, {z2, z0}, has the block
// [[-K, -K], [-1 - delta, -1]], whose reciprocal condition number is about
// delta / K: at delta 1e-6 and 1e-9 (1e-9, 1e-12) the ray is seen through a
// sound inverse and reported; at 1e-12 and 1e-14 (1e-15, 1e-17) the inverse
// is finite but has lost its digits, and the run stops as a singular basis
// after the same 2 pivots (with the check at 0, finiteness only, it
// reported a ray read off that inverse: this test then fails). Never ok
// (there is no solution), with any covering vector.
TEST(RedFlags, LemkeRefusesANearSingularBasisInsteadOfReadingItsRoundoff) {
  const double K = 1e3;
  for (double delta : {1e-6, 1e-9, 1e-12, 1e-14}) {
    Eigen::MatrixXd A(2, 2);
    A << -K, K, -1 - 0.5 * delta, 1 + delta;
    const Eigen::Vector2d b(-K, -1 - 0.5 * delta);
    LcpOptions opt;
    opt.covering = Eigen::Vector2d(K, 1);
    opt.covering_attempts = 1;
    const LcpResult r = SolveLcp(A, b, nullptr, opt);
    EXPECT_FALSE(r.ok) << "delta " << delta << ": the LCP has no solution";
    EXPECT_EQ(r.status, delta >= 1e-9 ? LcpStatus::kRayTermination : LcpStatus::kSingularBasis)
        << "delta " << delta << ": " << r.reason;
    EXPECT_NE(r.reason.find("after 2 pivots"), std::string::npos) << r.reason;
    const LcpResult any = SolveLcp(A, b, nullptr, LcpOptions{});
    EXPECT_FALSE(any.ok) << "delta " << delta;
    EXPECT_FALSE(any.reason.empty());
  }
}

}  // namespace
}  // namespace arena::mechanics

namespace arena::mechanics {
namespace {

// Whether (z, w = A z + b) solves the LCP, relative to the data's scale.
bool Solves(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, const LcpResult& r) {
  if (!r.ok || r.z.size() != b.size()) return false;
  const Eigen::VectorXd w = A * r.z + b;
  const double scale = std::max(b.lpNorm<Eigen::Infinity>(), 1e-300);
  return r.z.minCoeff() >= -1e-9 * r.z.lpNorm<Eigen::Infinity>() && w.minCoeff() >= -1e-9 * scale &&
         std::abs(r.z.dot(w)) <= 1e-9 * scale * std::max(1.0, r.z.lpNorm<Eigen::Infinity>());
}

// A degenerate LCP (every ratio ties at the first pivot: b = -1 with the
// covering vector all ones, and rows in symmetric pairs), scaled: (s A, s b)
// has the same solution z for every s > 0, and Lemke's path through it is
// the same when every tolerance is relative. Absolute ones made it fail
// silently: at s = 1e-15 the first pivot's point passed as a solution
// (acceptance floor 1, z0 "zero" below 1e-9) and came back ok with z 0.45
// off; the lexicographic rule's absolute 1e-14 made every row of the basis
// inverse tie at s = 1e15. Now the path is the same from 1e-8 to 1e15, and
// at 1e-15 (rounding of the data's size) the answer is right or a typed
// failure, never ok and wrong.
TEST(RedFlags, LemkeIsScaleInvariantAndNeverSilentlyWrong) {
  const int n = 8;
  Eigen::MatrixXd A0(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      A0(i, j) = (i == j ? 2.0 : 0.0) + ((i / 2 == j / 2) ? 1.0 : 0.0) -
                 (std::abs(i - j) == 2 ? 1.0 : 0.0);
    }
  }
  const Eigen::VectorXd b0 = -Eigen::VectorXd::Ones(n);
  LcpOptions opt;
  opt.covering = Eigen::VectorXd::Ones(n);
  opt.covering_attempts = 1;
  const LcpResult base = SolveLcp(A0, b0, nullptr, opt);
  ASSERT_TRUE(Solves(A0, b0, base)) << base.reason;
  for (double s : {1e-8, 1e8, 1e15}) {
    const LcpResult r = SolveLcp(Eigen::MatrixXd(s * A0), Eigen::VectorXd(s * b0), nullptr, opt);
    EXPECT_TRUE(Solves(s * A0, s * b0, r)) << "s = " << s << ": " << r.reason;
    EXPECT_EQ(r.pivots, base.pivots) << "s = " << s;
    if (r.ok) {
      EXPECT_LT((r.z - base.z).lpNorm<Eigen::Infinity>(), 1e-12) << "s = " << s;
    }
  }
  const double tiny = 1e-15;
  const LcpResult r =
      SolveLcp(Eigen::MatrixXd(tiny * A0), Eigen::VectorXd(tiny * b0), nullptr, opt);
  if (r.ok) {
    EXPECT_TRUE(Solves(tiny * A0, tiny * b0, r)) << "ok and wrong";
  } else {
    EXPECT_NE(r.status, LcpStatus::kOk);
    EXPECT_FALSE(r.reason.empty());
  }
}

}  // namespace
}  // namespace arena::mechanics
