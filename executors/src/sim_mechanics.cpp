// The real mechanics behind the simulated cell (kept in its own file so that
// code which brings its own backend does not link the model).
#include <algorithm>

#include <nlohmann/json.hpp>

#include "arena/executors/cell.hpp"
#include "arena/mechanics/scene_json.hpp"

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
    const mechanics::SimulationResult r = m_.simulate(AtFidelity(scene));
    ExecuteOutcome out;
    out.simulate_wall_s = r.wall_s;
    out.detail_json = nlohmann::json({{"model",
                                       {{"dof", r.model.dof},
                                        {"facets", r.model.facets},
                                        {"points", r.model.points},
                                        {"dt", r.model.dt},
                                        {"unknowns", r.model.unknowns}}},
                                      {"residuals",
                                       {{"force_balance", r.residuals.force_balance},
                                        {"complementarity", r.residuals.complementarity},
                                        {"cone", r.residuals.cone}}},
                                      {"solver",
                                       {{"steps", r.solver.steps},
                                        {"max_pivots", r.solver.max_pivots},
                                        {"failures", r.solver.failures}}},
                                      {"simulate_wall_s", r.wall_s}})
                          .dump();
    if (r.status != mechanics::SimulationStatus::kOk || r.samples.empty()) {
      const char* what = r.status == mechanics::SimulationStatus::kSolverFailure  ? "solver failure"
                         : r.status == mechanics::SimulationStatus::kInvalidScene ? "invalid scene"
                                                                                  : "ok";
      out.reason = std::string("simulation: ") + what + ": " + r.error;
      out.solver_failure = true;
      return out;
    }
    for (const auto& s : r.samples)
      if (!sink(s)) return out;
    out.ok = true;
    return out;
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
