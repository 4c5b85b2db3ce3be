// A cell's defect profile: how the simulated cell falls short of a perfect
// robot (format: executors/README.md, "Defect profiles"). Ground truth is the
// true state; observations are what the sensors saw. Everything random is
// drawn from reset::Rng streams derived from (seed, trial id, purpose), so the
// same trial, seed and profile give bit-identical streams.
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "arena/errors/error.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/reset/reset.hpp"
#include "arena/schemas/ground_truth.hpp"

namespace arena::executors {

// A profile field that is missing its type, out of range or unknown.
// what() is "<field>: <reason>", e.g. "pose_noise.position_std[1]: must be >= 0".
class DefectError : public Error {
 public:
  DefectError(std::string field, const std::string& reason)
      : Error(ErrorCategory::kBadInput, field + ": " + reason), field_(std::move(field)) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

struct DefectProfile {
  // Sensing noise (Gaussian, zero mean), per axis of the gripper frame.
  Eigen::Vector3d position_std = Eigen::Vector3d::Zero();  // m, motion capture
  Eigen::Vector3d rotation_std = Eigen::Vector3d::Zero();  // rad, about the object's axes
  Eigen::Vector3d force_std = Eigen::Vector3d::Zero();     // N, every F/T sensor
  Eigen::Vector3d torque_std = Eigen::Vector3d::Zero();    // N m
  // Actuation noise, drawn once per trial: v_actual = v * (1 + s) + o.
  double velocity_scale_std = 0;                                  // s ~ N(0, std), fraction
  Eigen::Vector3d velocity_offset_std = Eigen::Vector3d::Zero();  // o ~ N(0, std), m/s
  double latency_ms = 0;        // observed stream lags the truth by this much (>= 0)
  double drop_probability = 0;  // per sample, [0, 1)
  // The cell's true friction against the scene's: every mu is scaled by
  // mu_scale (a systematic error of the scene's coefficients, (0, 10]) ...
  double mu_scale = 1;
  // ... and trial to trial by 1 + N(0, std) on top.
  double mu_scale_std = 0;
  // Capabilities and limits.
  Eigen::Vector3d workspace_min = Eigen::Vector3d::Constant(-0.25);  // m, object position
  Eigen::Vector3d workspace_max = Eigen::Vector3d::Constant(0.25);   // m
  double max_pusher_speed = 0.5;                                     // m/s
  std::vector<mechanics::ContactType> contact_types = {mechanics::ContactType::kPoint,
                                                       mechanics::ContactType::kLine,
                                                       mechanics::ContactType::kPatch};
  // Reset phase (workspace and sensing noise are filled from the above).
  reset::ResetParams reset;
  // Fixture changes (issue 29, JSON "changes": {"finger_s", "object_s"}):
  // seconds a simulated cell spends changing the finger pads or the object
  // (scaled by --speed like every phase). The pusher's is reset.swap_time.
  // 0 by default: a simulated cell models only the pusher swap unless told.
  double finger_change_s = 0.0;
  double object_change_s = 0.0;
  // Fault injection, for the fault tests only (JSON "fault_injection"; never
  // set it on a cell that does real work):
  //   hang_after_accept: EXECUTE is accepted, then nothing more is sent for
  //     it (no ground truth, no status) while the cell stays alive (its
  //     liveliness and announcements continue): a hung controller.
  //   stream: "nan" puts a NaN into the first sample's object pose; "gap"
  //     numbers the first batch's samples from 1 instead of 0 (a sample-index
  //     gap, as lost or out-of-order batches show). "" streams normally.
  bool hang_after_accept = false;
  std::string corrupt_stream;
};

// @throws DefectError naming the first bad field.
DefectProfile ParseDefectProfile(std::string_view json_text);
void ValidateDefectProfile(const DefectProfile& profile);
// Canonical JSON (ParseDefectProfile(DefectProfileToJson(p)) == p).
std::string DefectProfileToJson(const DefectProfile& profile);

// The reset parameters with the profile's workspace and pose noise.
reset::ResetParams EffectiveResetParams(const DefectProfile& profile);

// What the cell actually does in a trial, drawn from the profile.
struct TrialPerturbation {
  double mu_scale = 1;                                        // applied to every mu
  double velocity_scale = 1;                                  // pusher velocity factor
  Eigen::Vector3d velocity_offset = Eigen::Vector3d::Zero();  // m/s
};
TrialPerturbation DrawPerturbation(const DefectProfile& profile, std::uint64_t seed,
                                   std::uint64_t trial_id);
// The scene the cell really runs: friction and pusher velocity perturbed.
mechanics::Scene ApplyPerturbation(const mechanics::Scene& scene, const TrialPerturbation& p);

// Why the cell cannot run this scene ("" = it can): contact types, workspace
// (object start and the pusher's travel), pusher speed.
std::string CheckCapabilities(const DefectProfile& profile, const mechanics::Scene& scene);

// What the sensors saw for each true sample (latency, drops, noise), and the
// pusher's true state. finger wrenches: the finger contact's force and torque.
std::vector<dds::Observation> Observe(const std::vector<mechanics::TrajectorySample>& truth,
                                      const mechanics::Scene& scene, const DefectProfile& profile,
                                      std::uint64_t seed, std::uint64_t trial_id);

// The same observations one sample at a time, as a backend streams them
// (the sensors only ever look back: latency shows an older sample): Next(truth)
// is the observation of truth.back(), and calling it after each sample gives
// exactly Observe(truth) (Observe is built on it).
class Observer {
 public:
  Observer(const mechanics::Scene& scene, const DefectProfile& profile, std::uint64_t seed,
           std::uint64_t trial_id);
  ~Observer();
  Observer(Observer&&) noexcept;
  Observer& operator=(Observer&&) noexcept;
  dds::Observation Next(const std::vector<mechanics::TrajectorySample>& truth_so_far);

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// The pusher's true pose and twist at a sample (constant actuated twist).
dds::PusherState PusherAt(const mechanics::Scene& actual_scene,
                          const mechanics::TrajectorySample& sample);

}  // namespace arena::executors
