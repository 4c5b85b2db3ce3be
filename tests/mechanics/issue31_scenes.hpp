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

inline Scene Parse(const std::string& body) { return ParseScene("{" + body + "}"); }

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
