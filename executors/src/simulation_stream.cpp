#include "simulation_stream.hpp"

#include <string>

#include <nlohmann/json.hpp>

namespace arena::executors {
namespace {

std::string SimulationFailure(const mechanics::SimulationResult& r) {
  switch (r.status) {
    case mechanics::SimulationStatus::kOk:
      return "simulation: ok: " + r.error;  // ok but no samples
    case mechanics::SimulationStatus::kSolverFailure:
      return "simulation: solver failure: " + r.error;
    case mechanics::SimulationStatus::kInvalidScene:
      return "simulation: invalid scene: " + r.error;
  }
  return "simulation: " + r.error;
}

}  // namespace

ExecuteOutcome StreamSimulation(const mechanics::SimulationResult& r, const SampleSink& sink) {
  ExecuteOutcome out;
  out.simulate_wall_s = r.wall_s;
  nlohmann::json detail(
      {{"model",
        {{"dof", r.model.dof},
         {"facets", r.model.facets},
         {"points", r.model.points},
         {"dt", r.model.dt},
         {"unknowns", r.model.unknowns}}},
       {"residuals",
        {{"force_balance", r.residuals.force_balance},
         {"complementarity", r.residuals.complementarity},
         {"cone", r.residuals.cone}}},
       {"solver", nlohmann::json::parse(mechanics::SolverStatisticsJson(r.solver))},
       {"simulate_wall_s", r.wall_s}});
  // The truth's final pose is one phase of a swing when it ends in one, and
  // its start an impact dt did not resolve when it was one: said.
  detail.update(nlohmann::json::parse(mechanics::RunFlagsJson(r)));
  out.detail_json = detail.dump();
  if (r.status != mechanics::SimulationStatus::kOk || r.samples.empty()) {
    out.reason = SimulationFailure(r);
    out.failure = ExecuteFailure::kSimulation;
    return out;
  }
  for (const auto& s : r.samples) {
    if (!sink(s)) {
      out.reason = "interrupted";
      out.failure = ExecuteFailure::kBackend;  // the cell stopped it: its own reason goes first
      return out;
    }
  }
  out.ok = true;
  return out;
}

}  // namespace arena::executors
