// The support's stage of a planar step (model.cpp): the support's friction
// as generalised friction directions in the plane's reduced coordinates.
//
// The support's normal load is fixed (the weight, spread by the pressure
// distribution), so its friction is the limit surface: the set of wrenches
// W(ν) = Σ_i -μ N w_i u_i/|u_i| over every planar twist ν (u_i the velocity
// of pressure point i). The step models it as a polytope inscribed in that
// set: the wrenches W_k of K sampled twist directions, used like a friction
// cone's edges (Stewart-Trinkle with the known "normal" μN):
//   per direction k: ξ + D_kᵀ ν⁺ >= 0 ⊥ β_k >= 0,   D_k = W_k / (μN)
//   μN - Σ_k β_k >= 0 ⊥ ξ >= 0;   the support's wrench is Σ_k β_k D_k.
// Sliding with twist ν, ξ = max_k (-D_kᵀν) and the wrench is the
// maximising W_k. Maximal dissipation on the true limit surface picks
// W(ν) itself, and the polytope's vertices lie on that surface, so when ν
// is one of the sampled directions the answer is exact. The sampled
// directions are 26 fixed ones (the 3×3×3 grid of (vx, vy, ω ρ) minus its
// centre, ρ the pressure's radius of gyration) and the previous step's
// twist: exact in steady sliding, first order in the twist's turn over one
// step otherwise.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/support.hpp"

namespace arena::mechanics {

class SupportStage {
 public:
  // Empty string, or why the support cannot be modelled. p: the plane's
  // normal (the model's plane must be the support's: p along gravity), e1,
  // e2 its in-plane axes (e2 = p × e1).
  std::string Setup(const Scene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& e1,
                    const Eigen::Vector3d& e2);

  bool active() const { return active_; }
  int directions() const { return static_cast<int>(fixed_.size()) + 1; }
  double limit() const { return mu_N_; }  // μN (N): Σβ at most this

  // This step's columns D_k (3 × directions(), reduced coordinates: force
  // along e1, e2 per unit β, torque about p through c in m) at the object's
  // pose (R, origin of O, centre of mass c; gripper frame), with the
  // previous step's reduced twist as the last sampled direction (the first
  // fixed one when it is zero).
  void Columns(const Eigen::Matrix3d& R, const Eigen::Vector3d& origin, const Eigen::Vector3d& c,
               const Eigen::Vector3d& previous_twist, Eigen::Matrix<double, 3, Eigen::Dynamic>* D);

  // The support's friction for the reduced twist ν (N, N, N m): the exact
  // limit-surface wrench at the current pose (for reports and tests).
  Eigen::Vector3d Exact(const Eigen::Vector3d& twist) const;

 private:
  bool active_ = false;
  double mu_N_ = 0;
  double rho_ = 1;  // radius of gyration of the pressure about the centre of mass (m)
  Eigen::Vector3d p_ = Eigen::Vector3d::UnitZ(), e1_ = Eigen::Vector3d::UnitX(),
                  e2_ = Eigen::Vector3d::UnitY();
  SupportPressure pressure_;
  std::vector<Eigen::Vector3d> fixed_;  // unit (vx, vy, ω ρ) directions
  // This step's pressure points relative to c in (e1, e2) coordinates.
  std::vector<Eigen::Vector2d> arms_;
};

}  // namespace arena::mechanics
