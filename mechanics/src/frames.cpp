#include "arena/mechanics/frames.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

namespace arena::mechanics {

Eigen::Vector3d FirstTangent(const Eigen::Vector3d& normal) {
  const Eigen::Vector3d n = normal.normalized();
  for (const Eigen::Vector3d& axis :
       {Eigen::Vector3d::UnitZ().eval(), Eigen::Vector3d::UnitY().eval(),
        Eigen::Vector3d::UnitX().eval()}) {
    if (std::abs(n.dot(axis)) < 0.9) return (axis - n.dot(axis) * n).normalized();
  }
  // Unreachable for a unit normal: some axis has |n·axis| <= 1/sqrt(3).
  return (Eigen::Vector3d::UnitX() - n.x() * n).normalized();
}

Eigen::Matrix3d RotationFromRpy(const Eigen::Vector3d& rpy) {
  return (Eigen::AngleAxisd(rpy.z(), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(rpy.y(), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(rpy.x(), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d RpyFromRotation(const Eigen::Matrix3d& R) {
  return {std::atan2(R(2, 1), R(2, 2)), std::asin(std::clamp(-R(2, 0), -1.0, 1.0)),
          std::atan2(R(1, 0), R(0, 0))};
}

}  // namespace arena::mechanics
