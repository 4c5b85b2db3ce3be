// Issue 30's scene fields: the support, the recorded pusher path and
// prisms of any simple polygon. Reading, writing and refusing them (each
// refusal names its field), the non-convex geometry against hand-derived
// answers, and a recorded path driving arena's model.
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/polygon.hpp"
#include "arena/mechanics/pusher_motion.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/mechanics/support.hpp"
#include "geometry.hpp"
#include "scenes.hpp"

namespace arena::mechanics {
namespace {

using nlohmann::json;

// The push dataset's set-up (free pushing, table frame): a 90 mm square
// prism 13 mm thick on the table, a 4.75 mm sphere pusher at mid-height
// 10 mm from its -x face, moving +x.
json FreePush() {
  return json::parse(R"({
    "object": {"shape": "prism", "height": 0.013, "mass": 0.8374,
               "polygon": [[-0.045, -0.045], [0.045, -0.045], [0.045, 0.045], [-0.045, 0.045]],
               "pose": {"position": [0, 0, 0.0065], "rpy": [0, 0, 0]}},
    "gravity": [0, 0, -9.81],
    "duration": 0.5,
    "grip_force": 0,
    "fingers": [],
    "pusher": {"type": "point", "radius": 0.00475, "position": [-0.055, 0, 0.0065],
               "normal": [1, 0, 0], "mu": 0.25,
               "motion": {"path": {"t": [0, 0.25, 0.5],
                                   "position": [[-0.055, 0, 0.0065], [-0.05, 0, 0.0065],
                                                [-0.04, 0, 0.0065]]}}},
    "support": {"mu": 0.3, "pressure": "uniform"},
    "model": {"facets": 8, "points": 3, "dt": 0.004}
  })");
}

std::string RefusedAt(const json& doc, std::string* message = nullptr) {
  try {
    ParseScene(doc.dump());
  } catch (const SceneError& e) {
    if (message) *message = e.what();
    return e.field();
  }
  return "";
}

TEST(SupportScene, ReadsAndWritesTheAgreedFieldsExactly) {
  const Scene s = ParseScene(FreePush().dump());
  ASSERT_TRUE(s.support.has_value());
  EXPECT_EQ(s.support->mu, 0.3);
  EXPECT_TRUE(s.support->pressure_points.empty());
  EXPECT_TRUE(s.fingers.empty());
  ASSERT_TRUE(s.pusher && s.pusher->path);
  EXPECT_EQ(s.pusher->path->t, (std::vector<double>{0, 0.25, 0.5}));
  EXPECT_EQ(s.pusher->path->position[2], Eigen::Vector3d(-0.04, 0, 0.0065));
  EXPECT_TRUE(s.pusher->path->rpy.empty());
  // Round trip, and the same with weighted points and angles.
  const Scene again = ParseScene(SceneToJson(s));
  EXPECT_EQ(SceneToJson(again), SceneToJson(s));
  json doc = FreePush();
  doc["support"]["pressure"] = {
      {"points", {{0.01, 0, 1}, {-0.01, 0, 1}, {0, 0.02, 0.5}, {0, -0.02, 0.5}}}};
  doc["pusher"]["motion"]["path"]["rpy"] = {{0, 0, 0}, {0, 0, 0.1}, {0, 0, 0.2}};
  const Scene w = ParseScene(doc.dump());
  ASSERT_EQ(w.support->pressure_points.size(), 4u);
  EXPECT_EQ(w.support->pressure_points[2], Eigen::Vector3d(0, 0.02, 0.5));
  ASSERT_EQ(w.pusher->path->rpy.size(), 3u);
  EXPECT_EQ(SceneToJson(ParseScene(SceneToJson(w))), SceneToJson(w));
  EXPECT_NE(SceneToJson(w).find("\"pressure\":{\"points\""), std::string::npos);
}

TEST(SupportScene, EachRuleNamesItsField) {
  struct Case {
    const char* what;
    std::function<void(json&)> edit;
    const char* field;
  };
  const std::vector<Case> cases = {
      {"no support, no fingers", [](json& d) { d.erase("support"); }, "fingers"},
      {"support without mu", [](json& d) { d["support"].erase("mu"); }, "support.mu"},
      {"negative support mu", [](json& d) { d["support"]["mu"] = -0.1; }, "support.mu"},
      {"unknown pressure", [](json& d) { d["support"]["pressure"] = "gaussian"; },
       "support.pressure"},
      {"unknown support key", [](json& d) { d["support"]["height"] = 0; }, "support.height"},
      {"empty points",
       [](json& d) {
         d["support"]["pressure"] = {{"points", json::array()}};
       },
       "support.pressure.points"},
      {"negative weight",
       [](json& d) {
         d["support"]["pressure"] = {{"points", {{0, 0, 1}, {0.01, 0, -1}}}};
       },
       "support.pressure.points[1][2]"},
      {"point off the face",
       [](json& d) {
         d["support"]["pressure"] = {{"points", {{0.2, 0, 1}, {-0.2, 0, 1}}}};
       },
       "support.pressure.points[0]"},
      {"centre of pressure off the centre of mass",
       [](json& d) {
         d["support"]["pressure"] = {{"points", {{0.03, 0, 1}}}};
       },
       "support.pressure.points"},
      {"all weights zero",
       [](json& d) {
         d["support"]["pressure"] = {{"points", {{0, 0, 0}}}};
       },
       "support.pressure.points"},
      {"no gravity", [](json& d) { d.erase("gravity"); }, "support"},
      {"tilted object",
       [](json& d) {
         d["object"]["pose"]["rpy"] = {0.3, 0, 0};
       },
       "support"},
      {"path and velocity",
       [](json& d) {
         d["pusher"]["motion"]["velocity"] = {0.01, 0, 0};
       },
       "pusher.motion.velocity"},
      {"path t not from 0", [](json& d) { d["pusher"]["motion"]["path"]["t"][0] = 0.001; },
       "pusher.motion.path.t[0]"},
      {"path t not increasing", [](json& d) { d["pusher"]["motion"]["path"]["t"][2] = 0.25; },
       "pusher.motion.path.t[2]"},
      {"path rows short", [](json& d) { d["pusher"]["motion"]["path"]["position"].erase(2); },
       "pusher.motion.path.position"},
      {"path rpy rows short",
       [](json& d) {
         d["pusher"]["motion"]["path"]["rpy"] = {{0, 0, 0}};
       },
       "pusher.motion.path.rpy"},
      {"path starts elsewhere",
       [](json& d) { d["pusher"]["motion"]["path"]["position"][0][0] = -0.06; },
       "pusher.motion.path.position[0]"},
      {"path row of 2",
       [](json& d) {
         d["pusher"]["motion"]["path"]["position"][1] = {0, 0};
       },
       "pusher.motion.path.position[1]"},
      {"pusher inside the object",
       [](json& d) {
         d["pusher"]["position"] = {-0.03, 0, 0.0065};
         d["pusher"]["motion"]["path"]["position"][0] = {-0.03, 0, 0.0065};
       },
       "pusher.position"},
      {"self-intersecting polygon",
       [](json& d) {
         d["object"]["polygon"] = {
             {-0.045, -0.045}, {0.045, 0.045}, {0.045, -0.045}, {-0.045, 0.045}};
       },
       "object.polygon[2]"},
      {"clockwise polygon",
       [](json& d) {
         d["object"]["polygon"] = {
             {-0.045, -0.045}, {-0.045, 0.045}, {0.045, 0.045}, {0.045, -0.045}};
       },
       "object.polygon[0]"},
  };
  for (const auto& c : cases) {
    json doc = FreePush();
    c.edit(doc);
    std::string message;
    EXPECT_EQ(RefusedAt(doc, &message), c.field) << c.what << ": " << message;
  }
  // A pusher apart from the object in fixed contacts (the frozen frame has
  // no way to make a contact) is refused.
  json doc = FreePush();
  doc["model"]["contacts"] = "fixed";
  EXPECT_EQ(RefusedAt(doc), "pusher.position");
}

// An L-shaped (non-convex) prism: the outline below, 2 × 2 minus the unit
// square at top right (area 3).
//
//   (0,2)---(1,2)
//     |       |
//     |     (1,1)---(2,1)
//     |               |
//   (0,0)-----------(2,0)
//
// Centroid: (3·(x̄ of the 2x2 = 1) - 1·1.5) / 2... by parts: the 2×2 square
// (area 4, centre (1, 1)) minus the unit square (area 1, centre (1.5, 1.5)):
// c = (4 (1, 1) - (1.5, 1.5)) / 3 = (5/6, 5/6). Second moment about the
// origin ∫x² dA = 4·(4/3) - (1·(1.5² + 1/12)) = 16/3 - 7/3 = 3; about the
// centroid 3 - 3 (5/6)² = 11/12; likewise ∫y²; ∫xy = 4·1 - 1·(1.5·1.5) =
// 7/4, about the centroid 7/4 - 3 (5/6)² = -1/3.
const polygon::Polygon kL = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};

TEST(SimplePolygon, LShapeMomentsTriangulationAndContainment) {
  EXPECT_FALSE(polygon::CheckSimple(kL).has_value());
  EXPECT_FALSE(polygon::IsConvex(kL));
  EXPECT_NEAR(polygon::SignedArea(kL), 3, 1e-15);
  const geometry::PolygonMoments m = geometry::MomentsOf(kL);
  EXPECT_NEAR(m.area, 3, 1e-15);
  EXPECT_NEAR(m.centroid.x(), 5.0 / 6, 1e-15);
  EXPECT_NEAR(m.centroid.y(), 5.0 / 6, 1e-15);
  EXPECT_NEAR(m.xx, 11.0 / 12, 1e-14);
  EXPECT_NEAR(m.yy, 11.0 / 12, 1e-14);
  EXPECT_NEAR(m.xy, -1.0 / 3, 1e-14);
  // n - 2 triangles that tile it: their areas sum to the polygon's, each is
  // counter-clockwise, and each one's centroid lies inside the L.
  const auto tris = polygon::Triangulate(kL);
  ASSERT_EQ(tris.size(), 4u);
  double area = 0;
  for (const auto& t : tris) {
    const polygon::Polygon tri = {kL[t[0]], kL[t[1]], kL[t[2]]};
    EXPECT_GT(polygon::SignedArea(tri), 0);
    area += polygon::SignedArea(tri);
    EXPECT_TRUE(polygon::Contains(kL, (tri[0] + tri[1] + tri[2]) / 3));
  }
  EXPECT_NEAR(area, 3, 1e-14);
  EXPECT_TRUE(polygon::Contains(kL, {0.5, 1.5}));
  EXPECT_FALSE(polygon::Contains(kL, {1.5, 1.5}));  // the notch
  EXPECT_TRUE(polygon::Contains(kL, {1, 1.5}));     // on the boundary
}

// The L as a prism of height 2 (z in [-1, 1]): closest points and entries
// against the notch, where a convex model (its half-spaces) would be wrong.
TEST(SimplePolygon, NonConvexPrismClosestPointsAndEntries) {
  ObjectSpec o;
  o.shape = ObjectShape::kPrism;
  o.polygon = kL;
  o.height = 2;
  o.mass = 1;
  const geometry::Solid solid(o);
  // In the notch at (1.5, 1.5, 0): outside, 0.5 from both inner edges.
  EXPECT_NEAR(solid.ClosestTo({1.5, 1.5, 0}).distance, 0.5, 1e-15);
  // Inside at (0.9, 0.9, 0), by the reflex corner (1, 1): the corner is the
  // closest boundary point (both inner edges end there), √0.02 away, and
  // the outward direction is from the point to it (no edge's normal).
  const geometry::Closest corner = solid.ClosestTo({0.9, 0.9, 0});
  EXPECT_NEAR(corner.distance, -std::sqrt(0.02), 1e-15);
  EXPECT_NEAR((corner.point_O - Eigen::Vector3d(1, 1, 0)).norm(), 0, 1e-15);
  EXPECT_NEAR((corner.normal_O - Eigen::Vector3d(1, 1, 0).normalized()).norm(), 0, 1e-15);
  // Inside near the inner edge y = 1 (x in [1, 2]): (1.5, 0.9, 0) is 0.1
  // deep under it; the outward normal is +y.
  const geometry::Closest in = solid.ClosestTo({1.5, 0.9, 0});
  EXPECT_NEAR(in.distance, -0.1, 1e-15);
  EXPECT_NEAR((in.normal_O - Eigen::Vector3d::UnitY()).norm(), 0, 1e-15);
  // A line along -x at y = 1.5 from x = 3 crosses the notch (empty) and
  // enters at the inner edge x = 1 with normal +x, s = 2.
  const auto e = solid.EntryOf({3, 1.5, 0}, {-1, 0, 0}, 1e-9);
  ASSERT_TRUE(e.has_value());
  EXPECT_NEAR(e->s, 2, 1e-15);
  EXPECT_NEAR((e->normal_O - Eigen::Vector3d::UnitX()).norm(), 0, 1e-15);
  // Along -y at x = 1.5 from y = 3: enters the lower arm's top y = 1, s = 2.
  const auto f = solid.EntryOf({1.5, 3, 0}, {0, -1, 0}, 1e-9);
  ASSERT_TRUE(f.has_value());
  EXPECT_NEAR(f->s, 2, 1e-15);
  EXPECT_NEAR((f->normal_O - Eigen::Vector3d::UnitY()).norm(), 0, 1e-15);
  // Down through the notch (x = y = 1.5): misses.
  EXPECT_FALSE(solid.EntryOf({1.5, 1.5, 3}, {0, 0, -1}, 1e-9).has_value());
  // Down onto the arm at (0.5, 1.5): the top cap at z = 1, s = 2.
  const auto g = solid.EntryOf({0.5, 1.5, 3}, {0, 0, -1}, 1e-9);
  ASSERT_TRUE(g.has_value());
  EXPECT_NEAR(g->s, 2, 1e-15);
  EXPECT_NEAR((g->normal_O - Eigen::Vector3d::UnitZ()).norm(), 0, 1e-15);
}

// The uniform quadrature of the support: weights sum to 1, its centre is
// the face's centroid (linear functions integrate exactly), and a disk's
// ring points give Σ w r = 2R/3 (the closed form ∫ r dA / A) exactly.
TEST(SupportPressure, QuadratureMomentsAreTheFaceOnes) {
  Scene s = ParseScene(FreePush().dump());
  s.object.polygon.clear();
  for (const auto& v : kL) s.object.polygon.push_back(0.03 * v);
  const SupportPressure p = SupportPressureOf(s);
  double total = 0;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double xx = 0;
  for (size_t i = 0; i < p.weights.size(); ++i) {
    total += p.weights[i];
    centre += p.weights[i] * p.points_O[i].head<2>();
    EXPECT_EQ(p.points_O[i].z(), -0.0065);  // the bottom cap
  }
  EXPECT_NEAR(total, 1, 1e-14);
  EXPECT_NEAR(centre.x(), 0.03 * 5 / 6, 1e-15);
  EXPECT_NEAR(centre.y(), 0.03 * 5 / 6, 1e-15);
  for (size_t i = 0; i < p.weights.size(); ++i)
    xx += p.weights[i] * std::pow(p.points_O[i].x() - centre.x(), 2);
  // The midpoint rule on small triangles: ∫x² within 1 % (it converges as h²).
  EXPECT_NEAR(xx, 0.03 * 0.03 * (11.0 / 12) / 3, 0.01 * 0.03 * 0.03 * (11.0 / 12) / 3);
  EXPECT_GE(p.weights.size(), 300u);

  Scene disk = s;
  disk.object.shape = ObjectShape::kCylinder;
  disk.object.polygon.clear();
  disk.object.radius = 0.05;
  disk.object.height = 0.013;
  const SupportPressure d = SupportPressureOf(disk);
  double mean_r = 0;
  Eigen::Vector2d dc = Eigen::Vector2d::Zero();
  for (size_t i = 0; i < d.weights.size(); ++i) {
    mean_r += d.weights[i] * d.points_O[i].head<2>().norm();
    dc += d.weights[i] * d.points_O[i].head<2>();
  }
  EXPECT_NEAR(mean_r, 2.0 / 3.0 * 0.05, 1e-15);
  EXPECT_LT(dc.norm(), 1e-15);
}

// A recorded path: linear between samples, at rest after the last; its
// rotation R(rpy(t)) R(rpy[0])ᵀ.
TEST(PusherPath, InterpolatesAndRests) {
  PusherSpec p;
  p.position = {1, 0, 0};
  PusherPath path;
  path.t = {0, 1, 3};
  path.position = {{1, 0, 0}, {2, 0, 0}, {2, 2, 0}};
  path.rpy = {{0, 0, 0.5}, {0, 0, 1.0}, {0, 0, 1.5}};
  p.path = path;
  EXPECT_EQ(PusherPoseAt(p, 0).position, Eigen::Vector3d(1, 0, 0));
  EXPECT_NEAR((PusherPoseAt(p, 0.25).position - Eigen::Vector3d(1.25, 0, 0)).norm(), 0, 1e-15);
  EXPECT_NEAR((PusherPoseAt(p, 2).position - Eigen::Vector3d(2, 1, 0)).norm(), 0, 1e-15);
  EXPECT_EQ(PusherPoseAt(p, 7).position, Eigen::Vector3d(2, 2, 0));
  // Turned by 0.25 rad about z at t = 0.5 (rpy yaw 0.75 against 0.5).
  const Eigen::AngleAxisd turn(PusherPoseAt(p, 0.5).rotation);
  EXPECT_NEAR(turn.angle(), 0.25, 1e-12);
  EXPECT_NEAR(std::abs(turn.axis().z()), 1, 1e-12);
  const PusherTwist tw = PusherTwistOver(p, 1.5, 0.5);
  EXPECT_NEAR((tw.velocity - Eigen::Vector3d(0, 1, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((tw.angular_velocity - Eigen::Vector3d(0, 0, 0.25)).norm(), 0, 1e-12);
  EXPECT_EQ(PusherTwistOver(p, 5, 0.1).velocity, Eigen::Vector3d::Zero());
}

// The canonical held box pushed from below by a recorded path: the same
// motion as the constant velocity 0.01 m/s for 0.5 s, then at rest. The
// object follows the path (stuck on the pusher, sliding in the grasp) as
// it follows the constant motion, to rounding, then stops with the pusher.
TEST(PusherPath, RecordedPathDrivesArenasModel) {
  for (const ContactTracking mode : {ContactTracking::kTracked, ContactTracking::kFixed}) {
    Scene constant = testing::CanonicalScene();
    constant.model.contacts = mode;
    constant.duration = 0.5;
    Scene recorded = constant;
    recorded.duration = 1.0;
    PusherPath path;
    for (int k = 0; k <= 125; ++k) {
      path.t.push_back(0.004 * k);
      path.position.push_back(constant.pusher->position +
                              constant.pusher->motion.velocity * (0.004 * k));
    }
    recorded.pusher->path = path;
    recorded.pusher->motion = PusherMotion{};
    ValidateScene(recorded);
    const SimulationResult a = Simulate(constant);
    const SimulationResult b = Simulate(recorded);
    ASSERT_EQ(a.status, SimulationStatus::kOk) << a.error;
    ASSERT_EQ(b.status, SimulationStatus::kOk) << b.error;
    const auto& end_a = a.samples.back();
    const auto& mid_b = b.samples.at(a.samples.size() - 1);
    EXPECT_NEAR((end_a.position - mid_b.position).norm(), 0, 1e-12) << ToString(mode);
    EXPECT_NEAR((end_a.pusher_position - mid_b.pusher_position).norm(), 0, 1e-15);
    EXPECT_NEAR(mid_b.position.z(), 0.005, 1e-9);  // 0.01 m/s for 0.5 s
    // At rest after the path: the pusher and the object stay where they are.
    const auto& last = b.samples.back();
    EXPECT_EQ(last.pusher_position, path.position.back());
    EXPECT_NEAR((last.position - mid_b.position).norm(), 0, 1e-9) << ToString(mode);
    EXPECT_LT(last.velocity.norm(), 1e-9);
  }
}

}  // namespace
}  // namespace arena::mechanics
