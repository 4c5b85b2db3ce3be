// Tracked contacts (issue 12): contact points and normals follow the
// object's surface, contacts are made and lost. Each expected value is
// derived in the comment above its test from the exact geometry.
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/polygon.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "extremes_suite.hpp"
#include "scenes.hpp"

namespace arena::mechanics {
namespace {

using testing::Finger;

const TrajectorySample& At(const SimulationResult& r, double t) {
  const auto k = static_cast<size_t>(std::lround(t * kSampleRateHz));
  EXPECT_LT(k, r.samples.size());
  return r.samples.at(std::min(k, r.samples.size() - 1));
}

// Rotation angle about the gripper's x axis of an orientation that turns
// about x only.
double AngleAboutX(const Eigen::Quaterniond& q) { return 2 * std::atan2(q.x(), q.w()); }

PusherSpec Pusher(ContactType type, Eigen::Vector3d position, Eigen::Vector3d normal,
                  Eigen::Vector3d velocity, double mu) {
  PusherSpec p;
  p.name = "pusher";
  p.type = type;
  p.position = position;
  p.normal = normal;
  p.mu = mu;
  p.motion.velocity = velocity;
  return p;
}

// The pivoting push: a box of width w (y) and height 2h (z) held by
// two point fingers on its x faces through its centre (the pivot axis is x),
// no gravity, a frictionless point pusher under the bottom face at y = d,
// pushing up at v.
Scene PivotScene(double w, double h, double d, double v, double dt) {
  Scene s;
  s.object.shape = ObjectShape::kBox;
  s.object.size = {0.05, w, 2 * h};
  s.object.mass = 0.2;
  s.duration = 1.0;
  s.grip_force = 100.0;  // holds the impulsive start (see validation_test, PivotingPush)
  s.fingers.push_back(Finger("left", ContactType::kPoint, {-0.025, 0, 0}, {1, 0, 0}, 0.5));
  s.fingers.push_back(Finger("right", ContactType::kPoint, {0.025, 0, 0}, {-1, 0, 0}, 0.5));
  s.pusher = Pusher(ContactType::kPoint, {0, d, -h}, {0, 0, 1}, {0, 0, v}, 0.0);
  s.model = {8, 3, dt, Reduce::kAuto, ContactTracking::kTracked};
  return s;
}

// Exact geometry of the pivot. Turned by θ about x, the bottom face's
// outward normal is (0, sin θ, -cos θ) and the face is the plane
// n·p = h. The pusher tip is at (0, d, -h + s) after travel s, so it stays on
// the face when d sin θ - (-h + s) cos θ = h, i.e.
//   s(θ) = h - h / cos θ + d tan θ,   ds/dθ = (d - h sin θ) / cos² θ.
// s grows until sin θ* = d / h, where the frictionless pusher's line of
// force (the face normal through the tip) passes through the pivot axis
// (its torque F (d - h sin θ) / cos θ vanishes); s(θ*) = h (1 - cos θ*) is
// the most travel that pure turning can absorb.
double Travel(double theta, double h, double d) {
  return h - h / std::cos(theta) + d * std::tan(theta);
}
// θ(s) on the rising branch, by Newton from the small-angle guess s / d.
double AngleAtTravel(double s, double h, double d) {
  double theta = s / d;
  const double stall = std::asin(d / h);
  theta = std::min(theta, stall);
  for (int i = 0; i < 60; ++i) {
    const double f = Travel(theta, h, d) - s;
    const double df = (d - h * std::sin(theta)) / std::pow(std::cos(theta), 2);
    if (df <= 0) break;
    theta = std::min(theta - f / df, stall);
  }
  return theta;
}

// Up to 90 % of the stall angle the pusher accelerates the object's turning
// (ω = v cos²θ / (d - h sin θ) grows), so it keeps contact and the object
// follows the geometric θ(s) to first order in dt. The frozen model turns at
// v / d instead: at 3° that is 15 % short. Beyond the stall no turning can
// absorb more travel: the pusher's force passes the axis, the fingers slide
// and the object translates, so the angle stays near θ* (the overshoot is
// the turning that the fingers' friction stops) instead of the frozen
// model's v t / d (34° after 6 mm).
TEST(TrackedPivot, AngleFollowsExactGeometryThroughTheStall) {
  const double w = 0.03, h = 0.05, d = 0.01, v = 0.01, dt = 0.0005;
  const double stall = std::asin(d / h);  // 11.5°
  Scene s = PivotScene(w, h, d, v, dt);
  s.duration = 0.6;
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  double worst = 0;
  for (const auto& sample : r.samples) {
    const double exact = AngleAtTravel(v * sample.t, h, d);
    if (exact > 0.9 * stall) break;
    const double got = AngleAboutX(sample.orientation);
    worst = std::max(worst, std::abs(got - exact));
    ASSERT_TRUE(sample.contacts[2].touching || sample.t == 0) << "t " << sample.t;
  }
  EXPECT_LT(worst, 2e-3) << "largest angle error before the stall (rad)";
  // Near 3° the frozen model is more than 10 % short; the tracked one within 0.5 %.
  const double t3 = At(r, Travel(3 * std::numbers::pi / 180, h, d) / v).t;
  const double exact3 = AngleAtTravel(v * t3, h, d);
  EXPECT_NEAR(AngleAboutX(At(r, t3).orientation), exact3, 0.005 * exact3);
  Scene fixed = s;
  fixed.model.contacts = ContactTracking::kFixed;
  const SimulationResult rf = Simulate(fixed);
  ASSERT_EQ(rf.status, SimulationStatus::kOk) << rf.error;
  EXPECT_NEAR(AngleAboutX(At(rf, t3).orientation), v * t3 / d, 1e-9);
  EXPECT_LT(AngleAboutX(At(rf, t3).orientation), 0.9 * exact3);
  // Through the stall: after 6 mm the angle is near θ*, not v t / d.
  const double end = AngleAboutX(r.samples.back().orientation);
  EXPECT_GT(end, 0.9 * stall);
  EXPECT_LT(end, 1.5 * stall) << "frozen model: " << AngleAboutX(rf.samples.back().orientation);
  EXPECT_GT(AngleAboutX(rf.samples.back().orientation), 0.5);
  for (const auto& sample : r.samples) {
    ASSERT_TRUE(sample.position.allFinite());
    ASSERT_TRUE(sample.pusher_force.allFinite());
  }
}

// The frictionless pusher on the turned bottom face pushes along the face's
// inward normal (0, -sin θ, cos θ), not along its own +z. A sample splits
// that force along the scene's normal for the pusher (+z): normal_force is
// its z component and tangential_force the rest, so that normal_force · n +
// tangential_force, the vector the store and every export rebuild, is the
// force applied (it used to be the magnitude along the face normal with no
// tangential part: a vertical force of the right size).
// Carried steps: turning the object about the grip axis takes a force only
// to accelerate it (no gravity), so balanced (quasi-static) steps have none
// to rebuild.
TEST(TrackedPivot, AContactsForceRebuiltAlongTheScenesNormalIsTheForceApplied) {
  const double w = 0.03, h = 0.05, d = 0.01, v = 0.01, dt = 0.0005;
  Scene s = PivotScene(w, h, d, v, dt);
  s.model.inertia = InertiaModel::kCarried;
  s.duration = 0.1;
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  const TrajectorySample& last = r.samples.back();
  const double theta = AngleAboutX(last.orientation);
  ASSERT_GT(theta, 0.08);  // turned some 5°: the face normal is well off +z
  const ContactState& pusher = last.contacts[2];
  const Eigen::Vector3d rebuilt =
      pusher.normal_force * Eigen::Vector3d::UnitZ() + pusher.tangential_force;
  const double scale = last.pusher_force.norm();
  ASSERT_GT(scale, 1e-3);
  EXPECT_LT((rebuilt - last.pusher_force).norm(), 1e-9 * scale);
  EXPECT_LT(std::abs(pusher.tangential_force.z()), 1e-9 * scale);
  // The sample's force is the last step's, solved at the pose one step
  // before the one it reports: the face has turned ω dt ≈ 3e-3 rad since
  // (ω = v cos²θ / (d - h sin θ) ≈ 6.5 rad/s as the stall nears), against
  // the sin θ > 0.08 a vertical force would be off.
  const Eigen::Vector3d face_inward(0, -std::sin(theta), std::cos(theta));
  EXPECT_LT((last.pusher_force / scale - face_inward).norm(), 1e-2);
}

// dt convergence on a 30° pivot (w = 8 cm, d = 3 cm: θ* = 36.9°). With
// carried steps the error of the angle against θ(s) at the travel where it
// is 30° falls at least in proportion to dt (first order: semi-implicit
// Euler with the gap linearised over one step). Balanced steps (the
// default on a held object) place the contacts where the step ends, so the
// angle is on θ(s) at every dt: no dt error to converge.
TEST(TrackedPivot, ConvergesAtFirstOrderOnAThirtyDegreePivot) {
  const double w = 0.08, h = 0.05, d = 0.03, v = 0.01;
  const double target = 30 * std::numbers::pi / 180;
  const double t = std::round(Travel(target, h, d) / v * kSampleRateHz) / kSampleRateHz;
  const double exact = AngleAtTravel(v * t, h, d);
  ASSERT_NEAR(exact, target, 0.01);
  for (InertiaModel inertia : {InertiaModel::kCarried, InertiaModel::kAuto}) {
    std::vector<double> errors;
    for (double dt : {0.004, 0.002, 0.001, 0.0005}) {
      Scene s = PivotScene(w, h, d, v, dt);
      s.model.inertia = inertia;
      s.duration = t + 0.004;
      const SimulationResult r = Simulate(s);
      ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
      errors.push_back(std::abs(AngleAboutX(At(r, t).orientation) - exact));
    }
    if (inertia == InertiaModel::kAuto) {
      for (size_t i = 0; i < errors.size(); ++i) EXPECT_LT(errors[i], 1e-9) << "dt index " << i;
      continue;
    }
    for (size_t i = 0; i + 1 < errors.size(); ++i) {
      const double order = std::log2(errors[i] / errors[i + 1]);
      EXPECT_GE(order, 0.9) << "dt halving " << i << ": errors " << errors[i] << " -> "
                            << errors[i + 1];
    }
    EXPECT_LT(errors.back(), 0.01 * target);
  }
}

// A held box slides down between two point fingers near its top (z_f =
// h - Δ): with m g > 2 μ N it slides at a = g - 2 μ N / m, so the fingers
// reach the top edge after t_e = sqrt(2 Δ / a); their pads then pass the
// edge, touch nothing, and the box falls freely: v(t) = -a t_e - g (t -
// t_e). The fixed model keeps the fingers' frames and holds on to air; its
// prediction is flagged as having left the grasp geometry.
TEST(TrackedGrasp, SlidesUntilTheFingersPassTheEdgeThenLetsGo) {
  const double mu = 0.5, grip = 10.0, g = 9.81, h = 0.05, delta = 0.005, dt = 0.0005;
  const double mass = 2 * (2 * mu * grip / g);
  const double a = g - 2 * mu * grip / mass;  // g / 2
  const double te = std::sqrt(2 * delta / a);
  Scene s = testing::HeldBox(mass, grip, mu);
  s.fingers[0].position.z() = h - delta;
  s.fingers[1].position.z() = h - delta;
  s.model.dt = dt;
  s.duration = 0.1;
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_EQ(r.grasp, GraspStatus::kLost);
  EXPECT_NEAR(r.grasp_changed_t, te, 3 * dt);
  EXPECT_NE(r.grasp_note.find("left"), std::string::npos) << r.grasp_note;
  for (const auto& sample : r.samples) {
    if (sample.t == 0) continue;
    if (sample.t < te - 3 * dt) {
      EXPECT_NEAR(sample.velocity.z(), -a * sample.t, 1e-9 * g) << "t " << sample.t;
      EXPECT_TRUE(sample.contacts[0].touching && sample.contacts[1].touching);
      // The finger's contact point climbs the face in the object frame.
      EXPECT_NEAR(sample.contacts[0].point.z(), h - delta + a * sample.t * sample.t / 2, 1e-3 * h)
          << "t " << sample.t;
    } else if (sample.t > te + 3 * dt) {
      EXPECT_NEAR(sample.velocity.z(), -a * te - g * (sample.t - te), 3 * g * dt)
          << "t " << sample.t;
      EXPECT_FALSE(sample.contacts[0].touching || sample.contacts[1].touching);
      EXPECT_EQ(sample.contacts[0].normal_force, 0.0);
    }
  }
  Scene fixed = s;
  fixed.model.contacts = ContactTracking::kFixed;
  const SimulationResult rf = Simulate(fixed);
  ASSERT_EQ(rf.status, SimulationStatus::kOk) << rf.error;
  EXPECT_EQ(rf.grasp, GraspStatus::kLeftGeometry);
  // Frozen: slides at a throughout; flagged once the points are 1 % of the
  // extent (1 mm) beyond the edge: Δ + 1 mm = a t² / 2.
  EXPECT_NEAR(rf.samples.back().velocity.z(), -a * rf.samples.back().t, 1e-9 * g);
  EXPECT_NEAR(rf.grasp_changed_t, std::sqrt(2 * (delta + 1e-3) / a), 2 * dt);
}

// A patch pusher (disk of radius R, normal +z) under a box turned by α about
// the fingers' axis touches only the box's lowest edge: the edge crosses the
// disk along a chord, so the pad acts as a line there, its constituent
// points on the chord, its force along the disk's normal (frictionless).
// Two point fingers hold the box on an axis (gripper x) c = 2 cm below its
// centre, so gravity tips it away from upright and keeps it on the pusher
// (the push itself only ever decelerates the turning). Relative to the
// axis the lowest edge is at (y, z) = (-w/2, -h') in the box, h' = h - c;
// turned by θ it is at height z_e(θ) = -(w/2) sin θ - h' cos θ, which the
// rising disk sets to z_e(α) + v t:
//   ρ sin(θ + φ) = -(z_e(α) + v t),  ρ = |(w/2, h')|, φ = atan2(h', w/2),
// until the face lands flat on the disk at θ = 0 (the test stops at 80 %).
TEST(TrackedPatch, PatchPusherOnATiltedFaceActsAsALine) {
  const double w = 0.03, h = 0.05, c = 0.02, hp = h - c;
  const double alpha = 10 * std::numbers::pi / 180, v = 0.002, R = 0.01, dt = 0.0005;
  Scene s = testing::HeldBox(0.2, 10.0, 0.5);
  s.object.pose.rpy = {alpha, 0, 0};
  s.object.pose.position = {0, -c * std::sin(alpha), c * std::cos(alpha)};
  s.model.points = 4;
  s.model.dt = dt;
  s.model.reduce = Reduce::kFull;
  const double ze0 = -(w / 2) * std::sin(alpha) - hp * std::cos(alpha);
  const double ye0 = -(w / 2) * std::cos(alpha) + hp * std::sin(alpha);
  s.pusher = Pusher(ContactType::kPatch, {0, ye0, ze0}, {0, 0, 1}, {0, 0, v}, 0.0);
  s.pusher->radius = R;
  const double land = -ze0 - hp;  // travel at which the face lands flat
  s.duration = std::floor(0.8 * land / v * kSampleRateHz) / kSampleRateHz;
  ValidateScene(s);
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  const double rho = std::hypot(w / 2, hp), phi = std::atan2(hp, w / 2);
  double worst = 0;
  for (const auto& sample : r.samples) {
    const double exact = std::asin(-(ze0 + v * sample.t) / rho) - phi;
    worst = std::max(worst, std::abs(AngleAboutX(sample.orientation) - exact));
    const ContactState& p = sample.contacts[2];
    ASSERT_TRUE(p.touching) << "t " << sample.t;
    EXPECT_EQ(p.touching_points, 4) << "t " << sample.t;  // all on the chord
    // On the edge (the force splits along the chord in any way that the
    // rigid fingers balance, so its centre is anywhere on the chord).
    EXPECT_NEAR(p.point.y(), -w / 2, 1e-9);
    EXPECT_NEAR(p.point.z(), -h, 1e-9);
    EXPECT_LE(std::abs(p.point.x()), R + 1e-9);
    // Frictionless, along the disk's normal (not the tilted face's).
    ASSERT_GT(sample.pusher_force.norm(), 0) << "t " << sample.t;
    EXPECT_NEAR(sample.pusher_force.normalized().z(), 1.0, 1e-12);
  }
  EXPECT_LT(worst, 1e-3);
  EXPECT_GT(AngleAboutX(r.samples.back().orientation), 0.0);
}

// Rotating and translating the whole scene (object pose, contacts, motion)
// by one rigid transform gives the same motion relative to it. The pivot is
// used, since its fingers stick well inside their cones and its pusher is
// frictionless, so the gripper-fixed cone discretisation plays no role.
TEST(TrackedScene, RigidTransformOfTheWholeSceneGivesTheSameRelativeAnswer) {
  Scene s = PivotScene(0.03, 0.05, 0.01, 0.01, 0.002);
  s.duration = 0.08;
  s.model.reduce = Reduce::kFull;
  const Eigen::Vector3d rpy0(0.3, -0.2, 0.5), T(0.1, -0.05, 0.2);
  const Eigen::Matrix3d R0 = RotationFromRpy(rpy0);
  Scene m = s;
  m.object.pose.position = R0 * s.object.pose.position + T;
  m.object.pose.rpy = rpy0;  // R0 * identity
  for (auto& f : m.fingers) {
    f.position = R0 * f.position + T;
    f.normal = R0 * f.normal;
  }
  m.pusher->position = R0 * s.pusher->position + T;
  m.pusher->normal = R0 * s.pusher->normal;
  m.pusher->motion.velocity = R0 * s.pusher->motion.velocity;
  ValidateScene(m);
  const SimulationResult a = Simulate(s), b = Simulate(m);
  ASSERT_EQ(a.status, SimulationStatus::kOk) << a.error;
  ASSERT_EQ(b.status, SimulationStatus::kOk) << b.error;
  ASSERT_EQ(a.samples.size(), b.samples.size());
  const Eigen::Quaterniond Q0(R0);
  ASSERT_GT(AngleAboutX(a.samples.back().orientation), 0.05);
  for (size_t i = 0; i < a.samples.size(); ++i) {
    const auto& x = a.samples[i];
    const auto& y = b.samples[i];
    EXPECT_LT((R0.transpose() * (y.position - T) - x.position).norm(), 1e-9 * 0.1);
    EXPECT_LT((Q0.inverse() * y.orientation).angularDistance(x.orientation), 1e-9);
    EXPECT_LT((R0.transpose() * y.pusher_force - x.pusher_force).norm(), 1e-9 * 10);
    for (size_t c = 0; c < x.contacts.size(); ++c) {
      EXPECT_LT((y.contacts[c].point - x.contacts[c].point).norm(), 1e-9 * 0.1);
      EXPECT_EQ(y.contacts[c].touching, x.contacts[c].touching);
    }
  }
}

// The fixed mode is today's model: its results do not depend on the object's
// shape beyond the inertia, and the canonical scene gives 2 μ N + m g in both
// modes (a straight push moves no contact over the surface).
TEST(TrackedScene, CanonicalPushIsTheSameInBothModes) {
  for (ContactTracking mode : {ContactTracking::kTracked, ContactTracking::kFixed}) {
    Scene s = testing::CanonicalScene();
    s.model.contacts = mode;
    const SimulationResult r = Simulate(s);
    ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
    EXPECT_NEAR(r.samples.back().pusher_force.z(), 10.0 + 0.2 * 9.81, 1e-9);
    EXPECT_NEAR(r.samples.back().position.z(), 0.01, 1e-12);
    EXPECT_EQ(r.grasp, GraspStatus::kHeld);
    for (const auto& c : r.samples.back().contacts) EXPECT_TRUE(c.touching);
  }
}

// A sphere pusher (point with a radius) pushing straight up on the bottom
// face is the canonical push: 2 μ N + m g, the object moving with it, its
// contact point at the sphere's bottom-face touch point.
TEST(TrackedScene, SpherePusherPushesLikeAPoint) {
  Scene s = testing::CanonicalScene();
  s.pusher->radius = 0.005;
  ValidateScene(s);
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_NEAR(r.samples.back().pusher_force.z(), 10.0 + 0.2 * 9.81, 1e-9);
  EXPECT_NEAR(r.samples.back().position.z(), 0.01, 1e-12);
  EXPECT_LT((r.samples.back().contacts[2].point - Eigen::Vector3d(0, 0, -0.05)).norm(), 1e-9);
}

// Any object pose: the fingers close on the object where it is. A box
// shifted 3 mm along x and turned 5° about z: the fingers' pads travel along
// their closing directions onto the turned faces, whose normals are no
// longer ±x; a point finger's force is along its face's normal, so the two
// grip forces no longer pass through one line and the box turns towards
// alignment; nothing is NaN and the grasp holds.
TEST(TrackedScene, FingersCloseOnAnObjectAtAnyPose) {
  Scene s = testing::HeldBox(0.2, 10.0, 0.5);
  s.gravity.setZero();
  s.object.pose.position = {0.003, 0, 0};
  s.object.pose.rpy = {0, 0, 5 * std::numbers::pi / 180};
  s.duration = 0.1;
  EXPECT_THROW(ValidateScene(s), SceneError);  // the planned contacts are off its faces
  SeatFingers(&s);
  ValidateScene(s);
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_EQ(r.grasp, GraspStatus::kHeld) << r.grasp_note;
  const auto& first = r.samples.front();
  for (const auto& c : first.contacts) {
    EXPECT_TRUE(c.touching);
    // On the x faces (object frame) of the 5 cm box.
    EXPECT_NEAR(std::abs(c.point.x()), 0.025, 1e-9);
  }
  for (const auto& sample : r.samples) ASSERT_TRUE(sample.position.allFinite());
}

// Prisms: a hexagon of circumradius ρ has area (3√3/2) ρ² and the moment
// of inertia about its axis m (5/12) ρ²; a non-convex polygon is a valid
// outline, a self-intersecting one is refused naming a vertex.
TEST(Prism, MassPropertiesAndPolygonChecks) {
  const double rho = 0.03, m = 0.3, hgt = 0.05;
  ObjectSpec o;
  o.shape = ObjectShape::kPrism;
  o.height = hgt;
  o.mass = m;
  for (int i = 0; i < 6; ++i) {
    const double a = i * std::numbers::pi / 3;
    o.polygon.emplace_back(rho * std::cos(a) + 0.01, rho * std::sin(a));
  }
  const Eigen::Matrix3d I = ObjectInertia(o);
  EXPECT_NEAR(I(2, 2), m * 5.0 / 12.0 * rho * rho, 1e-12);
  EXPECT_NEAR(I(0, 0), m * (5.0 / 24.0 * rho * rho + hgt * hgt / 12), 1e-12);
  EXPECT_NEAR(I(0, 1), 0, 1e-15);
  Scene s = testing::HeldBox(0.2, 10.0, 0.5);
  s.object = o;
  s.fingers[0].position = {-rho * std::sqrt(3) / 2, 0, 0};
  s.fingers[1].position = {rho * std::sqrt(3) / 2, 0, 0};
  // A hexagon has vertices, not faces, at ±x: turn it by 30° about z.
  s.object.pose.rpy = {0, 0, std::numbers::pi / 6};
  s.object.pose.position = {-0.01 * std::cos(std::numbers::pi / 6), -0.005, 0};
  ValidateScene(s);
  const SimulationResult r = Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  // A dented hexagon is simple: a valid (non-convex) prism outline.
  std::vector<Eigen::Vector2d> dented = s.object.polygon;
  dented[3] = {0.01, 0.0};
  EXPECT_FALSE(polygon::CheckSimple(dented).has_value());
  EXPECT_FALSE(polygon::IsConvex(dented));
  // Swapping two vertices makes it cross itself: refused naming a vertex.
  Scene bad = s;
  std::swap(bad.object.polygon[1], bad.object.polygon[4]);
  try {
    ValidateScene(bad);
    FAIL() << "a self-intersecting polygon was accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field().rfind("object.polygon[", 0), 0u) << e.what();
  }
}

// Edges: a pusher exactly on the bottom face's edge, a finger pad exactly on
// the edge of its face, a pusher grazing along the face (touching and not
// every step), and a pusher that turns the box through 90°: each is solved
// or fails with the typed error, never NaN.
TEST(TrackedEdges, GrazingOnEdgeAndQuarterTurnNeverNaN) {
  std::vector<std::pair<std::string, Scene>> cases;
  {
    Scene s = testing::CanonicalScene();
    s.pusher->position = {0, 0.015, -0.05};  // on the edge
    cases.emplace_back("pusher on the edge", s);
  }
  {
    Scene s = testing::HeldBox(0.2, 10.0, 0.5);
    s.fingers[0].position = {-0.025, 0.015, 0};  // on the face's edge
    s.fingers[1].position = {0.025, 0.015, 0};
    s.pusher = Pusher(ContactType::kPoint, {0, 0, -0.05}, {0, 0, 1}, {0, 0.01, 0}, 0.3);
    cases.emplace_back("pads on the edge, pusher grazing the face", s);
  }
  {
    Scene s = PivotScene(0.03, 0.05, 0.012, 0.2, 0.002);
    s.pusher->mu = 1.0;  // sticks: carries the corner round
    s.duration = 0.6;
    cases.emplace_back("quarter turn", s);
  }
  for (const auto& [name, s] : cases) {
    const SimulationResult r = Simulate(s);
    EXPECT_TRUE(r.status == SimulationStatus::kOk || r.status == SimulationStatus::kSolverFailure)
        << name;
    for (const auto& sample : r.samples) {
      ASSERT_TRUE(sample.position.allFinite()) << name;
      ASSERT_TRUE(sample.velocity.allFinite()) << name;
      ASSERT_TRUE(sample.pusher_force.allFinite()) << name;
      for (const auto& c : sample.contacts) ASSERT_TRUE(c.point.allFinite()) << name;
    }
    EXPECT_TRUE(std::isfinite(r.residuals.force_balance)) << name;
    if (name == "quarter turn") {
      // The pusher carries the corner round: the bottom face turns through
      // 90°, the pusher loses it (make and break) and meets a side face later.
      double most = 0;
      bool lost = false, again = false;
      for (const auto& sample : r.samples) {
        most = std::max(
            most, std::abs(std::remainder(AngleAboutX(sample.orientation), 2 * std::numbers::pi)));
        if (!sample.contacts[2].touching) lost = true;
        if (lost && sample.contacts[2].touching) again = true;
      }
      EXPECT_GT(most, std::numbers::pi / 2) << name;
      EXPECT_TRUE(lost && again) << name;
    }
  }
}

// Contact onset: a pusher that starts 1 mm below the face reaches it at
// t = 0.1 s and must bring the object to its speed. With rigid bodies that
// takes an impulse (m v plus the fingers' friction over the step), so the
// force in the onset step is impulse / dt; the impulse stays bounded as dt
// shrinks and no step adds a gap correction on top (force · dt ≤ m v + 2 μ
// N dt + m g dt within 1 %).
TEST(TrackedEdges, ImpulseAtContactOnsetStaysBoundedAsDtShrinks) {
  const double v = 0.01;
  for (double dt : {0.004, 0.001, 0.00025}) {
    Scene s = testing::CanonicalScene();
    s.pusher->position.z() -= 0.001;
    s.model.dt = dt;
    s.duration = 0.2;
    ContactModel model(s);
    ASSERT_EQ(model.status(), SimulationStatus::kOk) << model.error();
    double worst = 0;
    const int steps = static_cast<int>(std::lround(s.duration / dt));
    for (int i = 0; i < steps; ++i) {
      ASSERT_TRUE(model.Step().ok) << "dt " << dt << " step " << i;
      worst = std::max(worst, model.pusher_force().norm() * dt);
    }
    const double bound = 0.2 * v + (2 * 0.5 * 10.0 + 0.2 * 9.81) * dt;
    EXPECT_LE(worst, 1.01 * bound) << "dt " << dt;
    EXPECT_NEAR(model.velocity().z(), v, 1e-9);
  }
}

// Issue 12, item 7: line fingers, 2 N grip, a pusher 10 mm off the finger
// axis pushing 10 mm. At coarse settings (facets 8, points 3, dt 4 ms) the
// frozen-frame model spun the object through 145° and dropped it 39 mm,
// while the cell's 16 / 5 / 2 ms turned it 5°. Why: in both runs the pusher
// needs nearly all of its friction (|f_y| / f_z ≈ 0.27 of μ = 0.3) to keep
// its contact point from sliding as the object turns; the coarse run crosses
// the cone at t = 0.36 s, the fine one never does. Once the pusher slides,
// its frozen 10 mm arm applies about 3.5 N × 0.01 m = 0.035 N m about the
// finger axis, more than the line fingers' torsional friction can resist
// (2 × μ N × 0.01 m = 0.02 N m), and in a frozen frame nothing shortens that
// arm: the object spins up, its finger friction turns from holding the
// weight (2 μ N = 2.0 N against m g = 1.96 N) to resisting the spin, and it
// falls. (Energy falls throughout: no numerical energy is injected.) With
// tracked contacts the contact point slides over the tilting face and the
// arm shrinks, so the coarse setting is merely less accurate; the frozen
// run is flagged as having left the grasp geometry.
TEST(CoarseSettings, TrackedStaysNearTheFineAnswerAndTheFrozenRunawayIsFlagged) {
  Scene s = testing::CanonicalScene();
  for (auto& f : s.fingers) {
    f.type = ContactType::kLine;
    f.axis = {0, 0, 1};
    f.length = 0.02;
  }
  s.grip_force = 2.0;
  s.pusher->position = {0, 0.01, -0.05};
  auto turn = [](const SimulationResult& r) {
    return std::abs(AngleAboutX(r.samples.back().orientation));
  };
  Scene fine = s;
  fine.model = {16, 5, 0.002, Reduce::kAuto, ContactTracking::kTracked};
  const SimulationResult rf = Simulate(fine);
  ASSERT_EQ(rf.status, SimulationStatus::kOk) << rf.error;
  const SimulationResult rc = Simulate(s);  // 8 / 3 / 4 ms
  ASSERT_EQ(rc.status, SimulationStatus::kOk) << rc.error;
  EXPECT_LT(turn(rf), 0.15);
  EXPECT_LT(std::abs(turn(rc) - turn(rf)), 0.05) << turn(rc) << " vs " << turn(rf);
  EXPECT_LT((rc.samples.back().position - rf.samples.back().position).norm(), 0.003);
  EXPECT_EQ(rc.grasp, GraspStatus::kHeld) << rc.grasp_note;
  // The runaway was found with rigid pads (the default before issue 31):
  // the line fingers' undetermined load split let the solver put the whole
  // torsional friction on one end point.
  Scene frozen = s;
  frozen.model.contacts = ContactTracking::kFixed;
  frozen.model.pads = PadModel::kRigid;
  const SimulationResult rz = Simulate(frozen);
  ASSERT_EQ(rz.status, SimulationStatus::kOk) << rz.error;
  EXPECT_GT(turn(rz), 1.0);  // the runaway, reproduced
  EXPECT_EQ(rz.grasp, GraspStatus::kLeftGeometry) << rz.grasp_note;
  // With elastic pads (the default) the frozen frame at coarse settings stays
  // near the fine tracked answer and in the grasp (measured 0.0859 rad
  // against the fine run's turn).
  Scene frozen_elastic = s;
  frozen_elastic.model.contacts = ContactTracking::kFixed;
  const SimulationResult re = Simulate(frozen_elastic);
  ASSERT_EQ(re.status, SimulationStatus::kOk) << re.error;
  EXPECT_LT(std::abs(turn(re) - turn(rf)), 0.05) << turn(re) << " vs " << turn(rf);
  EXPECT_EQ(re.grasp, GraspStatus::kHeld) << re.grasp_note;
}

}  // namespace
}  // namespace arena::mechanics
