// A simulated backend's run as an EXECUTE outcome: the model's figures in the
// detail, a failed run as a simulation failure, every sample to the sink.
// Shared by the `model` stand-in and the simulators-room backends.
#pragma once

#include "arena/executors/backend.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::executors {

// @returns ok when every sample went to the sink; reason "interrupted" when
//   the sink stopped it (the cell knows why).
ExecuteOutcome StreamSimulation(const mechanics::SimulationResult& r, const SampleSink& sink);

}  // namespace arena::executors
