// Simulate a scene: the object's motion and every contact force over time,
// sampled at 250 Hz. Model: DESIGN.md (Mechanics) and the seed paper.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arena/mechanics/scene.hpp"

namespace arena::mechanics {

inline constexpr double kSampleRateHz = 250.0;

enum class ContactMode { kStick, kSlide, kSeparate };
const char* ToString(ContactMode mode);

// One finger or the pusher, summed over its constituent points.
struct ContactState {
  double normal_force = 0;                                     // N, on the object
  Eigen::Vector3d tangential_force = Eigen::Vector3d::Zero();  // N, on the object, gripper frame
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();            // N m about the contact position
  ContactMode mode = ContactMode::kSeparate;
};

struct TrajectorySample {
  double t = 0;                                        // s
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // object, gripper frame (m)
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();          // m/s
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s
  Eigen::Vector3d pusher_position = Eigen::Vector3d::Zero();   // pusher contact point (m)
  Eigen::Vector3d pusher_force = Eigen::Vector3d::Zero();      // on the object (N)
  std::vector<ContactState> contacts;  // fingers in scene order, then pusher
};

// Worst over all steps, relative to the scene's force scale.
struct Residuals {
  double force_balance = 0;
  double complementarity = 0;
  double cone = 0;
};

struct SolverStatistics {
  int steps = 0;
  int max_pivots = 0;
  long total_pivots = 0;
  int failures = 0;
};

struct ModelInfo {
  int dof = 6;  // 3 when the planar reduction is in use
  int facets = 0;
  int points = 0;
  double dt = 0;
  int unknowns = 0;  // LCP size of one step
};

enum class SimulationStatus {
  kOk,
  kSolverFailure,  // the complementarity solver found no solution (reason says why)
  kInvalidScene,   // e.g. reduce=planar on a scene that is not planar
};
const char* ToString(SimulationStatus status);

struct SimulationResult {
  SimulationStatus status = SimulationStatus::kOk;
  std::string error;  // empty when ok; names the step and reason otherwise
  int failed_step = -1;
  ModelInfo model;
  std::vector<TrajectorySample> samples;  // 250 Hz from t = 0 (up to the failure, if any)
  Residuals residuals;
  SolverStatistics solver;
  double wall_s = 0;
};

// Never throws for a scene that passed ValidateScene(); a step the solver
// cannot solve ends the run with status kSolverFailure. Never returns NaN.
SimulationResult Simulate(const Scene& scene);

}  // namespace arena::mechanics
