// The real mechanics behind the simulated cell (kept in its own file so that
// code which brings its own backend does not link the model).
#include <algorithm>

#include <nlohmann/json.hpp>

#include "arena/executors/cell.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "simulation_stream.hpp"

namespace arena::executors {

MechanicsBackend DefaultMechanics() {
  MechanicsBackend backend;
  backend.parse = [](std::string_view text) { return mechanics::ParseScene(text); };
  backend.simulate = [](const mechanics::Scene& scene) { return mechanics::Simulate(scene); };
  backend.simulate_closed_loop = [](const mechanics::Scene& scene,
                                    const mechanics::PusherCommandSource& commands) {
    return mechanics::Simulate(scene, commands);
  };
  return backend;
}

namespace {

// The `model` backend over a MechanicsBackend's simulate (the real model or a
// test's closed-form stand-in), at least at the cell's fidelity.
class MechanicsStandIn final : public Backend {
 public:
  MechanicsStandIn(MechanicsBackend m, const Fidelity& f) : m_(std::move(m)), f_(f) {}
  BackendCapabilities Capabilities() const override {
    BackendCapabilities c;
    c.name = "model";
    c.truth = TruthSource::kSelfConsistency;
    c.engine = "arena contact model";
    c.settings_json =
        nlohmann::json({{"facets", f_.facets}, {"points", f_.points}, {"dt", f_.dt}}).dump();
    c.closed_loop = static_cast<bool>(m_.simulate_closed_loop);
    return c;
  }
  std::string Prepare(const mechanics::Scene&, const TrialContext&) override { return ""; }
  mechanics::SimulationResult SimulateClosedLoop(
      const mechanics::Scene& scene, const mechanics::PusherCommandSource& commands) override {
    return m_.simulate_closed_loop(AtFidelity(scene), commands);
  }
  ExecuteOutcome Execute(const mechanics::Scene& scene, const TrialContext&,
                         const SampleSink& sink) override {
    return StreamSimulation(m_.simulate(AtFidelity(scene)), sink);
  }

 private:
  mechanics::Scene AtFidelity(const mechanics::Scene& scene) const {
    mechanics::Scene actual = scene;
    actual.model.facets = std::max(actual.model.facets, f_.facets);
    actual.model.points = std::max(actual.model.points, f_.points);
    actual.model.dt = std::min(actual.model.dt, f_.dt);
    return actual;
  }

  MechanicsBackend m_;
  Fidelity f_;
};

}  // namespace

std::unique_ptr<Backend> MakeMechanicsStandIn(const MechanicsBackend& mechanics,
                                              const Fidelity& fidelity) {
  return std::make_unique<MechanicsStandIn>(mechanics, fidelity);
}

}  // namespace arena::executors
