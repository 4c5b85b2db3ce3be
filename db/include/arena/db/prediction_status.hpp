// A prediction's status as a type: db::Prediction::status holds its text
// (ok, solver_failure, invalid_scene, error, diverged), which RecordPrediction
// checks. diverged: the prediction ran but left the grasp or blew up
// (assessment::PredictionOutcome::kDiverged): counted apart, never averaged in.
#pragma once

#include <optional>
#include <string>

namespace arena::db {

enum class PredictionStatus { kOk, kSolverFailure, kInvalidScene, kError, kDiverged };
const char* ToString(PredictionStatus status);
std::optional<PredictionStatus> ParsePredictionStatus(const std::string& text);

}  // namespace arena::db
