// Ground truth between its three shapes: the DDS message (schemas), the
// store's plain sample (db) and the model's trajectory sample (mechanics).
// The store keeps each contact force as one vector in the gripper frame; the
// model and the wire split it along the contact normal, so converting needs
// the scene's contact normals (fingers in scene order, then the pusher).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "arena/db/sample.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::msg {
class GroundTruthSample;
}

namespace arena::orchestrator {

// Unit normals into the object, one per contact: fingers, then the pusher.
std::vector<Eigen::Vector3d> ContactNormals(const mechanics::Scene& scene);

// @pre the sample passed dds::CheckSample and has one contact per normal.
// @throws std::invalid_argument when the contact count differs from the normals'.
db::Sample ToStoreSample(const msg::GroundTruthSample& sample,
                         const std::vector<Eigen::Vector3d>& normals,
                         mechanics::TrajectorySample* truth = nullptr);

// The true state of a stored sample as the model's sample.
// @throws std::invalid_argument when the contact count differs from the normals'.
mechanics::TrajectorySample ToTrajectorySample(const db::Sample& sample,
                                               const std::vector<Eigen::Vector3d>& normals,
                                               bool has_pusher);

}  // namespace arena::orchestrator
