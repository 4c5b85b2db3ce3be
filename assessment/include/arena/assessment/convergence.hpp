// Self-consistency apart from accuracy (the protocol of Erez, Tassa &
// Todorov, ICRA 2015): short pieces of a trial are restarted from the true
// state and run at every setting of a predictor and at its finest setting;
// the gap between the two is the discretisation error of that setting,
// which chaos cannot amplify because each piece starts from the truth.
// Beside the error against the truth it shows which part of the error is
// discretisation and which is the model.
#pragma once

#include <optional>
#include <vector>

#include "arena/assessment/evaluation.hpp"
#include "arena/assessment/predictor.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

// The scene restarted at the true sample `from`: object pose and pusher
// contact from the sample, fingers where the gripper holds them, `duration`
// long. Absent when that scene is not valid (e.g. a contact no longer on
// the object's surface after a turn).
std::optional<mechanics::Scene> RestartScene(const mechanics::Scene& scene,
                                             const mechanics::TrajectorySample& from,
                                             double duration);

// One trial's pieces: `pieces` restarts evenly spaced over the truth, each
// (trial duration / pieces) long.
struct ConvergenceTrial {
  mechanics::Scene scene;
  std::vector<mechanics::TrajectorySample> truth;
};

// Per setting of `predictor`: the distance at the end of each piece between
// that setting and the finest one (pieces where either failed are left out).
std::vector<std::optional<Convergence>> ConvergenceTable(
    const Predictor& predictor, const std::vector<ConvergenceTrial>& trials, int pieces = 4);

}  // namespace arena::assessment
