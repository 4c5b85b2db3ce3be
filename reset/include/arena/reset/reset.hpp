// The reset phase: bring the object back to the next trial's start pose.
//
// From the *observed* end pose (what the cell's sensors saw, not the truth)
// PlanReset() makes a sequence of reset primitives; ExecuteReset() runs it on
// a simulated executor that can fail (a configurable probability per attempt,
// and an object that left the workspace, which no retry fixes), verifies the
// result against a tolerance from the observed pose, and retries up to
// max_attempts times. A reset that still fails is reported with its reason so
// the scheduler can quarantine the cell.
//
// Whose randomness: where a placement really ends and what verification sees
// belong to the trial the reset prepares, so they are drawn from a stream
// keyed by that trial's seed alone (PlacementForTrial()); a trial's start pose
// is then a pure function of (its seed, its target pose, the reset
// parameters), whichever cell prepared it and whatever ran there before. Only
// the slips (failures and where they happen, hence time and retries) are the
// cell's history, drawn from (seed, id of the trial just executed).
//
// Frames: all poses in the gripper's nominal frame at the start of a trial
// (docs/scene.md), m and rad.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace arena::reset {

struct Pose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // m
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
};

enum class PrimitiveKind {
  kSwapPusher,  // exchange the pusher for the geometry the next trial needs
  kMovePusher,  // the same pusher, moved to where the next trial needs it
  kRelease,     // open the fingers, leaving the object on the fixture
  kRotate,      // regrasp and rotate the object in the grasp to the target orientation
  kTranslate,   // pick and place the object at the target position
  kRegrasp,     // grasp the object at the nominal grasp (the target pose)
};
const char* ToString(PrimitiveKind kind);

struct Primitive {
  PrimitiveKind kind = PrimitiveKind::kRelease;
  Pose target;            // pose of the object when the primitive ends
  double duration_s = 0;  // planned execution time (s)
};

struct ResetParams {
  double position_tolerance = 0.002;     // m, observed vs target
  double angle_tolerance = 0.02;         // rad, observed vs target
  int max_attempts = 3;                  // >= 1
  double failure_probability = 0.0;      // per attempt, [0, 1]: the object slips
  double placement_position_std = 2e-4;  // m per axis: where a placement really ends
  double placement_angle_std = 2e-3;     // rad per axis
  double sensing_position_std = 0.0;     // m per axis: pose noise when verifying
  double sensing_angle_std = 0.0;        // rad per axis
  Eigen::Vector3d workspace_min = Eigen::Vector3d::Constant(-0.25);  // m
  Eigen::Vector3d workspace_max = Eigen::Vector3d::Constant(0.25);   // m
  double translate_speed = 0.05;                                     // m/s
  double rotate_speed = 0.5;                                         // rad/s
  double grasp_time = 0.5;                                           // s per release or regrasp
  double swap_time = 5.0;                                            // s per pusher swap
};

// @throws std::invalid_argument naming the field ("reset.max_attempts: ...").
void ValidateResetParams(const ResetParams& params);

// Plans from the observed pose to the target. Primitives that are not needed
// (already within tolerance) are left out; swap_pusher adds a swap first, and
// pusher_move_m > 0 (the same pusher, placed elsewhere; no swap) a move of the
// pusher at translate_speed.
std::vector<Primitive> PlanReset(const Pose& observed, const Pose& target, bool swap_pusher,
                                 const ResetParams& params, double pusher_move_m = 0);

struct ResetRequest {
  Pose observed_end;         // what the sensors saw at the end of the last phase
  Pose true_end;             // where the object really is
  Pose target;               // the next trial's start pose
  bool swap_pusher = false;  // the next trial needs another pusher geometry
  // The next trial needs the same pusher elsewhere (its contact point moved
  // by this much, m): a move of the arm, not a tool change. 0 with a swap.
  double pusher_move_m = 0;
};

struct ResetOutcome {
  bool success = false;
  std::string failure;    // empty on success; the reason otherwise
  bool retryable = true;  // false: no retry can help (object left the workspace)
  int attempts = 0;
  double position_error = 0;    // m, last verification (observed vs target)
  double angle_error = 0;       // rad
  double time_s = 0;            // simulated time spent in all attempts
  std::vector<Primitive> plan;  // the plan of the last attempt
  Pose final_true;              // where the object really ends
  Pose final_observed;          // what verification saw
};

// Simulated execution with verification and retries. `seed` is the seed of
// the trial the reset prepares (the target's), `trial_id` the trial that just
// ran (slips only). Every attempt that does not slip ends at the next of the
// prepared trial's placements (PlacementForTrial), also when no primitive
// was needed: the next trial's grasp seats the object anew, so a simulated
// object keeps no memory of earlier trials (no time is spent then).
// On success, final_true == PlacementForTrial(target, params, seed).true_pose.
// @pre ValidateResetParams(params) passes.
ResetOutcome ExecuteReset(const ResetRequest& request, const ResetParams& params,
                          std::uint64_t seed, std::uint64_t trial_id);

// The placements a simulated reset aimed at one trial draws, in order:
// placement k ends at target (+) N(0, placement std) per axis and is seen at
// that (+) N(0, sensing std) per axis; the first within tolerance of the
// target is kept (at most max_attempts are drawn).
struct Placement {
  Pose true_pose;             // where the object ends
  Pose observed;              // what verification saw
  int placements = 0;         // placements drawn, 1..max_attempts
  bool verified = false;      // false: none verified; the last one is returned
  double position_error = 0;  // m, observed vs target
  double angle_error = 0;     // rad
};
// Pure: the same (target, params, trial_seed) give the same placement bit for
// bit. A simulated cell starts a trial here when its own last reset was not
// aimed at that trial (another cell took it, or no reset ran yet): a
// simulation's bookkeeping, as if its reset had been (executors/README.md).
// @pre ValidateResetParams(params) passes.
Placement PlacementForTrial(const Pose& target, const ResetParams& params,
                            std::uint64_t trial_seed);

// Angle (rad) of the rotation between two orientations.
double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

}  // namespace arena::reset
