// The `arena` simulator: arena's own contact model at chosen settings.
#include <algorithm>

#include <nlohmann/json.hpp>

#include "arena/simulators/simulator.hpp"

namespace arena::simulators {
namespace {

class ArenaSimulator final : public Simulator {
 public:
  explicit ArenaSimulator(const ArenaSettings& s) : settings_(s) {
    if (s.facets != 0 && s.facets < 3) throw SimulatorError("arena.facets", "must be 0 or >= 3");
    if (s.points < 0) throw SimulatorError("arena.points", "must be 0 or >= 1");
    if (!(s.dt >= 0) || s.dt > 1) throw SimulatorError("arena.dt", "must be 0 or in (0, 1] s");
  }
  std::string name() const override { return "arena"; }
  TruthKind truth() const override { return TruthKind::kSelfConsistency; }
  std::string settings_json() const override {
    return nlohmann::json({{"facets", settings_.facets},
                           {"points", settings_.points},
                           {"dt", settings_.dt},
                           {"at_least", settings_.at_least}})
        .dump();
  }
  std::string CheckScene(const mechanics::Scene&) const override { return ""; }

  mechanics::SimulationResult Simulate(const mechanics::Scene& scene) const override {
    return mechanics::Simulate(AtSettings(scene));
  }
  bool closed_loop() const override { return true; }
  mechanics::SimulationResult SimulateClosedLoop(
      const mechanics::Scene& scene,
      const mechanics::PusherCommandSource& commands) const override {
    return mechanics::Simulate(AtSettings(scene), commands);
  }

 private:
  mechanics::Scene AtSettings(const mechanics::Scene& scene) const {
    mechanics::Scene s = scene;
    auto& m = s.model;
    if (settings_.at_least) {
      if (settings_.facets) m.facets = std::max(m.facets, settings_.facets);
      if (settings_.points) m.points = std::max(m.points, settings_.points);
      if (settings_.dt > 0) m.dt = std::min(m.dt, settings_.dt);
    } else {
      if (settings_.facets) m.facets = settings_.facets;
      if (settings_.points) m.points = settings_.points;
      if (settings_.dt > 0) m.dt = settings_.dt;
    }
    return s;
  }

  ArenaSettings settings_;
};

// The default PreparedScene: nothing to keep, every variant run afresh.
class FreshRuns final : public PreparedScene {
 public:
  explicit FreshRuns(const Simulator& simulator) : simulator_(simulator) {}
  mechanics::SimulationResult Simulate(const mechanics::Scene& variant) override {
    ++runs_;
    return simulator_.Simulate(variant);
  }
  long reused() const override { return 0; }
  long rebuilt() const override { return runs_; }

 private:
  const Simulator& simulator_;
  long runs_ = 0;
};

}  // namespace

std::unique_ptr<PreparedScene> Simulator::Prepare(const mechanics::Scene&) const {
  return std::make_unique<FreshRuns>(*this);
}

const char* ToString(TruthKind kind) {
  switch (kind) {
    case TruthKind::kSelfConsistency:
      return "self-consistency";
    case TruthKind::kIndependent:
      return "independent";
  }
  return "?";
}

std::unique_ptr<Simulator> MakeArenaSimulator(const ArenaSettings& settings) {
  return std::make_unique<ArenaSimulator>(settings);
}

}  // namespace arena::simulators
