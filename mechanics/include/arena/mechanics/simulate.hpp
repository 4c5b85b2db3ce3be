// Simulate a scene: the object's motion and every contact force over time,
// sampled at 250 Hz. Model: DESIGN.md (Mechanics) and the seed paper.
#pragma once

#include <functional>
#include <optional>
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
  // Closed loop: why the command source stopped the run early (status stays
  // kOk, samples end there); empty when it ran to the scene's duration.
  std::string stopped;
};

// Never throws for a scene that passed ValidateScene(); a step the solver
// cannot solve ends the run with status kSolverFailure. Never returns NaN.
// A closed-loop scene (pusher.controller set) runs with its pusher at rest:
// use the overload below to give it commands.
SimulationResult Simulate(const Scene& scene);

// Closed loop: the pusher's motion commanded sample by sample. Called once
// per sample, in order, with every sample so far (the newest last); the
// motion it returns moves the pusher from the next step on. It returns
// nullopt to stop the run (why in *stop_reason, copied to
// SimulationResult::stopped). A command that leaves the plane of a planar
// model, or turns the pusher differently from the scene, ends the run with
// kInvalidScene. The same commands in the same order give the same result,
// bit for bit: the replay of a closed-loop trial is this with the recorded
// commands.
using PusherCommandSource = std::function<std::optional<PusherMotion>(
    const std::vector<TrajectorySample>& samples, std::string* stop_reason)>;
SimulationResult Simulate(const Scene& scene, const PusherCommandSource& commands);

}  // namespace arena::mechanics
