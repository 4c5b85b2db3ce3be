// Simulate(): steps the contact model over the scene's duration and samples
// it at 250 Hz. Each sample at t in (t_n, t_{n+1}] reports the pose at t
// (exact: the pose moves linearly in position and along a constant rotation
// within a step), the twist and contact forces of that step; the sample at
// t = 0 reports the initial pose and rest twist with the first step's forces.
#include "arena/mechanics/simulate.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/pusher_motion.hpp"

namespace arena::mechanics {

const char* ToString(ContactMode mode) {
  switch (mode) {
    case ContactMode::kStick:
      return "stick";
    case ContactMode::kSlide:
      return "slide";
    case ContactMode::kSeparate:
      return "separate";
  }
  return "unknown";
}

const char* ToString(SimulationStatus status) {
  switch (status) {
    case SimulationStatus::kOk:
      return "ok";
    case SimulationStatus::kSolverFailure:
      return "solver_failure";
    case SimulationStatus::kInvalidScene:
      return "invalid_scene";
  }
  return "unknown";
}

const char* ToString(GraspStatus status) {
  switch (status) {
    case GraspStatus::kHeld:
      return "held";
    case GraspStatus::kLost:
      return "lost";
    case GraspStatus::kLeftGeometry:
      return "left_geometry";
  }
  return "unknown";
}

SimulationResult Simulate(const Scene& scene) { return Simulate(scene, nullptr); }

namespace {

// The command a closed loop may apply: translation within the model's plane
// (when the model is planar), the scene's own turning.
std::string CheckCommand(const Scene& scene, const ModelInfo& info, const PusherMotion& command) {
  if (!command.velocity.allFinite() || !command.angular_velocity.allFinite())
    return "pusher command: not finite";
  if (command.angular_velocity != scene.pusher->motion.angular_velocity)
    return "pusher command: angular velocity differs from the scene's (the model turns the pusher "
           "at a constant rate only)";
  if (info.dof == 3) {
    Scene with = scene;
    with.pusher->motion = command;
    const PlaneCheck plane = FindPlane(with);
    const PlaneCheck base = FindPlane(scene);
    if (!plane.planar || plane.normal.cross(base.normal).norm() > 1e-6)
      return "pusher command: leaves the plane of the planar model";
  }
  return "";
}

}  // namespace

SimulationResult Simulate(const Scene& scene, const PusherCommandSource& commands) {
  const auto start = std::chrono::steady_clock::now();
  SimulationResult result;
  ContactModel model(scene);
  result.model = model.info();
  // Every return goes through finish(): it moves the result out (returned
  // by value from a lambda that captures it, it was copied, every sample
  // and its contact states, once per trial).
  auto finish = [&] {
    result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return std::move(result);
  };
  if (model.status() != SimulationStatus::kOk) {
    result.status = model.status();
    result.error = model.error();
    return finish();
  }
  const double dt = scene.model.dt;
  const double period = 1.0 / kSampleRateHz;
  const long n_samples = static_cast<long>(std::floor(scene.duration * kSampleRateHz + 1e-9)) + 1;
  const long n_steps = std::max(1L, static_cast<long>(std::ceil(scene.duration / dt - 1e-9)));
  result.samples.reserve(static_cast<size_t>(n_samples));
  const Eigen::Vector3d pusher0 = scene.pusher ? scene.pusher->position : Eigen::Vector3d::Zero();
  const Eigen::Vector3d pusher_v =
      scene.pusher ? scene.pusher->motion.velocity : Eigen::Vector3d::Zero();
  const bool closed_loop = commands && scene.pusher;
  Eigen::Vector3d command_v = pusher_v;  // closed loop: the motion in force

  long next = 0;  // next sample index
  for (long step = 0; step < n_steps; ++step) {
    const double t0 = model.time();
    const Eigen::Vector3d c0 = model.position();
    const Eigen::Quaterniond q0 = model.orientation();
    const StepReport rep = model.Step();
    ++result.solver.steps;
    result.solver.max_pivots = std::max(result.solver.max_pivots, rep.pivots);
    result.solver.total_pivots += rep.pivots;
    if (!rep.ok) {
      result.solver.failures++;
      result.status = SimulationStatus::kSolverFailure;
      result.failed_step = static_cast<int>(step);
      char when[64];
      std::snprintf(when, sizeof when, "step %ld (t = %.6g s): ", step, t0);
      result.error = when + rep.error;
      return finish();
    }
    result.residuals.force_balance =
        std::max(result.residuals.force_balance, rep.residuals.force_balance);
    result.residuals.complementarity =
        std::max(result.residuals.complementarity, rep.residuals.complementarity);
    result.residuals.cone = std::max(result.residuals.cone, rep.residuals.cone);
    if (result.grasp == GraspStatus::kHeld) {
      result.grasp = model.Grasp(&result.grasp_note);
      if (result.grasp != GraspStatus::kHeld) result.grasp_changed_t = model.time();
    }
    const double t1 = model.time();
    while (next < n_samples) {
      const double ts = static_cast<double>(next) * period;
      if (ts > t1 + 1e-9 * dt && step + 1 < n_steps) break;
      const double s = std::clamp((ts - t0) / dt, 0.0, 1.0);
      TrajectorySample sample;
      sample.t = ts;
      sample.position = c0 + (ts - t0) * model.velocity();
      sample.orientation = q0.slerp(s, model.orientation());
      if (next > 0) {
        sample.velocity = model.velocity();
        sample.angular_velocity = model.angular_velocity();
      }
      sample.pusher_position =
          closed_loop
              ? Eigen::Vector3d(model.pusher_position() - command_v * (t1 - ts))
              : (scene.pusher && scene.pusher->path ? PusherPoseAt(*scene.pusher, ts).position
                                                    : Eigen::Vector3d(pusher0 + pusher_v * ts));
      sample.pusher_force = model.pusher_force();
      sample.contacts = model.contacts();
      result.samples.push_back(std::move(sample));
      ++next;
      if (!closed_loop) continue;
      std::string why;
      const std::optional<PusherMotion> command = commands(result.samples, &why);
      if (!command) {
        result.stopped = why.empty() ? "stopped by the command source" : why;
        return finish();
      }
      if (std::string bad = CheckCommand(scene, result.model, *command); !bad.empty()) {
        result.status = SimulationStatus::kInvalidScene;
        result.error = bad;
        return finish();
      }
      model.SetPusherMotion(*command);
      command_v = command->velocity;
    }
  }
  return finish();
}

}  // namespace arena::mechanics
