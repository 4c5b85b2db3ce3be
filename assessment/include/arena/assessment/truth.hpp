// Ground truth as the model sees it: the store keeps each contact force as
// one vector in the gripper frame; the model splits it along the contact
// normal, so converting needs the scene's contact normals (fingers in scene
// order, then the pusher). The wire-to-store half lives with the service
// (orchestrator/trial_data.hpp), since only it touches DDS messages.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "arena/db/sample.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

// Unit normals into the object, one per contact: fingers, then the pusher.
std::vector<Eigen::Vector3d> ContactNormals(const mechanics::Scene& scene);

// The true state of a stored sample as the model's sample. A truth without
// forces (`forces_measured` false: db::GroundTruth::forces_measured) has no
// contacts, and the model's sample then has none either (no force scored).
// @throws std::invalid_argument when the contact count differs from the
//   normals' (or, without forces, is not 0).
mechanics::TrajectorySample ToTrajectorySample(const db::Sample& sample,
                                               const std::vector<Eigen::Vector3d>& normals,
                                               bool has_pusher, bool forces_measured = true);

// A stored trial's ground truth as the model's trajectory (ReadGroundTruth
// then ToTrajectorySample for every sample, with the trial's stated truth:
// a measured trial without forces has samples without contacts).
// @throws db::StoreError from the store, std::invalid_argument on a contact mismatch.
std::vector<mechanics::TrajectorySample> ReadTruth(const db::Store& store, std::int64_t trial_id,
                                                   const mechanics::Scene& scene);

}  // namespace arena::assessment
