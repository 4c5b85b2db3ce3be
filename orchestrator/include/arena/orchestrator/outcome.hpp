// A trial's outcome, computed from its ground truth by pure functions: what
// the boundary sampler classifies and the replicates sampler measures.
// (Until the store keeps per-contact outcomes itself, they are derived here
// from the stored samples.)
#pragma once

#include <array>
#include <vector>

#include "arena/db/sample.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/campaign.hpp"

namespace arena::orchestrator {

// What the outcome functions need of a trajectory.
struct TrialOutcome {
  std::array<double, 3> final_position{};  // m, object, gripper frame
  double displacement = 0;                 // m, |final - initial position|
  double rotation = 0;                     // rad, net rotation angle initial -> final, [0, pi]
  double finger_slide_fraction = 0;        // of (sample, finger) pairs in slide mode
  bool fingers_touching_at_end = true;     // no finger separated over the last 10 % of samples
  int samples = 0;
};

// @param fingers: the scene's finger count (contacts after them, the pusher, are ignored).
TrialOutcome ComputeOutcome(const std::vector<db::Sample>& samples, int fingers);
TrialOutcome ComputeOutcome(const std::vector<mechanics::TrajectorySample>& samples, int fingers);

// The class the boundary sampler looks at: pivoted: rotation > threshold;
// finger_slip: finger_slide_fraction > threshold; grasp_kept: fingers
// touching at the end and displacement <= threshold.
bool Classify(OutcomeKind kind, double threshold, const TrialOutcome& outcome);
// "pivoted"/"not pivoted", "slide"/"stick", "kept"/"lost".
const char* ClassName(OutcomeKind kind, bool positive);

}  // namespace arena::orchestrator
