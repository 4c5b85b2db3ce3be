// The part of a cell's defect profile that changes what the object really
// does (executors/include/arena/executors/defects.hpp, "Actuation noise" and
// "Trial-to-trial friction variability"), read from the profile's JSON here
// because assessment does not link executors. The cell draws per trial:
//   every mu      *= 1 + N(0, mu_scale_std)   (redrawn while <= 0)
//   pusher v       = v * (1 + N(0, velocity_scale_std)) + N(0, velocity_offset_std) per axis
// Sensing noise, latency and drops change only what the sensors saw, never
// the ground truth, so they play no part in the predicted spread.
#pragma once

#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "arena/mechanics/scene.hpp"

namespace arena::assessment {

// A profile field of the wrong type or range: what() is "<field>: <reason>".
class NoiseError : public std::invalid_argument {
 public:
  NoiseError(const std::string& field, const std::string& reason)
      : std::invalid_argument(field + ": " + reason), field_(field) {}
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

}  // namespace arena::assessment
