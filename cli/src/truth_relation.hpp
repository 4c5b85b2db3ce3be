// Whether a predictor is measured against an independent truth or against
// its own engine: MuJoCo predicting trials a MuJoCo cell ran, or arena's
// model predicting the model backend's trials, is self-consistency, never
// accuracy (issue 26). `truth_source` is the evaluation report's
// truth.source: the campaign's backends, comma separated ("model,mujoco").
#pragma once

#include <sstream>
#include <string>

namespace arena::cli {

// The backend that runs a predictor's engine as a cell ("" if none does).
inline std::string EngineBackend(const std::string& predictor) {
  if (predictor == "arena") return "model";
  if (predictor == "mujoco") return "mujoco";
  return "";
}

// true when the predictor's engine produced (some of) the truth.
inline bool SelfConsistent(const std::string& predictor, const std::string& truth_source) {
  const std::string engine = EngineBackend(predictor);
  if (engine.empty()) return false;
  std::stringstream in(truth_source);
  for (std::string backend; std::getline(in, backend, ',');)
    if (backend == engine) return true;
  return false;
}

}  // namespace arena::cli
