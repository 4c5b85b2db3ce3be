// Ground truth from the wire (the DDS message) into the store's plain sample
// and the model's trajectory sample. The store keeps each contact force as one
// vector in the gripper frame; the wire splits it along the contact normal, so
// converting needs the scene's contact normals (assessment::ContactNormals).
// The store-to-model half is assessment/truth.hpp.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "arena/db/outcomes.hpp"
#include "arena/db/sample.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::msg {
class GroundTruthSample;
}

namespace arena::orchestrator {

// @pre the sample passed dds::CheckSample and has one contact per normal,
//   or none at all when `contactless_ok` (a measured cell's trial whose
//   truth measured no forces: the service checks the cell's statement of it
//   against the whole stream when the EXECUTE status arrives).
// @throws std::invalid_argument when the contact count differs from the normals'.
db::Sample ToStoreSample(const msg::GroundTruthSample& sample,
                         const std::vector<Eigen::Vector3d>& normals,
                         mechanics::TrajectorySample* truth = nullptr, bool contactless_ok = false);

// The scene's contacts as the store's outcomes need them (db/outcomes.hpp):
// fingers in order, then the pusher, from the scene already parsed, so the
// store never parses a scene on the ingest path.
std::vector<db::ContactSite> ContactSitesOf(const mechanics::Scene& scene);

// What a cell's EXECUTED status detail says ran the trial: its top-level
// "backend" and "truth" strings ("" when absent or not strings) and the text
// of its top-level "defects_applied" value as the cell wrote it (nullopt:
// none). Read with one pass that builds nothing and a scan for that value's
// extent, not a parse into a document and a dump back (issue 27: the stated
// truth is needed between the stream's end and the RESET). nullopt when the
// detail is not a well-formed JSON object. A repeated key: the last counts.
struct ExecutionDetail {
  std::string backend, truth;
  std::optional<std::string> defects_applied;
};
std::optional<ExecutionDetail> ReadExecutionDetail(std::string_view detail_json);

}  // namespace arena::orchestrator
