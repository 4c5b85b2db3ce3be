// How a trial ended (the trials.outcome column) as a type: Trial::outcome,
// FailTrial and Ingest::Finish hold it (db::TrialOutcome is another idea: the
// motion a stream shows). Its text ("", ok, solver_failure, invalid_scene,
// refused, failed, cancelled) is written and read only at the store's edge.
#pragma once

#include <optional>
#include <string>

namespace arena::db {

enum class TrialEnd {
  kNone,           // "": not set yet
  kOk,             // the cell ran it
  kSolverFailure,  // the simulating cell's solver found no solution (a re-run is identical)
  kInvalidScene,   // the scene cannot be run (refused before dispatch)
  kRefused,        // the cell refused the scene
  kFailed,         // attempts exhausted, or failed for another reason
  kCancelled,      // its campaign was cancelled
};
const char* ToString(TrialEnd outcome);
std::optional<TrialEnd> ParseTrialEnd(const std::string& text);

}  // namespace arena::db
