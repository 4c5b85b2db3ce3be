// The predicted outcome of one push, as sensitivity and stability analysis
// see it: a few continuous quantities (differentiable, in SI units) and the
// discrete facts a small change can flip (each contact's mode sequence,
// whether the grasp is kept). Frames: everything in the gripper frame.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

// Any predictor: arena's own model (mechanics::Simulate, the default), a
// simulators:: backend, a lab's surrogate. Must be callable from several
// threads at once (the analysis runs model runs in parallel).
using SimulateFn = std::function<mechanics::SimulationResult(const mechanics::Scene&)>;

// mechanics::Simulate as a SimulateFn.
SimulateFn DefaultSimulate();

// The continuous outcome quantities, in this order everywhere.
enum class Quantity : int {
  kPositionX,     // m, final object position (gripper frame)
  kPositionY,     // m
  kPositionZ,     // m
  kRoll,          // rad, final orientation, roll-pitch-yaw about fixed x, y, z
  kPitch,         // rad
  kYaw,           // rad
  kRotation,      // rad, net rotation angle from the start pose, [0, pi]
  kDisplacement,  // m, |final - start position|
  kPusherForce,   // N, mean |pusher force| over the push (0 without a pusher)
};
inline constexpr int kQuantityCount = 9;
enum class QuantityKind { kLength, kAngle, kForce };

const char* Name(Quantity q);  // "position_x", "roll", "rotation", "pusher_force", ...
const char* Unit(Quantity q);  // "m", "rad", "N"
QuantityKind KindOf(Quantity q);

// Runs shorter than this many 250 Hz samples (8 ms) are not part of a mode
// sequence: a one-sample flicker at a step's start is solver detail, not a
// change of contact mode a person would see.
inline constexpr int kMinModeRunSamples = 2;

struct Outcome {
  bool ok = false;
  std::string error;  // the predictor's reason when !ok
  std::array<double, kQuantityCount> values{};
  Eigen::Vector3d rotation_vector = Eigen::Vector3d::Zero();  // rad, axis * angle of q_end q_0^-1
  bool grasp_kept = false;
  // Per contact (fingers in scene order, then the pusher): its modes over the
  // push with runs shorter than kMinModeRunSamples dropped, e.g. {kStick, kSlide}.
  std::vector<std::vector<mechanics::ContactMode>> modes;

  double value(Quantity q) const { return values[static_cast<int>(q)]; }
};

// The outcome of `result` (a run of `scene`).
// Grasp kept: the run finished, every finger still presses on the object at
// the end, and every finger's contact point, carried into the object's final
// frame, is still on the object's face (box: within the face's extent;
// cylinder: within its height) -- the object has not slid or turned out of
// the fingers.
Outcome MeasureOutcome(const mechanics::Scene& scene, const mechanics::SimulationResult& result);

// "stick>slide>stick" (or "-" when the contact never touched).
std::string ModeSequenceText(const std::vector<mechanics::ContactMode>& modes);

// The discrete part: ok, grasp kept and every contact's mode sequence equal.
bool SameDiscreteOutcome(const Outcome& a, const Outcome& b);

// What differs between two discrete outcomes, for a person:
// "right: stick -> stick>slide; grasp kept -> lost". Empty when the same.
std::string DescribeDiscreteChange(const mechanics::Scene& scene, const Outcome& from,
                                   const Outcome& to);

// Contact names: fingers in scene order, then "pusher".
std::vector<std::string> ContactNames(const mechanics::Scene& scene);

}  // namespace arena::assessment
