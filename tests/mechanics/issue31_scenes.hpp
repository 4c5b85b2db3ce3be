// The parts of issue 31's scenes and the helpers its closed-form tests share
// (closed_forms_test.cpp, quasi_static_test.cpp).
#pragma once

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
