// Model structure: tangent basis, constituent points and rigidity, unknown
// counts ("model only what the scene requires"), planarity, full-vs-auto
// agreement, and 250 Hz sampling.
#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/simulate.hpp"
#include "scenes.hpp"

namespace arena::mechanics {
namespace {

using testing::CanonicalScene;
using testing::Finger;
using testing::HeldBox;

TEST(TangentBasis, FollowsTheSceneRule) {
  // Fingers along ±x: t1 = z.
  EXPECT_LT((FirstTangent({1, 0, 0}) - Eigen::Vector3d::UnitZ()).norm(), 1e-15);
  EXPECT_LT((FirstTangent({-1, 0, 0}) - Eigen::Vector3d::UnitZ()).norm(), 1e-15);
  // |n·z| >= 0.9: fall back to y.
  EXPECT_LT((FirstTangent({0, 0, 1}) - Eigen::Vector3d::UnitY()).norm(), 1e-15);
  // Normal along y... and z: x is the last resort.
  const Eigen::Vector3d n = Eigen::Vector3d(0, 1, 1).normalized();
  EXPECT_LT((FirstTangent(n) - Eigen::Vector3d(0, -1, 1).normalized()).norm(), 1e-15);
  // Projection, normalised.
  const Eigen::Vector3d m = Eigen::Vector3d(1, 0, 0.5).normalized();
  const Eigen::Vector3d t1 = FirstTangent(m);
  EXPECT_NEAR(t1.norm(), 1, 1e-15);
  EXPECT_NEAR(t1.dot(m), 0, 1e-15);
  EXPECT_GT(t1.z(), 0);
}

TEST(TangentBasis, EdgesAlongAxesForMultiplesOfFour) {
  for (const Eigen::Vector3d& n : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(-1, 0, 0)}) {
    const auto edges = ConeEdges(n, 8);
    ASSERT_EQ(edges.size(), 8u);
    EXPECT_LT((edges[0] - Eigen::Vector3d::UnitZ()).norm(), 1e-15);
    EXPECT_LT((edges[2] - n.cross(Eigen::Vector3d::UnitZ())).norm(), 1e-15);
    for (const auto& e : edges) {
      EXPECT_NEAR(e.norm(), 1, 1e-15);
      EXPECT_NEAR(e.dot(n), 0, 1e-15);
    }
    int along_axes = 0;
    for (const auto& e : edges) along_axes += e.cwiseAbs().maxCoeff() > 1 - 1e-15;
    EXPECT_EQ(along_axes, 4);  // ±y and ±z
  }
}

// The paper's interpolation constraints tie the constituent points of a
// line (patch) to two (three) reference points. Here the points' velocities
// come from one rigid twist, so the constraints hold identically.
TEST(Rigidity, InterpolationConstraintsAreIdentities) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(-1, 1);
  ContactSpec line = Finger("line", ContactType::kLine, {0.02, 0.01, -0.03}, {-1, 0, 0}, 0.5);
  line.axis = Eigen::Vector3d(0, 0.3, 1).normalized();
  line.length = 0.04;
  ContactSpec patch = Finger("patch", ContactType::kPatch, {0.02, 0, 0},
                             Eigen::Vector3d(-1, 0.2, 0).normalized(), 0.5);
  patch.radius = 0.01;
  const Eigen::Vector3d com(0.001, -0.002, 0.003);
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Vector3d v(U(rng), U(rng), U(rng)), w(U(rng), U(rng), U(rng));
    auto vel = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d { return v + w.cross(p - com); };
    {
      const auto off = ConstituentOffsets(line, 6);
      ASSERT_EQ(off.size(), 6u);
      const Eigen::Vector3d p1 = line.position + off[0], p2 = line.position + off[1];
      const Eigen::Vector3d a1 = vel(p1), a2 = vel(p2);
      for (const auto& o : off) {
        const Eigen::Vector3d pj = line.position + o;
        const double s = (pj - p1).dot(line.axis) / (p2 - p1).norm();  // signed dist ratio
        EXPECT_LT((vel(pj) - (a1 + (a2 - a1) * s)).norm(), 1e-13);
      }
      EXPECT_NEAR((off.back() - off.front()).norm(), line.length, 1e-15);
    }
    {
      const auto off = ConstituentOffsets(patch, 5);
      ASSERT_EQ(off.size(), 5u);
      // Barycentric interpolation from the first three points.
      const Eigen::Vector3d p1 = patch.position + off[0], p2 = patch.position + off[1],
                            p3 = patch.position + off[2];
      Eigen::Matrix<double, 3, 2> E;
      E << p2 - p1, p3 - p1;
      for (const auto& o : off) {
        const Eigen::Vector3d pj = patch.position + o;
        EXPECT_NEAR((pj - patch.position).dot(patch.normal), 0, 1e-15);  // in the contact plane
        EXPECT_NEAR(o.norm(), 2 * patch.radius / 3, 1e-15);
        const Eigen::Vector2d st = E.colPivHouseholderQr().solve(pj - p1);
        const Eigen::Vector3d interp =
            vel(p1) + (vel(p2) - vel(p1)) * st[0] + (vel(p3) - vel(p1)) * st[1];
        EXPECT_LT((vel(pj) - interp).norm(), 1e-12);
      }
    }
  }
}

// Unknowns: a point finger has no normal row (λ = grip force) and no
// torsional rows; absent pusher and gravity add nothing.
TEST(ModelSize, OnlyWhatTheSceneRequires) {
  Scene s = CanonicalScene();
  s.model.reduce = Reduce::kFull;
  // left point: 8 β + ξ; right line 3 × (λ + 8 β + ξ) + pad y±; pusher λ + 8 β + ξ.
  EXPECT_EQ(ContactModel(s).info().unknowns, 9 + 32 + 10);
  Scene no_pusher = s;
  no_pusher.pusher.reset();
  EXPECT_EQ(ContactModel(no_pusher).info().unknowns, 9 + 32);
  Scene no_gravity = no_pusher;
  no_gravity.gravity.setZero();
  EXPECT_EQ(ContactModel(no_gravity).info().unknowns, 9 + 32);
  Scene frictionless = s;
  for (auto& f : frictionless.fingers) f.mu = 0;
  frictionless.pusher->mu = 0;
  EXPECT_EQ(ContactModel(frictionless).info().unknowns, 0 + (3 + 2) + 1);
  Scene no_grip = s;
  no_grip.grip_force = 0;
  EXPECT_EQ(ContactModel(no_grip).info().unknowns, 10);
  // Planar: two in-plane edges per point.
  Scene planar = CanonicalScene();
  const ContactModel m(planar);
  EXPECT_EQ(m.info().dof, 3);
  EXPECT_EQ(m.info().unknowns, 3 + 14 + 4);
  EXPECT_EQ(m.info().facets, 8);
  EXPECT_EQ(m.info().points, 3);
}

TEST(Planarity, DetectsThePlaneAndRefusesOthers) {
  const PlaneCheck canonical = FindPlane(CanonicalScene());
  ASSERT_TRUE(canonical.planar) << canonical.reason;
  EXPECT_NEAR(std::abs(canonical.normal.y()), 1, 1e-12);

  Scene tilted = CanonicalScene();
  tilted.fingers[0].normal = Eigen::Vector3d(1, 0.1, 0).normalized();
  EXPECT_FALSE(FindPlane(tilted).planar);
  tilted.model.reduce = Reduce::kPlanar;
  const SimulationResult r = Simulate(tilted);
  EXPECT_EQ(r.status, SimulationStatus::kInvalidScene);
  EXPECT_NE(r.error.find("not planar"), std::string::npos) << r.error;
  EXPECT_TRUE(r.samples.empty());
  tilted.model.reduce = Reduce::kAuto;
  const SimulationResult a = Simulate(tilted);
  EXPECT_EQ(a.status, SimulationStatus::kOk) << a.error;
  EXPECT_EQ(a.model.dof, 6);

  Scene odd = CanonicalScene();
  odd.model.facets = 5;  // no cone edge along the plane
  EXPECT_FALSE(FindPlane(odd).planar);
  Scene six = CanonicalScene();
  six.model.facets = 6;  // fingers: edges at 0 and π from t1 = z, in the plane; but the
  // pusher (n = z, t1 = y out of the plane) would need an edge at π/2.
  EXPECT_FALSE(FindPlane(six).planar);
  EXPECT_NE(FindPlane(six).reason.find("pusher"), std::string::npos) << FindPlane(six).reason;
  six.pusher.reset();
  EXPECT_TRUE(FindPlane(six).planar) << FindPlane(six).reason;

  Scene patch = CanonicalScene();
  patch.fingers[1].type = ContactType::kPatch;
  patch.fingers[1].radius = 0.01;
  EXPECT_FALSE(FindPlane(patch).planar);

  Scene sideways = CanonicalScene();
  sideways.pusher->motion.velocity = {0, 0.01, 0.01};
  EXPECT_FALSE(FindPlane(sideways).planar);

  Scene rotated = CanonicalScene();
  rotated.object.pose.rpy = {0, 0, 0.3};  // y no longer a principal axis
  EXPECT_FALSE(FindPlane(rotated).planar);
  rotated.object.pose.rpy = {0, 0.3, 0};  // turned about the plane normal: still planar
  EXPECT_TRUE(FindPlane(rotated).planar) << FindPlane(rotated).reason;
}

// With the momentum carried, written: with quasi-static steps ("auto") the
// full model drifts out of the plane on the turning pusher (a mode nothing
// holds; quasi_static_test.cpp), which the planar model has not.
void ExpectSameTrajectory(const Scene& scene, const char* what) {
  Scene full = scene, planar = scene;
  full.model.reduce = Reduce::kFull;
  planar.model.reduce = Reduce::kPlanar;
  full.model.inertia = planar.model.inertia = InertiaModel::kCarried;
  const SimulationResult f = Simulate(full);
  const SimulationResult p = Simulate(planar);
  ASSERT_EQ(f.status, SimulationStatus::kOk) << what << ": " << f.error;
  ASSERT_EQ(p.status, SimulationStatus::kOk) << what << ": " << p.error;
  EXPECT_EQ(f.model.dof, 6);
  EXPECT_EQ(p.model.dof, 3);
  EXPECT_LT(p.model.unknowns, f.model.unknowns);
  ASSERT_EQ(f.samples.size(), p.samples.size());
  const double L = 0.1, V = 0.05, F = 20.0;
  double worst = 0;
  for (size_t k = 0; k < f.samples.size(); ++k) {
    const auto& a = f.samples[k];
    const auto& b = p.samples[k];
    worst = std::max(worst, (a.position - b.position).norm() / L);
    worst = std::max(worst, a.orientation.angularDistance(b.orientation));
    worst = std::max(worst, (a.velocity - b.velocity).norm() / V);
    worst = std::max(worst, (a.angular_velocity - b.angular_velocity).norm() * L / V);
    worst = std::max(worst, (a.pusher_force - b.pusher_force).norm() / F);
    for (size_t i = 0; i < a.contacts.size(); ++i) {
      worst =
          std::max(worst, std::abs(a.contacts[i].normal_force - b.contacts[i].normal_force) / F);
      EXPECT_EQ(a.contacts[i].mode, b.contacts[i].mode) << what << " t " << a.t << " contact " << i;
    }
  }
  EXPECT_LT(worst, 1e-9) << what;
}

TEST(FullVersusAuto, CanonicalScene) { ExpectSameTrajectory(CanonicalScene(), "canonical"); }

TEST(FullVersusAuto, HeldAndSlidingObjects) {
  ExpectSameTrajectory(HeldBox(0.2, 10, 0.5), "held");
  ExpectSameTrajectory(HeldBox(3.0, 10, 0.5), "sliding");
  ExpectSameTrajectory(HeldBox(0.2, 10, 0.5, 6), "held, 6 facets");
}

TEST(FullVersusAuto, OffCentrePushTurnsTheObjectInPlane) {
  Scene s = CanonicalScene();
  s.fingers[1].type = ContactType::kPoint;  // two point fingers: free to pivot about y
  s.pusher->position = {0.015, 0, -0.05};
  s.pusher->motion.velocity = {0, 0, 0.02};
  s.duration = 0.5;
  ExpectSameTrajectory(s, "off-centre push");
  const SimulationResult r = Simulate(s);
  EXPECT_GT(std::abs(r.samples.back().angular_velocity.y()), 1e-3);  // it does turn
}

TEST(FullVersusAuto, ObliquePushWithLineFingerAndCylinder) {
  Scene s = CanonicalScene();
  s.object.shape = ObjectShape::kCylinder;
  s.object.radius = 0.025;
  s.object.height = 0.1;
  s.object.pose.rpy = {0, 0.2, 0};
  s.pusher->normal = Eigen::Vector3d(0.3, 0, 1).normalized();
  s.pusher->motion.velocity = {0.004, 0, 0.01};
  s.model.points = 4;
  // Built for the frozen contact frame: the line finger's ends and the
  // pusher's normal are not on (normal to) the tilted cylinder's surface.
  s.model.contacts = ContactTracking::kFixed;
  ExpectSameTrajectory(s, "oblique push");
}

TEST(FullVersusAuto, TurningPusher) {
  Scene s = CanonicalScene();
  s.fingers[1].type = ContactType::kPoint;
  s.pusher->motion.angular_velocity = {0, 0.5, 0};
  s.pusher->type = ContactType::kLine;
  s.pusher->axis = {1, 0, 0};
  s.pusher->length = 0.01;
  ExpectSameTrajectory(s, "turning line pusher");
}

TEST(FullVersusAuto, NoGravityNoPusher) {
  Scene s = HeldBox(0.2, 10, 0.5);
  s.gravity.setZero();
  ExpectSameTrajectory(s, "idle");
}

// Samples at k / 250 s whatever dt is; the pose between steps is exact for
// the piecewise-constant twist.
TEST(Sampling, TwoHundredFiftyHertzForAnyTimeStep) {
  const double mu = 0.5, grip = 10, mass = 2.0, g = 9.81;
  const double a = g - 2 * mu * grip / mass;
  for (double dt : {0.004, 0.003, 0.001, 0.0095}) {
    Scene s = HeldBox(mass, grip, mu);
    s.object.size.z() = 1.0;  // the fingers stay on its faces while it slides 0.22 m
    s.model.dt = dt;
    s.duration = 0.3;
    const SimulationResult r = Simulate(s);
    ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
    ASSERT_EQ(r.samples.size(), 76u) << "dt " << dt;
    for (size_t k = 0; k < r.samples.size(); ++k) {
      const auto& smp = r.samples[k];
      const double t = static_cast<double>(k) / 250.0;
      EXPECT_NEAR(smp.t, t, 1e-15);
      // Step n covers (n dt, (n+1) dt] with velocity -a (n+1) dt.
      const long steps_done = static_cast<long>(std::ceil(t / dt - 1e-9));
      const double v = k == 0 ? 0.0 : -a * steps_done * dt;
      EXPECT_NEAR(smp.velocity.z(), v, 1e-9) << "dt " << dt << " t " << t;
      // Position: sum of earlier steps plus the partial one.
      const long full = k == 0 ? 0 : steps_done - 1;
      const double z =
          -a * dt * dt * full * (full + 1) / 2.0 - a * (full + 1) * dt * (t - full * dt) * (k > 0);
      EXPECT_NEAR(smp.position.z(), z, 1e-12) << "dt " << dt << " t " << t;
    }
  }
}

}  // namespace
}  // namespace arena::mechanics
