// A prediction's status as a type: db::Prediction::status holds its text
// (ok, solver_failure, invalid_scene, error), which RecordPrediction checks.
#pragma once

#include <optional>
#include <string>

namespace arena::db {

enum class PredictionStatus { kOk, kSolverFailure, kInvalidScene, kError };
const char* ToString(PredictionStatus status);
std::optional<PredictionStatus> ParsePredictionStatus(const std::string& text);

}  // namespace arena::db
