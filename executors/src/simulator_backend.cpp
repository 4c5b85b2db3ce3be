// The simulated backends, `model` and `mujoco`, on simulators/, and the
// backend factory by name.
#include <cmath>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arena/executors/backend.hpp"
#include "arena/simulators/simulator.hpp"
#include "simulation_stream.hpp"

namespace arena::executors {
namespace {

class SimulatorBackend final : public Backend {
 public:
  SimulatorBackend(std::string name, TruthSource truth, std::unique_ptr<simulators::Simulator> sim,
                   std::string engine)
      : sim_(std::move(sim)) {
    caps_.name = std::move(name);
    caps_.truth = truth;
    caps_.engine = std::move(engine);
    caps_.emulates_defects = true;
    caps_.settings_json = sim_->settings_json();
    caps_.closed_loop = sim_->closed_loop();
  }
  BackendCapabilities Capabilities() const override { return caps_; }
  std::string Prepare(const mechanics::Scene& scene, const TrialContext&) override {
    const std::string why = sim_->CheckScene(scene);
    return why.empty() ? "" : caps_.name + " backend: " + why;
  }
  ExecuteOutcome Execute(const mechanics::Scene& scene, const TrialContext&,
                         const SampleSink& sink) override {
    return StreamSimulation(sim_->Simulate(scene), sink);
  }
  mechanics::SimulationResult SimulateClosedLoop(
      const mechanics::Scene& scene, const mechanics::PusherCommandSource& commands) override {
    return sim_->SimulateClosedLoop(scene, commands);
  }

 private:
  BackendCapabilities caps_;
  std::unique_ptr<simulators::Simulator> sim_;
};

}  // namespace

const char* ToString(TruthSource s) {
  switch (s) {
    case TruthSource::kSelfConsistency:
      return "self-consistency";
    case TruthSource::kSimulator:
      return "simulator";
    case TruthSource::kRobot:
      return "robot";
    case TruthSource::kRecorded:
      return "recorded";
    case TruthSource::kMeasured:
      return "measured";
  }
  return "?";
}

TruthSource ParseTruthSource(std::string_view name) {
  for (auto s : {TruthSource::kSelfConsistency, TruthSource::kSimulator, TruthSource::kRobot,
                 TruthSource::kRecorded, TruthSource::kMeasured}) {
    if (name == ToString(s)) return s;
  }
  throw std::invalid_argument("truth: unknown value '" + std::string(name) +
                              "' (self-consistency, simulator, robot, recorded, measured)");
}

std::unique_ptr<Backend> MakeModelBackend(const ModelFidelity& f) {
  simulators::ArenaSettings s;
  s.facets = f.facets;
  s.points = f.points;
  s.dt = f.dt;
  s.at_least = true;  // a scene asking for finer settings keeps its own
  char engine[96];
  std::snprintf(engine, sizeof engine, "arena contact model (at least g%d k%d dt %g)", f.facets,
                f.points, f.dt);
  return std::make_unique<SimulatorBackend>("model", TruthSource::kSelfConsistency,
                                            simulators::MakeArenaSimulator(s), engine);
}

std::unique_ptr<Backend> MakeMujocoBackend(std::string_view settings_json) {
  auto sim = simulators::MakeSimulator("mujoco", settings_json);
  const auto settings = nlohmann::json::parse(sim->settings_json());
  return std::make_unique<SimulatorBackend>("mujoco", TruthSource::kSimulator, std::move(sim),
                                            settings.value("engine", std::string("MuJoCo")));
}

std::unique_ptr<Backend> MakeBackend(std::string_view spec, const ModelFidelity& fidelity,
                                     std::string_view settings_json) {
  try {
    if (spec == "model") {
      if (!settings_json.empty() && settings_json != "{}")
        throw std::invalid_argument(
            "--backend-settings: the model backend takes none (use the "
            "cell's fidelity)");
      return MakeModelBackend(fidelity);
    }
    if (spec == "mujoco") return MakeMujocoBackend(settings_json);
    if (spec.rfind("exec:", 0) == 0) {
      ExecBackendOptions o;
      o.command = std::string(spec.substr(5));
      if (o.command.empty()) throw std::invalid_argument("exec: needs a command (exec:COMMAND)");
      return MakeExecBackend(o);
    }
    if (spec.rfind("replay:", 0) == 0) {
      const std::string dir(spec.substr(7));
      if (dir.empty()) throw std::invalid_argument("replay: needs a dataset (replay:DIR)");
      return MakeReplayBackend(dir);
    }
  } catch (const simulators::SimulatorError& e) {
    throw std::invalid_argument(std::string("--backend-settings: ") + e.what());
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    if (what.rfind("--backend", 0) == 0) throw;
    throw std::invalid_argument("--backend " + std::string(spec) + ": " + what);
  }
  throw std::invalid_argument("--backend: unknown backend '" + std::string(spec) +
                              "' (model, mujoco, exec:COMMAND, replay:DATASET)");
}

}  // namespace arena::executors
