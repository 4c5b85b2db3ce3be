// The simulators room: the `arena` simulator is mechanics::Simulate at its
// settings; the `mujoco` simulator passes the closed-form checks that the
// contact model passes (mechanics/validation_test.cpp), within the
// tolerances soft contact allows (written next to each check and in
// simulators/README.md).
#include <cmath>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/simulators/simulator.hpp"
#include "mechanics/scenes.hpp"

namespace arena::simulators {
namespace {

using mechanics::ContactMode;
using mechanics::ContactType;
using mechanics::Scene;
using mechanics::SimulationStatus;
using mechanics::testing::HeldBox;

mechanics::PusherSpec PusherBelow(double offset_y, double speed, double mu) {
  mechanics::PusherSpec p;
  p.name = "pusher";
  p.type = ContactType::kPoint;
  p.position = {0, offset_y, -0.05};
  p.normal = {0, 0, 1};
  p.mu = mu;
  p.motion.velocity = {0, 0, speed};
  return p;
}

double Roll(const mechanics::TrajectorySample& s) {
  const Eigen::Vector3d y = s.orientation * Eigen::Vector3d::UnitY();
  return std::atan2(y.z(), y.y());
}

TEST(ArenaSimulator, IsTheContactModelAtItsSettings) {
  Scene s = HeldBox(0.2, 10, 0.5);
  s.pusher = PusherBelow(0.01, 0.02, 0.3);
  s.duration = 0.1;
  ArenaSettings settings;
  settings.facets = 16;
  settings.dt = 0.002;
  const auto sim = MakeArenaSimulator(settings);
  EXPECT_EQ(sim->name(), "arena");
  EXPECT_EQ(sim->truth(), TruthKind::kSelfConsistency);
  Scene direct = s;
  direct.model.facets = 16;
  direct.model.dt = 0.002;
  const auto a = sim->Simulate(s);
  const auto b = mechanics::Simulate(direct);
  ASSERT_EQ(a.status, SimulationStatus::kOk);
  ASSERT_EQ(a.samples.size(), b.samples.size());
  EXPECT_EQ(a.samples.back().position, b.samples.back().position);
  EXPECT_EQ(a.model.facets, 16);
  // at_least: a scene asking for finer settings keeps them.
  settings.at_least = true;
  s.model.facets = 32;
  EXPECT_EQ(MakeArenaSimulator(settings)->Simulate(s).model.facets, 32);
}

TEST(SimulatorFactory, NamesAndSettingsAreChecked) {
  EXPECT_EQ(MakeSimulator("arena")->name(), "arena");
  EXPECT_EQ(MakeSimulator("mujoco", R"({"timestep": 0.001})")->name(), "mujoco");
  try {
    MakeSimulator("bullet");
    FAIL();
  } catch (const SimulatorError& e) {
    EXPECT_EQ(e.field(), "simulator");
  }
  try {
    MakeSimulator("mujoco", R"({"timestep": -1})");
    FAIL();
  } catch (const SimulatorError& e) {
    EXPECT_EQ(e.field(), "mujoco.timestep");
  }
  try {
    MakeSimulator("mujoco", R"({"timestpe": 0.001})");
    FAIL();
  } catch (const SimulatorError& e) {
    EXPECT_EQ(e.field(), "mujoco.timestpe");
  }
  EXPECT_THROW(MakeSimulator("mujoco", R"({"cone": "round"})"), SimulatorError);
  EXPECT_THROW(MakeSimulator("arena", R"({"facets": 2})"), SimulatorError);
}

TEST(MujocoModel, HasExplicitPairsCoupledFingersAndPads) {
  Scene s = HeldBox(0.2, 10, 0.5);
  s.fingers[1].type = ContactType::kPatch;
  s.fingers[1].radius = 0.006;
  s.pusher = PusherBelow(0, 0.01, 0.3);
  s.pusher->type = ContactType::kLine;
  s.pusher->axis = {1, 0, 0};
  s.pusher->length = 0.02;
  const std::string xml = MujocoModelXml(s, MujocoSettings{});
  EXPECT_NE(xml.find("cone=\"elliptic\""), std::string::npos);
  EXPECT_NE(xml.find("<pair geom1=\"pad0_0\" geom2=\"object\""), std::string::npos);
  EXPECT_EQ(xml.find("name=\"pad0_1\""), std::string::npos);               // point: one sphere
  EXPECT_NE(xml.find("<pair geom1=\"pad1_5\""), std::string::npos);        // patch: 6 on the ring
  EXPECT_NE(xml.find("<pair geom1=\"pusher_pad_4\""), std::string::npos);  // line: 5
  EXPECT_NE(xml.find("polycoef=\"0 1 0 0 0\""), std::string::npos);
  EXPECT_EQ(xml.find("type=\"capsule\""), std::string::npos);  // spheres only
  EXPECT_EQ(xml.find("contype=\"1\""), std::string::npos);     // no implicit contacts
}

// Held box: two point fingers, 10 N, μ 0.5, 0.2 kg (m g = 1.96 N < 2 μ N = 10 N).
//   Each finger carries m g / 2 upward; normal forces equal the grip.
// Soft contact sinks a little while the contact forces build up (~2·timeconst):
// tolerance 0.05 mm over 0.5 s, forces 1 %.
TEST(MujocoClosedForm, HeldBoxStays) {
  Scene s = HeldBox(0.2, 10, 0.5);
  s.duration = 0.5;
  const auto r = MakeMujocoSimulator({})->Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  ASSERT_EQ(r.samples.size(), 126u);
  const auto& last = r.samples.back();
  EXPECT_LT(last.position.norm(), 5e-5);
  EXPECT_LT(last.velocity.norm(), 1e-4);
  for (int f = 0; f < 2; ++f) {
    EXPECT_NEAR(last.contacts[f].normal_force, 10.0, 0.1);
    EXPECT_NEAR(last.contacts[f].tangential_force.z(), 0.2 * 9.81 / 2, 0.02);
    EXPECT_EQ(last.contacts[f].mode, ContactMode::kStick);
  }
}

// Sliding push: the pusher under the bottom face pushes +z at 1 cm/s; the box
// slides up between the fingers, so the pusher force is 2 μ N + m g
// = 2·0.5·10 + 0.2·9.81 = 11.962 N. Soft contact (impratio 10, elliptic cone):
// 0.5 %. The box follows the pusher: 0.1 mm after 0.4 s.
TEST(MujocoClosedForm, SlidingPushForce) {
  Scene s = HeldBox(0.2, 10, 0.5);
  s.pusher = PusherBelow(0, 0.01, 0.3);
  s.duration = 0.4;
  const auto r = MakeMujocoSimulator({})->Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  const auto& last = r.samples.back();
  EXPECT_NEAR(last.pusher_force.z(), 11.962, 0.06);
  EXPECT_NEAR(last.position.z(), 0.004, 1e-4);
  EXPECT_EQ(last.contacts[0].mode, ContactMode::kSlide);
  EXPECT_EQ(last.contacts[1].mode, ContactMode::kSlide);
  EXPECT_EQ(last.contacts[2].mode, ContactMode::kStick);
}

// Pivoting push (no gravity): point fingers on the x axis with μ = 2 (sliding
// would need 40 N), a frictionless pusher d = 1 cm off the axis pushing +z.
// The box can only pivot about the fingers' axis while the pusher slides
// along its bottom face (h = 5 cm from the axis; the pad is a sphere of
// r = 1 mm, H = h + r). The pad centre, pushed z up, stays on the face:
//     d sinθ + (H - z) cosθ = H   ->   θ = φ - acos(H / ρ),
//     ρ = sqrt(d² + (H - z)²), φ = atan2(d, H - z)        (the smaller root)
// until z reaches H - sqrt(H² - d²) (~1 mm): then no rotation makes room, the
// box stalls at asin(d / H') and slides up over the fingers, H' = H - Δz_box.
// Soft-contact tolerance: 0.01 rad while pivoting (penetration, damping lag;
// checked up to 0.6 mm of push: near the stall dθ/dz diverges and tens of µm
// of penetration move θ by more), 0.005 rad at the stall. arena's contact model (contact frames
// fixed in the gripper frame) agrees at the start and turns the same way.
double PivotAngle(double d, double H, double z) {
  const double rho = std::hypot(d, H - z);
  return std::atan2(d, H - z) - std::acos(std::min(1.0, H / rho));
}

TEST(MujocoClosedForm, PivotingPushFollowsTheGeometryAndStalls) {
  Scene s = HeldBox(0.2, 10, 2.0);
  s.gravity = Eigen::Vector3d::Zero();
  s.pusher = PusherBelow(0.01, 0.01, 0.0);
  s.duration = 0.5;
  const auto r = MakeMujocoSimulator({})->Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  const double d = 0.01, H = 0.051;
  for (double t : {0.02, 0.04, 0.06}) {
    const auto& sample = r.samples.at(static_cast<size_t>(std::lround(t * 250)));
    EXPECT_NEAR(Roll(sample), PivotAngle(d, H, 0.01 * t), 0.01) << "t " << t;
    EXPECT_LT(std::abs(sample.position.z()), 2e-4) << "t " << t;  // pivots, does not slide
  }
  const auto& last = r.samples.back();
  EXPECT_GT(last.position.z(), 0.002);  // stalled: slides up over the fingers
  EXPECT_NEAR(Roll(last), std::asin(d / (H - last.position.z())), 0.005);
  EXPECT_GT(last.contacts[2].normal_force, 0);  // the pusher still pushes
  Scene m = s;
  m.duration = 0.02;
  const auto model = mechanics::Simulate(m);
  ASSERT_EQ(model.status, SimulationStatus::kOk);
  EXPECT_GT(Roll(r.samples[5]) * Roll(model.samples.back()), 0)
      << "turns the other way than arena's model";
}

// Settings that differ only in <option> share a cached model (the options
// written into it, the data reset): every run gives the trajectory of a fresh
// build to the last bit, whichever setting used the model before, and a
// scene with another gravity or geometry gets its own model.
TEST(MujocoModelCache, ReusedModelsGiveTheFreshTrajectories) {
  Scene a = HeldBox(0.2, 10, 0.5);
  a.pusher = PusherBelow(0.005, 0.01, 0.3);
  a.duration = 0.06;
  Scene b = a;
  b.gravity = {0, 0, -5};
  MujocoSettings coarse;
  coarse.timestep = 0.002;
  coarse.noslip_iterations = 0;
  MujocoSettings fine;  // defaults: 0.5 ms, elliptic, noslip 10
  MujocoSettings pyramidal = coarse;
  pyramidal.elliptic = false;
  pyramidal.impratio = 1;
  auto same = [](const mechanics::SimulationResult& x, const mechanics::SimulationResult& y) {
    if (x.status != y.status || x.samples.size() != y.samples.size()) return false;
    for (std::size_t i = 0; i < x.samples.size(); ++i) {
      const auto &p = x.samples[i], &q = y.samples[i];
      if (p.position != q.position || p.orientation.coeffs() != q.orientation.coeffs() ||
          p.velocity != q.velocity || p.pusher_force != q.pusher_force)
        return false;
      for (std::size_t c = 0; c < p.contacts.size(); ++c) {
        if (p.contacts[c].normal_force != q.contacts[c].normal_force ||
            p.contacts[c].tangential_force != q.contacts[c].tangential_force ||
            p.contacts[c].mode != q.contacts[c].mode)
          return false;
      }
    }
    return true;
  };
  const auto cache = MakeMujocoModelCache(1);
  for (const MujocoSettings* st : {&coarse, &fine, &pyramidal, &coarse}) {
    for (const Scene* scene : {&a, &b, &a}) {
      const auto fresh = MakeMujocoSimulator(*st)->Simulate(*scene);
      ASSERT_EQ(fresh.status, SimulationStatus::kOk) << fresh.error;
      const auto cached = MakeMujocoSimulator(*st, cache)->Simulate(*scene);
      EXPECT_TRUE(same(fresh, cached)) << "timestep " << st->timestep << " elliptic "
                                       << st->elliptic << " gravity " << scene->gravity.z();
    }
  }
}

TEST(MujocoSimulator, NeverReturnsNaNAndReportsTheEngine) {
  const auto sim = MakeMujocoSimulator({});
  EXPECT_EQ(sim->truth(), TruthKind::kIndependent);
  EXPECT_NE(sim->settings_json().find("MuJoCo 2."), std::string::npos);
  Scene s = HeldBox(0.2, 10, 0.5);
  s.object.shape = mechanics::ObjectShape::kCylinder;
  s.object.radius = 0.025;
  s.object.height = 0.1;
  s.duration = 0.1;
  const auto r = sim->Simulate(s);
  ASSERT_EQ(r.status, SimulationStatus::kOk) << r.error;
  for (const auto& sample : r.samples) ASSERT_TRUE(sample.position.allFinite());
  EXPECT_LT(r.samples.back().position.norm(), 1e-4);
}

}  // namespace
}  // namespace arena::simulators
