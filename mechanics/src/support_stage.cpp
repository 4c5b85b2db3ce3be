// The support's stage of a planar step (support_stage.hpp).
#include "support_stage.hpp"

#include <cmath>

#include "arena/mechanics/model.hpp"
#include "geometry.hpp"

namespace arena::mechanics {

std::string SupportStage::Setup(const Scene& scene, const Eigen::Vector3d& p,
                                const Eigen::Vector3d& e1, const Eigen::Vector3d& e2) {
  active_ = false;
  if (!scene.support) return {};
  const double g = scene.gravity.norm();
  if (!(g > 0)) return "support: needs gravity (the object's weight is the support's load)";
  if (scene.gravity.cross(p).norm() > 1e-9 * g)
    return "support: the model's plane is not the support's (gravity must be its normal)";
  try {
    pressure_ = SupportPressureOf(scene);
  } catch (const std::exception& e) {
    return e.what();
  }
  mu_N_ = scene.support->mu * scene.object.mass * g;
  p_ = p;
  e1_ = e1;
  e2_ = e2;
  // Radius of gyration of the pressure about the centre of mass (O frame;
  // the object turns about p only, so it is the same at every pose).
  const Eigen::Vector3d com_O = geometry::Solid(scene.object).centroid_O();
  double j = 0;
  for (size_t i = 0; i < pressure_.weights.size(); ++i)
    j += pressure_.weights[i] * (pressure_.points_O[i] - com_O).head<2>().squaredNorm();
  rho_ = j > 0 ? std::sqrt(j) : 1.0;
  fixed_.clear();
  for (int a = -1; a <= 1; ++a) {
    for (int b = -1; b <= 1; ++b) {
      for (int c = -1; c <= 1; ++c) {
        if (a == 0 && b == 0 && c == 0) continue;
        fixed_.push_back(Eigen::Vector3d(a, b, c).normalized());
      }
    }
  }
  arms_.resize(pressure_.weights.size());
  active_ = mu_N_ > 0;
  return {};
}

void SupportStage::Columns(const Eigen::Matrix3d& R, const Eigen::Vector3d& origin,
                           const Eigen::Vector3d& c, const Eigen::Vector3d& previous_twist,
                           Eigen::Matrix<double, 3, Eigen::Dynamic>* D) {
  for (size_t i = 0; i < arms_.size(); ++i) {
    const Eigen::Vector3d a = origin + R * pressure_.points_O[i] - c;
    arms_[i] = {e1_.dot(a), e2_.dot(a)};
  }
  const int k_all = directions();
  D->resize(3, k_all);
  auto column = [&](int k, const Eigen::Vector3d& dir) {
    // dir = (vx, vy, ω ρ): the twist (vx, vy) and ω = dir.z / ρ.
    const Eigen::Vector3d w =
        SupportFriction(arms_, pressure_.weights, 1.0, dir.head<2>(), dir.z() / rho_);
    D->col(k) = w;
  };
  for (size_t k = 0; k < fixed_.size(); ++k) column(static_cast<int>(k), fixed_[k]);
  const Eigen::Vector3d scaled(previous_twist.x(), previous_twist.y(), previous_twist.z() * rho_);
  const double n = scaled.norm();
  column(k_all - 1, n > 0 ? Eigen::Vector3d(scaled / n) : fixed_[0]);
}

Eigen::Vector3d SupportStage::Exact(const Eigen::Vector3d& twist) const {
  return SupportFriction(arms_, pressure_.weights, mu_N_, twist.head<2>(), twist.z());
}

}  // namespace arena::mechanics
