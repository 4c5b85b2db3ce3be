// The parts of issue 31's scenes and the helpers its closed-form tests share
// (closed_forms_test.cpp, quasi_static_test.cpp).
#pragma once

#include <cmath>
#include <numbers>
#include <string>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::mechanics::issue31 {

inline constexpr const char* kBox =
    R"("object":{"shape":"box","size":[0.05,0.03,0.1],"mass":0.2,"pose":{"position":[0,0,0],"rpy":[0,0,0]}})";
inline constexpr const char* kPointFingers =
    R"("fingers":[{"name":"left","type":"point","position":[-0.025,0,0],"normal":[1,0,0],"mu":0.5},)"
    R"({"name":"right","type":"point","position":[0.025,0,0],"normal":[-1,0,0],"mu":0.5}])";

// Two 10 mm patches, μ 0.5, either side of the box.
inline constexpr const char* kPatchFingers =
    R"("fingers":[{"name":"left","type":"patch","position":[-0.025,0,0],"normal":[1,0,0],)"
    R"("mu":0.5,"radius":0.01},{"name":"right","type":"patch","position":[0.025,0,0],)"
    R"("normal":[-1,0,0],"mu":0.5,"radius":0.01}])";

inline Scene Parse(const std::string& body) { return ParseScene("{" + body + "}"); }

// Issue 31's central push from below on two 4-point patches, with gravity,
// the model reduced as `reduce` says.
inline Scene CentralPushOnPatches(const std::string& reduce) {
  return Parse(std::string(kBox) + R"(,"gravity":[0,0,-9.81],"duration":0.2,"grip_force":10.0,)" +
               kPatchFingers + R"(,"model":{"facets":8,"points":4,"dt":0.001,"reduce":")" + reduce +
               R"("},"pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],)"
               R"("mu":0.0,"motion":{"velocity":[0,0,0.01],"angular_velocity":[0,0,0]}})");
}

// Issue 31's push tilted by 30° in the y-z plane through the grip axis, no
// gravity, the pusher (μ 0.3) sticking, the fingers sliding in a free
// direction (closed form: closed_forms_test.cpp,
// TiltedPushTurnsWithThePusherSeenFromTheAxis): θ(T) = 0.054686 rad.
inline std::string TiltedPushBody() {
  return std::string(kBox) + R"(,"gravity":[0,0,0],"duration":0.5,"grip_force":10.0,)" +
         kPointFingers +
         R"(,"model":{"facets":8,"points":3,"dt":0.001,"reduce":"auto"},)"
         R"("pusher":{"type":"point","position":[0,0,-0.05],"normal":[0,0,1],)"
         R"("mu":0.3,"motion":{"velocity":[0,0.004999999999999999,)"
         R"(0.008660254037844387],"angular_velocity":[0,0,0]}})";
}
inline double TiltedPushRoll() {
  const double v = 0.01, phi = std::numbers::pi / 6, h = 0.05, T = 0.5;
  return std::atan2(v * std::sin(phi) * T, h - v * std::cos(phi) * T);
}

// Issue 31's pivot past its stall: grip 1 kN, point fingers, a frictionless
// point pusher 10 mm off the grip axis pushing up at 1 cm/s for 0.6 s, no
// gravity, the model's choices `model` (JSON members):
// roll atan(d/(h − vT)) = 0.22348 rad at T (quasi_static_test.cpp).
inline Scene PivotPastStall(const std::string& model) {
  return Parse(std::string(kBox) + R"(,"gravity":[0,0,0],"duration":0.6,"grip_force":1000.0,)" +
               kPointFingers + R"(,"model":{"facets":8,"points":3,"dt":0.001,"reduce":"auto",)" +
               model +
               R"(},"pusher":{"type":"point","position":[0,0.01,-0.05],"normal":[0,0,1],)"
               R"("mu":0.0,"motion":{"velocity":[0,0,0.01],"angular_velocity":[0,0,0]}})");
}
inline double PivotPastStallRoll() { return std::atan(0.01 / (0.05 - 0.01 * 0.6)); }

// Rotation about the gripper's x axis (the grip axis) of a sample.
inline double Roll(const TrajectorySample& s) {
  const Eigen::AngleAxisd aa(s.orientation);
  return aa.angle() * aa.axis().x();
}

// A run that must succeed: its status checked, its samples non-empty.
inline SimulationResult SimulateOk(const Scene& scene) {
  SimulationResult r = Simulate(scene);
  EXPECT_EQ(r.status, SimulationStatus::kOk) << r.error;
  EXPECT_FALSE(r.samples.empty());
  return r;
}

}  // namespace arena::mechanics::issue31
