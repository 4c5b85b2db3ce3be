// The part of a cell's defect profile that changes what the object really
// does (executors/include/arena/executors/defects.hpp, "Actuation noise" and
// "Trial-to-trial friction variability"), read from the profile's JSON here
// because assessment does not link executors. The cell draws per trial:
//   every mu      *= 1 + N(0, mu_scale_std)   (redrawn while <= 0)
//   pusher v       = v * (1 + N(0, velocity_scale_std)) + N(0, velocity_offset_std) per axis
// and a simulated cell starts each trial where the reset that prepared it
// placed the object (reset/include/arena/reset/reset.hpp, PlacementForTrial):
//   start pose     = nominal (+) N(0, reset.placement_*_std) per axis, the
//                    first of at most reset.max_attempts placements that the
//                    verification (pose_noise as sensing) sees within tolerance.
// Sensing noise, latency and drops otherwise change only what the sensors
// saw, never the ground truth, so they play no other part in the spread.
#pragma once

#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "arena/errors/error.hpp"
#include "arena/mechanics/scene.hpp"

namespace arena::assessment {

// A profile field of the wrong type or range: what() is "<field>: <reason>".
class NoiseError : public Error {
 public:
  NoiseError(const std::string& field, const std::string& reason)
      : Error(ErrorCategory::kBadInput, field + ": " + reason), field_(field) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

struct ActuationNoise {
  double mu_scale_std = 0;                                        // fraction
  double velocity_scale_std = 0;                                  // fraction
  Eigen::Vector3d velocity_offset_std = Eigen::Vector3d::Zero();  // m/s, per gripper axis
  bool any() const {
    return mu_scale_std > 0 || velocity_scale_std > 0 || velocity_offset_std.maxCoeff() > 0;
  }
};

// Reads the noise out of a defect profile (a JSON object; other fields are
// not this room's business and are skipped). "{}" gives no noise.
// @throws NoiseError naming the field ("friction_variability.mu_scale_std").
ActuationNoise ParseActuationNoise(std::string_view profile_json);

struct NoiseDraw {
  double mu_scale = 1;
  double velocity_scale = 1;
  Eigen::Vector3d velocity_offset = Eigen::Vector3d::Zero();  // m/s
};

// One draw, as the cell draws it (own random stream: an ensemble member is
// not any trial's replay).
NoiseDraw DrawNoise(const ActuationNoise& noise, std::mt19937_64* rng);

// The scene with the draw applied (friction scaled, pusher velocity changed).
mechanics::Scene ApplyNoise(const mechanics::Scene& scene, const NoiseDraw& draw);

// The start-pose error a simulated cell's reset leaves, from the profile's
// "reset" object (the cell's reset parameters; a profile without one is a
// cell at the reset defaults, as reset::ResetParams has them) and
// "pose_noise" (verification sensing: the largest axis, as the cell uses
// it). Read here because assessment links neither reset nor executors; a test
// holds it to reset::PlacementForTrial's distribution.
struct StartPoseNoise {
  double position_std = 2e-4;         // m per axis (reset.placement_position_std)
  double angle_std = 2e-3;            // rad per axis (reset.placement_angle_std)
  double position_tolerance = 0.002;  // m: verification
  double angle_tolerance = 0.02;      // rad
  double sensing_position_std = 0;    // m per axis
  double sensing_angle_std = 0;       // rad per axis
  int max_attempts = 3;
  // False when the cell's backend does not emulate defects (a robot, a
  // recording: "emulated": false in the applied profile): it has its own start.
  bool emulated = true;
  bool any() const { return emulated && (position_std > 0 || angle_std > 0); }
};

// @throws NoiseError naming the field ("reset.placement_position_std").
StartPoseNoise ParseStartPoseNoise(std::string_view profile_json);

struct StartPoseDraw {
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();    // m, in the gripper frame
  Eigen::Vector3d rotation = Eigen::Vector3d::Zero();  // rad, rotation vector in the object frame
};

// One draw (own random stream, as DrawNoise). Zero when !noise.any().
StartPoseDraw DrawStartPose(const StartPoseNoise& noise, std::mt19937_64* rng);

// The scene starting at the drawn pose, the fingers closed onto the object
// there (mechanics::SeatFingers), as the cell starts it.
// @throws mechanics::SceneError when a finger misses the object there.
mechanics::Scene ApplyStartPose(const mechanics::Scene& scene, const StartPoseDraw& draw);

}  // namespace arena::assessment
