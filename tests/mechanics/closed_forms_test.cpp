// Issue 31's scenes against their closed forms at the default settings
// (since issue 31: elastic pads, the aligned cone, "auto" inertia, which is
// quasi-static on these held objects), each option's share of the answer,
// and what the old defaults (rigid pads, the polyhedral cone, carried
// momentum, set explicitly) get wrong on them.
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <utility>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "issue31_scenes.hpp"

namespace arena::mechanics {
namespace {

using issue31::kBox;
using issue31::kPointFingers;
using issue31::Parse;
using issue31::Roll;
using issue31::SimulateOk;

// A central push from below on two 4-point patches without a stiffness,
// with gravity: by symmetry no roll, and the patches slide with their full
// friction, so the pusher carries the weight and both pads' friction:
// 2 μ N + m g = 11.962 N. Rigid pads (the old default) split their load at a
// vertex the solver picked: 0.18 rad of roll, the force 9.5 % low.
TEST(ClosedForms, CentralPushOnPatchesDoesNotRoll) {
  const Scene scene = issue31::CentralPushOnPatches("auto");
  Scene elastic = scene;  // the defaults
  Scene rigid = scene;
  rigid.model.pads = PadModel::kRigid;
  rigid.model.cone = ConeModel::kPolyhedral;
  const SimulationResult r = SimulateOk(elastic);
  const double expected = 2 * 0.5 * 10.0 + 0.2 * 9.81;
  double worst_angle = 0;
  for (const TrajectorySample& s : r.samples)
    worst_angle = std::max(worst_angle, Eigen::AngleAxisd(s.orientation).angle());
  std::printf("central: worst angle %.3g rad, pusher force %.6f N (expected %.6f)\n", worst_angle,
              r.samples.back().pusher_force.z(), expected);
  EXPECT_LT(worst_angle, 1e-6);
  EXPECT_NEAR(r.samples.back().pusher_force.z(), expected, 1e-6 * expected);
  // Deterministic: a second run, after another scene ran in between, is
  // identical.
  const SimulationResult old = SimulateOk(rigid);
  double rigid_angle = 0;
  for (const TrajectorySample& s : old.samples)
    rigid_angle = std::max(rigid_angle, Eigen::AngleAxisd(s.orientation).angle());
  EXPECT_GT(rigid_angle, 0.01) << "the undetermined rigid split this scene measures";
  const SimulationResult again = SimulateOk(elastic);
  EXPECT_EQ(again.samples.back().position, r.samples.back().position);
}

// A run of `steps` model steps at the scene's settings, counting the aligned
// cones' re-solves; `ok` false (with the reason added as a failure) when the
// scene is refused or a step fails.
struct AlignedRun {
  bool ok = false;
  long resolves = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  double roll = 0;  // about x, for a turn about the grip axis
};
AlignedRun RunCountingResolves(const Scene& scene, int steps) {
  AlignedRun run;
  ContactModel m(scene);
  if (m.status() != SimulationStatus::kOk) {
    ADD_FAILURE() << m.error();
    return run;
  }
  for (int k = 0; k < steps; ++k) {
    const StepReport step = m.Step();
    if (!step.ok) {
      ADD_FAILURE() << "step " << k << ": " << step.error;
      return run;
    }
    run.resolves += step.align_solves;
  }
  run.ok = true;
  run.position = m.position();
  run.roll = 2 * std::atan2(m.orientation().x(), m.orientation().w());
  return run;
}

// A push tilted by φ = 30° in the y-z plane, through the grip axis, with no
// gravity: the pusher's contact sticks, moment balance about the grip axis
// keeps the contact force through the axis, so the object turns with the
// direction of the pusher seen from the axis. With the pusher at (0, -h)
// from the axis and moving by v t (sin φ, cos φ):
//   θ(T) = atan2(v sin φ T, h - v cos φ T) = 0.054686 rad at T = 0.5 s,
// and the centre of mass, which the object carries around the axis, at
// (-0.233, 4.255) mm in (y, z).
TEST(ClosedForms, TiltedPushTurnsWithThePusherSeenFromTheAxis) {
  const Scene scene = Parse(issue31::TiltedPushBody());
  Scene aligned = scene;
  aligned.model.cone = ConeModel::kAligned;
  // Carried (with quasi-static steps: AlignedQuasiStaticStepsFollowBothClosedForms).
  aligned.model.inertia = InertiaModel::kCarried;
  Scene polyhedral = scene;  // the default cone before issue 31, carried
  polyhedral.model.cone = ConeModel::kPolyhedral;
  polyhedral.model.inertia = InertiaModel::kCarried;
  const SimulationResult r = SimulateOk(aligned);
  const double theta = issue31::TiltedPushRoll();
  const TrajectorySample& last = r.samples.back();
  std::printf("tilted: roll %.6f rad (expected %.6f), com (%.4f, %.4f) mm\n", Roll(last), theta,
              1e3 * last.position.y(), 1e3 * last.position.z());
  // The aligned cone, re-solved within the step until the fingers' slip
  // opposes their friction (AlignCones), brings this from 56 % too far (the
  // facets steered the fingers' slip) to 0.07 %, at 4, 8, 16 and 64 facets
  // alike; lagging the alignment by one step (the first version) left
  // 2.9 %, the edge flipping from side to side of the slip. The facets no
  // longer matter: 0.054709-0.054725 rad at 4, 8, 16 and 64 facets (the
  // polyhedral cone: 0.1293, 0.0854, 0.0683, 0.0564).
  EXPECT_NEAR(Roll(last), theta, 0.01 * theta);
  EXPECT_NEAR(last.position.y(), -0.233e-3, 0.01e-3);
  EXPECT_NEAR(last.position.z(), 4.255e-3, 0.01e-3);
  EXPECT_LT(std::abs(last.position.x()), 1e-6) << "the scene is symmetric about x = 0";
  for (int facets : {4, 16, 64}) {
    Scene other = aligned;
    other.model.facets = facets;
    EXPECT_NEAR(Roll(SimulateOk(other).samples.back()), theta, 0.01 * theta) << facets;
  }
  const SimulationResult p = SimulateOk(polyhedral);
  EXPECT_GT(Roll(p.samples.back()), 1.5 * theta) << "the steered slip this scene measures";
  // At the default dt, 4 ms, the fingers' friction is fixed by the balance
  // (the pusher sticks, the object's inertia over dt is 4 times smaller):
  // the slip swings across a whole facet for a turn of the edge far below
  // 1e-3 rad and the friction lands on a face of the cone. Turned onto the
  // friction's own direction there, the cone settles in about 1.6 re-solves
  // per step: 0.054662-0.054667 rad at 4, 8 and 16 facets, 0.054753 rad
  // (+0.12 %) at 64, where faces two steps running are pinned. (Turned
  // onto the slip, every re-solve of every step missed by ±π/8 at 8
  // facets: 1500 re-solves in 125 steps and 0.053704 rad, −1.8 %.)
  for (int facets : {4, 8, 16, 64}) {
    Scene coarse = aligned;
    coarse.model.facets = facets;
    coarse.model.dt = 0.004;
    const AlignedRun run = RunCountingResolves(coarse, 125);
    ASSERT_TRUE(run.ok) << facets;
    std::printf("tilted at dt 4 ms, %d facets: roll %.6f rad, %ld re-solves\n", facets, run.roll,
                run.resolves);
    EXPECT_NEAR(run.roll, theta, 2e-3 * theta) << facets;
    EXPECT_LE(run.resolves, 2 * 125) << facets;
  }
}

// A push tilted by φ = 30° towards the grip axis x, through the centre of
// mass, with free point pads and no gravity: the pads follow the object
// along x (no force along x but the pusher's), the fingers slide along z
// with friction μ N each, and the pusher (μ 0.3) sticks: the force needed
// along x is 0, along z 2 μ N = 10 N, tan⁻¹(0/10) inside the pusher's cone.
// So the object moves with the pusher, x(T) = v sin φ T = 1.000 mm and
// z(T) = v cos φ T = 1.732 mm at T = 0.2 s, and nothing turns it (the force
// passes through the centre of mass, the finger forces act on the grip
// axis). Carrying momentum, the start impulse leaves the object drifting
// along x and pitching: 11 % too far. Quasi-static steps follow the path.
TEST(ClosedForms, PushAlongTheGripAxisFollowsThePusherWithoutPitch) {
  Scene scene = Parse(std::string(kBox) + R"(,"gravity":[0,0,0],"duration":0.2,)" +
                      R"("grip_force":10.0,)" + kPointFingers +
                      R"(,"model":{"facets":8,"points":3,"dt":0.001,"reduce":"auto",)"
                      R"("cone":"aligned","inertia":"quasi_static"},)"
                      R"("pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],)"
                      R"("mu":0.3,"motion":{"velocity":[0.004999999999999999,0,)"
                      R"(0.008660254037844387],"angular_velocity":[0,0,0]}})");
  const SimulationResult r = SimulateOk(scene);
  const TrajectorySample& last = r.samples.back();
  const double angle = Eigen::AngleAxisd(last.orientation).angle();
  std::printf("grip axis: x %.4f mm, z %.4f mm, angle %.3g rad\n", 1e3 * last.position.x(),
              1e3 * last.position.z(), angle);
  EXPECT_NEAR(last.position.x(), 1.000e-3, 0.01e-3);
  EXPECT_NEAR(last.position.z(), 1.732e-3, 0.01732e-3);
  EXPECT_LT(angle, 1e-3);
  scene.model.inertia = InertiaModel::kCarried;
  const SimulationResult carried = SimulateOk(scene);
  EXPECT_GT(carried.samples.back().position.x(), 1.05e-3) << "the drift this scene measures";
}

// Two 4-point patches (radius 10 mm) hold the box against gravity with
// nothing else: each pad's friction can carry μ N along the weight (t1 = z
// is a cone edge, so the octagonal cone holds exactly μ N there), so the
// holding limit is m* g = 2 μ N, m* = 2 · 0.5 · 10 / 9.81 = 1.0194 kg. At
// 0.95 m* the box stays; at 1.05 m* it slides down with the closed-form
// acceleration a = g − 2 μ N / m. On the old defaults (rigid pads, the
// solver's vertex) the 0.95 m* grasp dropped (0.0297 m/s down at 0.2 s)
// and the 1.05 m* one slid 39 % too fast (0.1303 m/s against 0.0934).
TEST(ClosedForms, PatchGraspHoldsBelowItsLimitAndDropsAbove) {
  const double mu = 0.5, grip = 10.0, g = 9.81, limit = 2 * mu * grip / g;
  for (double ratio : {0.95, 1.05}) {
    const double mass = ratio * limit;
    char object[200];
    std::snprintf(object, sizeof object,
                  R"("object":{"shape":"box","size":[0.05,0.03,0.1],"mass":%.17g,)"
                  R"("pose":{"position":[0,0,0],"rpy":[0,0,0]}})",
                  mass);
    const Scene scene = Parse(
        std::string(object) + R"(,"gravity":[0,0,-9.81],"duration":0.2,"grip_force":10.0,)" +
        issue31::kPatchFingers + R"(,"model":{"facets":8,"points":4,"dt":0.001,"reduce":"auto"})");
    const SimulationResult r = SimulateOk(scene);
    const TrajectorySample& last = r.samples.back();
    const double expected_vz = ratio < 1 ? 0.0 : -(g - 2 * mu * grip / mass) * last.t;
    std::printf("patch grasp at %.2f of its limit: vz %.6f m/s (expected %.6f)\n", ratio,
                last.velocity.z(), expected_vz);
    EXPECT_NEAR(last.velocity.z(), expected_vz, 0.01 * std::abs(expected_vz) + 1e-9) << ratio;
    EXPECT_LT(Eigen::AngleAxisd(last.orientation).angle(), 1e-6) << ratio;
    Scene rigid = scene;
    rigid.model.pads = PadModel::kRigid;
    rigid.model.cone = ConeModel::kPolyhedral;
    const double old_vz = SimulateOk(rigid).samples.back().velocity.z();
    std::printf("  old defaults: vz %.6f m/s\n", old_vz);
    EXPECT_LT(old_vz, ratio < 1 ? -0.01 : 1.2 * expected_vz) << "the wrong split this measures";
  }
}

// The issue's pivot past its stall with the momentum carried and the
// aligned cone: the fingers slide while the object rocks about the
// quasi-static path, and from solve to solve their slip jumps across the
// whole fan of the vertex their friction sits on (it missed by exactly
// ±π/8 at 8 facets) when the friction turns by less than 1e-3 rad. The
// re-solves stop once no cone would turn by more than 1e-3 rad (the
// friction's direction is then right within it), and a friction that
// comes back to a face at the direction it was just turned onto, or in the
// step after, is left there (pinned: MeasureAlignMiss): 109 re-solves in
// the 600 steps at 8 facets, 26 at 32. Before, until the slip's miss was below 1e-3 rad, which it
// never was: 5966 (497 steps at the cap of 12).
TEST(ClosedForms, CarriedPivotAlignsWithinBoundedResolves) {
  const Scene scene = issue31::PivotPastStall(R"("cone":"aligned","inertia":"carried")");
  for (int facets : {8, 32}) {
    Scene s = scene;
    s.model.facets = facets;
    const AlignedRun run = RunCountingResolves(s, 600);
    ASSERT_TRUE(run.ok) << facets;
    std::printf("carried pivot, aligned cone, %d facets: %ld re-solves, y %.4f mm\n", facets,
                run.resolves, 1e3 * run.position.y());
    EXPECT_LE(run.resolves, 150) << facets;  // 109 at 8 facets (367 pinning within a step only)
    // The sideways slide in the grasp, against the polyhedral cone at 64
    // facets (its slip steered by at most 1/64 of a turn): y −1.007 mm; the
    // aligned cone −1.009 mm at 8 facets, −0.969 at 32 (turned onto the slip
    // rather than the friction, −0.57 mm at 8).
    EXPECT_NEAR(run.position.y(), -1.007e-3, 0.05e-3) << facets;
  }
  {
    Scene fine = scene;
    fine.model.cone = ConeModel::kPolyhedral;
    fine.model.facets = 64;
    const SimulationResult r = SimulateOk(fine);
    std::printf("carried pivot, polyhedral cone, 64 facets: y %.4f mm\n",
                1e3 * r.samples.back().position.y());
    EXPECT_NEAR(r.samples.back().position.y(), -1.007e-3, 0.005e-3);
  }
}

// Aligned cones with quasi-static steps, on both of issue 31's scenes that
// need them together (a slip in a free direction, a mode nothing damps):
// the tilted push through the grip axis, θ(T) = 0.054686 rad, and the
// pivot past its stall, atan(d/(h − vT)) = 0.22348 rad, at every facets and
// dt. Each balance keeps its cones, which turn between balances onto the
// balanced slip, and a damper across the aligned edge (the circular cone to
// first order) chooses the slip within the vertex's fan (model.cpp,
// BalanceAligned, SetSlipDampers). Every finger's friction stays within its
// cone, |f_t| <= μ N, at every sample: a damper whose coefficient came from
// a slower slip, or kept into a carried step, once pushed it 0.6 % and 22 %
// of μ N across the edge. Before: refused on 6-DOF scenes, because
// the cones turned inside every solve of a balance threw the tilted push
// metres out of its grasp (at dt 2 ms: the object at 8.35 m/s after its
// third step, passed as reachable because the lost fingers' grip still
// counted in the reach).
// The largest |f_t| / (μ N) of the two point fingers (μ 0.5) over a run.
double WorstFrictionShare(const SimulationResult& r) {
  double worst = 0;
  for (const TrajectorySample& sample : r.samples) {
    for (size_t i = 0; i < 2 && i < sample.contacts.size(); ++i) {
      const ContactState& c = sample.contacts[i];
      if (c.normal_force > 0)
        worst = std::max(worst, c.tangential_force.norm() / (0.5 * c.normal_force));
    }
  }
  return worst;
}

// A held box pushed through its centre of mass on a face, no gravity,
// along y or along z (the fingers' tangent plane; a push there off the
// face's normal would turn the box about the grip axis): the box moves with
// the pusher, both point fingers slide, each resisting with its full μ N
// opposite the slip, so the pusher force is 2 μ N = 10 N along the push.
// With quasi-static steps each finger's slip damper acts across the edge
// its friction sits on. Across the first edge (t1 = z) whatever the slip, a
// slide along y, an edge of the basis the cone never turns from at 4, 8,
// 12 and 16 facets, had a damper along its slip and was resisted with
// 20 N; at 3 and 6 facets y lies on a face and the cone turns.
TEST(ClosedForms, AFingerSlidingAlongAnyEdgeResistsWithItsFullFriction) {
  const Eigen::Vector3d y(0, 1, 0), z(0, 0, 1);
  for (const auto& [u, reach] : {std::pair{y, 0.015}, std::pair{z, 0.05}}) {
    for (int facets : {3, 4, 6, 8, 12, 16}) {
      for (const char* inertia : {"quasi_static", "carried"}) {
        Scene s = Parse(std::string(kBox) + R"(,"gravity":[0,0,0],"duration":0.1,)" +
                        R"("grip_force":10.0,)" + kPointFingers +
                        R"(,"model":{"reduce":"full","cone":"aligned","inertia":")" + inertia +
                        R"("},"pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],)"
                        R"("mu":0.3,"motion":{"velocity":[0,0,0]}})");
        s.model.facets = facets;
        s.pusher->position = -reach * u;
        s.pusher->normal = u;
        s.pusher->motion.velocity = 0.01 * u;
        const SimulationResult r = SimulateOk(s);
        if (r.samples.empty()) continue;
        const TrajectorySample& last = r.samples.back();
        const std::string what = std::string(u == y ? "along y, " : "along z, ") +
                                 std::to_string(facets) + " facets, " + inertia;
        // A turned cone opposes the slip within 1e-3 rad (kAlignMiss): the
        // force across the push and the object's drift within that share.
        EXPECT_NEAR(last.pusher_force.dot(u), 10.0, 1e-6) << what;
        EXPECT_LT((last.pusher_force - last.pusher_force.dot(u) * u).norm(), 1e-3 * 10.0) << what;
        EXPECT_LT((last.velocity - 0.01 * u).norm(), 1e-3 * 0.01) << what;
        EXPECT_LE(WorstFrictionShare(r), 1 + 1e-5) << what;
      }
    }
  }
}

TEST(ClosedForms, AlignedQuasiStaticStepsFollowBothClosedForms) {
  const double tilted_roll = issue31::TiltedPushRoll();
  for (double dt : {0.0005, 0.001, 0.002, 0.004}) {
    for (int facets : {4, 8, 16, 32, 64}) {
      Scene s = Parse(issue31::TiltedPushBody());
      s.model.cone = ConeModel::kAligned;
      s.model.inertia = InertiaModel::kQuasiStatic;
      s.model.dt = dt;
      s.model.facets = facets;
      const SimulationResult r = SimulateOk(s);
      if (r.samples.empty()) continue;
      const double roll = Roll(r.samples.back());
      std::printf("tilted, aligned, quasi-static, dt %g, %d facets: roll %.6f (%+.4f %%)\n", dt,
                  facets, roll, 100 * (roll / tilted_roll - 1));
      EXPECT_NEAR(roll, tilted_roll, 1e-3 * tilted_roll) << dt << " " << facets;  // 0.05-0.08 %
      EXPECT_FALSE(r.steered_slip.detected) << dt << " " << facets;
      EXPECT_FALSE(r.oscillation.detected) << dt << " " << facets;
      EXPECT_LE(WorstFrictionShare(r), 1 + 1e-5) << dt << " " << facets;
    }
  }
  // The pivot: its roll at every facets and dt up to 2 ms; its slide along y
  // in the grasp (no closed form) the same at every facets, −1.083 mm,
  // where the polyhedral cone's quasi-static steps steer it to −1.95 mm at 8
  // facets and −1.24 at 64.
  const double pivot_roll = issue31::PivotPastStallRoll();
  for (double dt : {0.0005, 0.001, 0.002}) {
    for (int facets : {4, 8, 16, 32, 64}) {
      Scene s = issue31::PivotPastStall(R"("cone":"aligned","inertia":"quasi_static")");
      s.model.dt = dt;
      s.model.facets = facets;
      const SimulationResult r = SimulateOk(s);
      if (r.samples.empty()) continue;
      const TrajectorySample& last = r.samples.back();
      std::printf(
          "pivot, aligned, quasi-static, dt %g, %d facets: roll %.6f, y %.4f mm, |f_t|/(mu N) "
          "at most 1 + %.2g\n",
          dt, facets, Roll(last), 1e3 * last.position.y(), WorstFrictionShare(r) - 1);
      EXPECT_NEAR(Roll(last), pivot_roll, 1e-5) << dt << " " << facets;
      EXPECT_NEAR(last.position.y(), -1.083e-3, 0.005e-3) << dt << " " << facets;
      EXPECT_FALSE(r.oscillation.detected) << dt << " " << facets;
      EXPECT_LE(WorstFrictionShare(r), 1 + 1e-5) << dt << " " << facets;
    }
  }
  for (const auto& [facets, y] : {std::pair{8, -1.950e-3}, std::pair{64, -1.240e-3}}) {
    Scene s = issue31::PivotPastStall(R"("cone":"polyhedral","inertia":"quasi_static")");
    s.model.facets = facets;
    const SimulationResult r = SimulateOk(s);
    std::printf("pivot, polyhedral, quasi-static, %d facets: y %.4f mm\n", facets,
                1e3 * r.samples.back().position.y());
    EXPECT_NEAR(r.samples.back().position.y(), y, 0.01e-3) << "the steering this measures";
  }
  // At dt 4 ms the pivot finds no balance at step 25 while the pusher
  // presses (the polyhedral cone's quasi-static steps leave the grasp
  // there): "quasi_static" is refused naming model.inertia (it mixed
  // carried steps into balanced ones, "ok", rocking), and "auto" turns
  // carried from that step on: the carried steps rock, and the output says
  // so.
  Scene coarse = issue31::PivotPastStall(R"("cone":"aligned","inertia":"quasi_static")");
  coarse.model.dt = 0.004;
  const SimulationResult refused = Simulate(coarse);
  EXPECT_EQ(refused.status, SimulationStatus::kSolverFailure);
  EXPECT_NE(refused.error.find("model.inertia"), std::string::npos) << refused.error;
  coarse.model.inertia = InertiaModel::kAuto;
  const SimulationResult rocking = SimulateOk(coarse);
  EXPECT_EQ(rocking.model.inertia, InertiaModel::kCarried);
  EXPECT_EQ(rocking.solver.quasi_static_carried, 1);
  EXPECT_TRUE(rocking.oscillation.detected);
  // Within 0.2 % here (1.00196 at its worst sample; not traced further: the
  // run is flagged), where a damper kept into its carried steps gave 22 %.
  EXPECT_LE(WorstFrictionShare(rocking), 1.003);
  // "auto" is quasi-static for this held object: the same answer.
  Scene automatic = issue31::PivotPastStall(R"("cone":"aligned","inertia":"auto")");
  const SimulationResult a = SimulateOk(automatic);
  EXPECT_EQ(a.model.inertia, InertiaModel::kQuasiStatic);
  EXPECT_NEAR(Roll(a.samples.back()), pivot_roll, 1e-5);
}

// A slipping grasp: a 1.5 kg box held by two point fingers (grip 10 N,
// μ 0.5: 2 μ N = 10 N, below its weight 14.7 N) under gravity tilted by
// α = 20° from -z towards -y, nothing else. Gravity and both fingers'
// friction act through the centre of mass (the fingers on the grip axis x),
// so nothing turns it; friction opposes the slip, and the net tangential
// load is along gravity from rest on: on the circular cone the box slides
// straight along gravity's direction, α = 20° from -z in the y-z plane,
// whatever the facets. The polyhedral cone steers it towards its edges:
// 25.49° at 4 facets, 20.43° at 8, 18.79° at 16, 19.97° at 64. The aligned
// cone: 20.0000° at all four, and the same speed at all four.
TEST(ClosedForms, SlippingGraspSlidesAlongTheNetTangentialLoad) {
  const double alpha = 20.0 * std::numbers::pi / 180, g = 9.81;
  char gravity[120];
  std::snprintf(gravity, sizeof gravity, R"("gravity":[0,%.17g,%.17g],)", -g * std::sin(alpha),
                -g * std::cos(alpha));
  const Scene scene = Parse(
      R"("object":{"shape":"box","size":[0.05,0.03,0.1],"mass":1.5,"pose":{"position":[0,0,0],)"
      R"("rpy":[0,0,0]}},)" +
      std::string(gravity) + R"("duration":0.2,"grip_force":10.0,)" + kPointFingers +
      R"(,"model":{"facets":8,"points":3,"dt":0.001,"reduce":"full","cone":"aligned",)"
      R"("inertia":"carried"})");
  double speed8 = 0;
  for (int facets : {8, 4, 16, 64}) {
    Scene s = scene;
    s.model.facets = facets;
    const TrajectorySample last = SimulateOk(s).samples.back();
    const double direction = std::atan2(-last.velocity.y(), -last.velocity.z());
    std::printf("slipping grasp, %d facets: %.4f deg, %.6f m/s\n", facets,
                direction * 180 / std::numbers::pi, last.velocity.norm());
    EXPECT_NEAR(direction, alpha, 1.0 * std::numbers::pi / 180) << facets;  // the target: 1°
    // What it does: within 3e-4 rad at 4 facets (a step's re-solves stop once
    // the slip is within 3e-3 rad of opposing the friction and the friction
    // would turn by less than 1e-3), below 1e-4 at 8 to 64.
    EXPECT_NEAR(direction, alpha, facets == 4 ? 3e-4 : 1e-4) << facets;
    if (facets == 8) speed8 = last.velocity.norm();
    EXPECT_NEAR(last.velocity.norm(), speed8, 0.01 * speed8) << facets;
    EXPECT_LT(std::abs(last.position.x()), 1e-4) << facets;
  }
  Scene polyhedral = scene;
  polyhedral.model.cone = ConeModel::kPolyhedral;
  polyhedral.model.facets = 4;
  const TrajectorySample p = SimulateOk(polyhedral).samples.back();
  EXPECT_GT(std::atan2(-p.velocity.y(), -p.velocity.z()), alpha + 0.05)
      << "the steered slip this scene measures";
}

// A centred push on point fingers, under gravity, started 3 mrad off plane
// (the pose a cell measures, so 6 DOF), with carried steps (the cones'
// turns within a step, measured before issue 31 made "auto" the default
// inertia): the fingers slide almost along an
// edge of the tangent basis (z), where the aligned cone snaps onto that
// edge. The polyhedral cone steers the slip: roll at 0.2 s 0.0244 rad at 8
// facets, 0.0152 at 16, 0.0065 at 64, first order in 1/facets towards
// about 0.0036 (Richardson from 16 and 64). The aligned cone gives 0.0032
// at 8 and 32 facets, settling in about one re-solve per step. (Its stop
// rule once waited for the slip's miss on such a point while the snap
// undid every turn: all 12 re-solves on every step, 486 in 50.)
TEST(ClosedForms, AlignedConeSettlesOnAnEdgeOfTheBasis) {
  const Scene scene =
      Parse(R"("object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{)"
            R"("position":[0.0002,-0.0003,0.0001],"rpy":[0.003,-0.002,0.001]}},)"
            R"("gravity":[0,0,-9.81],"duration":0.2,"grip_force":8.0,)" +
            std::string(kPointFingers) +
            R"(,"pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],"mu":0.3,)"
            R"("motion":{"velocity":[0,0,0.02],"angular_velocity":[0,0,0]}},)"
            R"("model":{"facets":8,"points":3,"dt":0.004,"reduce":"auto","cone":"aligned",)"
            R"("inertia":"carried"})");
  const auto roll_of = [](const Scene& s) { return Roll(SimulateOk(s).samples.back()); };
  Scene polyhedral = scene;
  polyhedral.model.cone = ConeModel::kPolyhedral;
  polyhedral.model.facets = 16;
  const double p16 = roll_of(polyhedral);
  polyhedral.model.facets = 64;
  const double p64 = roll_of(polyhedral);
  const double limit = p64 + (p64 - p16) / 3;
  for (int facets : {8, 32}) {
    Scene s = scene;
    s.model.facets = facets;
    const AlignedRun run = RunCountingResolves(s, 50);
    ASSERT_TRUE(run.ok) << facets;
    std::printf(
        "tilted start, aligned, %d facets: roll %.6f (polyhedral limit %.6f), %ld re-solves\n",
        facets, run.roll, limit, run.resolves);
    EXPECT_NEAR(run.roll, limit, 5e-4) << facets;
    EXPECT_LE(run.resolves, 2 * 50) << facets;
  }
  polyhedral.model.facets = 8;
  EXPECT_GT(roll_of(polyhedral), 5 * limit) << "the steered slip this scene measures";
}

// Issue 31's four scenes exactly as filed (no "cone", no "inertia": the
// defaults, the aligned cone and "auto") meet their closed forms within
// 1 %, at the filed facets and dt and at others: the central push on rigid-less
// patches (no roll, 2 μ N + m g), the tilted push (θ(T) = atan2(v sin φ T, h − v cos φ T); the
// pusher's contact point stuck to the object, so the centre of mass at
// p(T) − R(θ)(0, 0, −h): y = v sin φ T − h sin θ, z = v cos φ T − h (1 − cos θ)),
// the pivot past its stall (atan(d/(h − v T)), settled, not swinging) and
// the push along the grip axis (x = v sin φ T, z = v cos φ T, no pitch).
TEST(ClosedForms, IssueScenesAsFiledMeetTheirClosedFormsAtTheDefaults) {
  const std::string central =
      R"({"object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{"position":[0,0,0],"rpy":[0,0,0]}},"gravity":[0,0,-9.81],"duration":0.2,"grip_force":10.0,"fingers":[{"name":"left","type":"patch","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5,"radius":0.01},{"name":"right","type":"patch","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5,"radius":0.01}],"model":{"facets":8,"points":4,"dt":0.001,"reduce":"auto"},"pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],"mu":0.0,"motion":{"velocity":[0,0,0.01],"angular_velocity":[0,0,0]}}})";
  const std::string tilted =
      R"({"object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{"position":[0,0,0],"rpy":[0,0,0]}},"gravity":[0,0,0],"duration":0.2,"grip_force":10.0,"fingers":[{"name":"left","type":"point","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5},{"name":"right","type":"point","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5}],"model":{"facets":8,"points":3,"dt":0.001,"reduce":"auto"},"pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],"mu":0.3,"motion":{"velocity":[0,0.004999999999999999,0.008660254037844387],"angular_velocity":[0,0,0]}}})";
  const std::string pivot =
      R"({"object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{"position":[0,0,0],"rpy":[0,0,0]}},"gravity":[0,0,0],"duration":0.6,"grip_force":1000.0,"fingers":[{"name":"left","type":"point","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5},{"name":"right","type":"point","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5}],"model":{"facets":8,"points":3,"dt":0.001,"reduce":"auto"},"pusher":{"type":"point","position":[0,0.01,-0.05],"normal":[0,0,1],"mu":0.0,"motion":{"velocity":[0,0,0.01],"angular_velocity":[0,0,0]}}})";
  const std::string grip_axis =
      R"({"object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{"position":[0,0,0],"rpy":[0,0,0]}},"gravity":[0,0,0],"duration":0.2,"grip_force":10.0,"fingers":[{"name":"left","type":"point","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5},{"name":"right","type":"point","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5}],"model":{"facets":8,"points":3,"dt":0.001,"reduce":"auto"},"pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],"mu":0.3,"motion":{"velocity":[0.004999999999999999,0,0.008660254037844387],"angular_velocity":[0,0,0]}}})";
  const double v = 0.01, h = 0.05, phi = std::numbers::pi / 6;
  for (const auto& [facets, dt] :
       {std::pair{8, 0.001}, std::pair{32, 0.001}, std::pair{8, 0.002}, std::pair{8, 0.0005}}) {
    const auto run = [&](const std::string& text) {
      Scene s = ParseScene(text);
      s.model.facets = facets;
      s.model.dt = dt;
      return SimulateOk(s);
    };
    const std::string at = std::to_string(facets) + " facets, dt " + std::to_string(dt);
    {
      const SimulationResult r = run(central);
      if (r.samples.empty()) continue;
      EXPECT_LT(Eigen::AngleAxisd(r.samples.back().orientation).angle(), 1e-6) << at;
      EXPECT_NEAR(r.samples.back().pusher_force.z(), 11.962, 0.01 * 11.962) << at;
    }
    {
      const SimulationResult r = run(tilted);
      if (r.samples.empty()) continue;
      const TrajectorySample& last = r.samples.back();
      const double T = last.t;
      const double theta = std::atan2(v * std::sin(phi) * T, h - v * std::cos(phi) * T);
      const double y = v * std::sin(phi) * T - h * std::sin(theta);
      const double z = v * std::cos(phi) * T - h * (1 - std::cos(theta));
      std::printf("tilted as filed, %s: roll %.6f (%.6f), com (%.4f, %.4f) mm (%.4f, %.4f)\n",
                  at.c_str(), Roll(last), theta, 1e3 * last.position.y(), 1e3 * last.position.z(),
                  1e3 * y, 1e3 * z);
      EXPECT_NEAR(Roll(last), theta, 0.01 * theta) << at;
      EXPECT_NEAR(last.position.y(), y, 0.01 * std::hypot(y, z)) << at;
      EXPECT_NEAR(last.position.z(), z, 0.01 * std::hypot(y, z)) << at;
      EXPECT_FALSE(r.steered_slip.detected) << at;
    }
    {
      const SimulationResult r = run(pivot);
      if (r.samples.empty()) continue;
      const TrajectorySample& last = r.samples.back();
      const double roll = std::atan(0.01 / (h - v * last.t));
      std::printf("pivot as filed, %s: roll %.6f (%.6f)\n", at.c_str(), Roll(last), roll);
      EXPECT_NEAR(Roll(last), roll, 0.01 * roll) << at;
      EXPECT_FALSE(r.oscillation.detected) << at;
    }
    {
      const SimulationResult r = run(grip_axis);
      if (r.samples.empty()) continue;
      const TrajectorySample& last = r.samples.back();
      const double x = v * std::sin(phi) * last.t, z = v * std::cos(phi) * last.t;
      std::printf("grip axis as filed, %s: x %.4f mm, z %.4f mm, angle %.2g rad\n", at.c_str(),
                  1e3 * last.position.x(), 1e3 * last.position.z(),
                  Eigen::AngleAxisd(last.orientation).angle());
      EXPECT_NEAR(last.position.x(), x, 0.01 * x) << at;
      EXPECT_NEAR(last.position.z(), z, 0.01 * z) << at;
      EXPECT_LT(Eigen::AngleAxisd(last.orientation).angle(), 1e-4) << at;
      EXPECT_FALSE(r.oscillation.detected) << at;
    }
  }
}

// The model options are read, written back when not the default (since
// issue 31: elastic pads, the aligned cone, "auto" inertia), and a wrong
// value is refused naming the field.
TEST(ClosedForms, PadAndConeOptionsRoundTrip) {
  const std::string base =
      std::string(kBox) + R"(,"duration":0.1,"grip_force":10.0,)" + kPointFingers + R"(,"model":{)";
  const Scene plain = Parse(base + "}");
  EXPECT_EQ(plain.model.pads, PadModel::kElastic);
  EXPECT_EQ(plain.model.cone, ConeModel::kAligned);
  EXPECT_EQ(plain.model.inertia, InertiaModel::kAuto);
  EXPECT_EQ(Scene{}.model.pads, PadModel::kElastic);  // built in code: the same defaults
  EXPECT_EQ(Scene{}.model.cone, ConeModel::kAligned);
  EXPECT_EQ(Scene{}.model.inertia, InertiaModel::kAuto);
  for (const char* key : {"\"pads\"", "\"cone\"", "\"inertia\""})
    EXPECT_EQ(SceneToJson(plain).find(key), std::string::npos) << key;
  const Scene written = Parse(base + R"("pads":"elastic","cone":"aligned","inertia":"auto"})");
  EXPECT_EQ(SceneToJson(written), SceneToJson(plain));
  const Scene set = Parse(base + R"("pads":"rigid","cone":"polyhedral","inertia":"carried"})");
  EXPECT_EQ(set.model.pads, PadModel::kRigid);
  EXPECT_EQ(set.model.cone, ConeModel::kPolyhedral);
  EXPECT_EQ(set.model.inertia, InertiaModel::kCarried);
  const Scene back = ParseScene(SceneToJson(set));
  EXPECT_EQ(back.model.pads, PadModel::kRigid);
  EXPECT_EQ(back.model.cone, ConeModel::kPolyhedral);
  EXPECT_EQ(back.model.inertia, InertiaModel::kCarried);
  const Scene quasi = Parse(base + R"("inertia":"quasi_static"})");
  EXPECT_EQ(ParseScene(SceneToJson(quasi)).model.inertia, InertiaModel::kQuasiStatic);
  try {
    Parse(base + R"("cone":"circular"})");
    ADD_FAILURE() << "accepted cone circular";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("model.cone"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arena::mechanics
