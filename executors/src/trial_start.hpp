// A cell's rules for where a trial starts and what the next trial's pusher
// asks of the reset (issue 12), apart from the cell's DDS and threads so that
// they are tested on their own (tests/executors/trial_start_test.cpp).
//
//   ResetEnded(seed, target, pose)   a simulated reset left the object at `pose`,
//                                    aimed at the trial with `seed` starting at `target`
//   TrialRan()                       the trial moved the object: no reset's pose holds
//   StartPose(seed, target, ...)     where that trial starts (nullopt: as planned)
//   PlacedAt(scene, start)           the scene with its object there, fingers seated
//   ChangeOfPusher(now, next)        nothing, a move of the same pusher, or a swap
//   EmulatedChangeSeconds(changes, in_reset)
//                                    what a simulated cell spends on fixture
//                                    changes (issue 29) besides its reset plan
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "arena/mechanics/scene.hpp"
#include "arena/reset/reset.hpp"
#include "arena/schemas/fixtures.hpp"

namespace arena::executors {

// What the next trial's pusher asks of the cell: nothing, a move of the same
// pusher (only its contact point differs: the arm places it), or a swap
// (another geometry or direction: a tool change).
struct PusherChange {
  bool swap = false;
  double move_m = 0;
};
PusherChange ChangeOfPusher(const std::optional<mechanics::PusherSpec>& now,
                            const std::optional<mechanics::PusherSpec>& next);

// Fixture changes (schemas/fixtures.hpp): a reset aimed at the next trial
// makes the changes its scene asks for (the finger pads, the pusher, the
// object); a trial the cell runs with other fixtures than those mounted (a
// fresh cell, or a trial other than the one its reset was aimed at) has them
// made first, in EXECUTE. A simulated cell spends the declared seconds
// (scaled by --speed like every phase); in a reset the pusher's change is
// the plan's own swap primitive (reset.swap_time), so it is not counted twice.
double EmulatedChangeSeconds(const std::vector<schemas::FixtureChange>& changes, bool in_reset);
// Whether `changes` include a change of the pusher tool.
bool ChangesPusher(const std::vector<schemas::FixtureChange>& changes);

class TrialStart {
 public:
  // A simulated reset of this cell ended with the object at `pose`; it was
  // aimed at the trial with `seed` whose planned start is `target`.
  void ResetEnded(std::uint64_t seed, const reset::Pose& target, const reset::Pose& pose);
  // The trial moved the object: the last reset's pose no longer holds.
  void TrialRan() { left_.reset(); }

  // Where a trial starts on a simulated cell (nullopt: as planned). The
  // placement error belongs to the trial the placement prepares
  // (reset::PlacementForTrial): the cell's own reset if it was aimed at this
  // very trial, otherwise the same pure draw for this trial -- as if the
  // cell's reset had been aimed at it. That is the simulation's bookkeeping
  // (the driver aims a reset at the trial it expects next; another cell may
  // take it, and a fresh cell has reset nothing), so a trial's truth never
  // depends on which cell ran it or what ran before. A backend that does not
  // emulate defects (`emulated` false: a robot, recorded data) has its own
  // start and is left alone.
  std::optional<reset::Pose> StartPose(std::uint64_t seed, const reset::Pose& target,
                                       const reset::ResetParams& params, bool emulated) const;

  // The scene with its object at `start` (nullopt: unchanged), the fingers
  // closed on it there (mechanics::SeatFingers). @throws mechanics::SceneError
  // when a finger misses the object.
  static mechanics::Scene PlacedAt(mechanics::Scene scene, const std::optional<reset::Pose>& start);

 private:
  struct Left {
    std::uint64_t seed = 0;  // the prepared trial's seed
    reset::Pose target;      // its planned start pose
    reset::Pose pose;        // where the object really ended
  };
  std::optional<Left> left_;  // the last successful simulated reset, until a trial runs
};

}  // namespace arena::executors
