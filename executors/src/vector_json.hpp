// A vector as the JSON the cell writes it in (private).
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace arena::executors::internal {

// [x, y, z].
inline nlohmann::json Vec(const Eigen::Vector3d& v) {
  return nlohmann::json::array({v.x(), v.y(), v.z()});
}

}  // namespace arena::executors::internal
