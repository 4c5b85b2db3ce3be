// A prediction's status: db::Prediction::status and PredictedStream::status
// hold it as a type; its text (ok, solver_failure, invalid_scene, error,
// diverged) is written only at the store's and the export's edge. diverged:
// the prediction ran but left the grasp or blew up: counted apart, never
// averaged in.
#pragma once

#include <optional>
#include <string>

namespace arena::db {

enum class PredictionStatus { kOk, kSolverFailure, kInvalidScene, kError, kDiverged };
const char* ToString(PredictionStatus status);
std::optional<PredictionStatus> ParsePredictionStatus(const std::string& text);
// A stored status as read back: "left_geometry" (frozen-frame predictions
// whose fingers left the object, stored by older versions) is kDiverged; a
// text no version wrote is kError.
PredictionStatus StoredPredictionStatus(const std::string& text);

}  // namespace arena::db
