#include "arena/assessment/predictor.hpp"

#include <algorithm>
#include <cstdio>
#include <numeric>
#include <set>
#include <stdexcept>
#include <thread>

#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/simulators/simulator.hpp"

namespace arena::assessment {

namespace {

// A scene a predictor's setting cannot take: a result saying so, not an exception.
mechanics::SimulationResult InvalidScene(const std::string& why) {
  mechanics::SimulationResult r;
  r.status = mechanics::SimulationStatus::kInvalidScene;
  r.error = why;
  return r;
}

// Each setting's refinement rank (0 = coarsest): `knobs[i]` describes
// settings[i]; `coarser(x, y)` is true when x is the coarser of the two.
template <typename Knobs, typename Coarser>
void RankByRefinement(const std::vector<Knobs>& knobs, std::vector<PredictorSetting>* settings,
                      Coarser coarser) {
  std::vector<std::size_t> order(knobs.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return coarser(knobs[a], knobs[b]); });
  for (std::size_t rank = 0; rank < order.size(); ++rank)
    (*settings)[order[rank]].refinement = static_cast<int>(rank);
}

class ArenaPredictor final : public Predictor {
 public:
  explicit ArenaPredictor(std::vector<mechanics::ModelOptions> grid) : models_(std::move(grid)) {
    if (models_.empty()) throw std::invalid_argument("arena predictor: the grid is empty");
    std::set<std::string> keys;
    for (const auto& m : models_) {
      PredictorSetting s;
      s.key = ModelKey(m);
      if (!keys.insert(s.key).second) {
        throw std::invalid_argument("arena predictor: setting " + s.key + " is repeated");
      }
      nlohmann::json knobs = {{"predictor", "arena"},
                              {"facets", m.facets},
                              {"points", m.points},
                              {"dt", m.dt},
                              {"reduce", mechanics::ToString(m.reduce)},
                              {"contacts", mechanics::ToString(m.contacts)}};
      // The opt-in choices only where they differ from the model's defaults,
      // as the key names them: earlier evaluations' knobs stay the same.
      const mechanics::ModelOptions defaults;
      if (m.pads != defaults.pads) knobs["pads"] = mechanics::ToString(m.pads);
      if (m.cone != defaults.cone) knobs["cone"] = mechanics::ToString(m.cone);
      if (m.inertia != defaults.inertia) knobs["inertia"] = mechanics::ToString(m.inertia);
      s.knobs_json = knobs.dump();
      s.step = m.dt;
      settings_.push_back(std::move(s));
    }
    // Finer: smaller step first, then more facets, then more points.
    RankByRefinement(models_, &settings_, [](const auto& x, const auto& y) {
      if (x.dt != y.dt) return x.dt > y.dt;
      if (x.facets != y.facets) return x.facets < y.facets;
      return x.points < y.points;
    });
  }
  const std::string& name() const override { return name_; }
  const std::vector<PredictorSetting>& settings() const override { return settings_; }
  mechanics::SimulationResult Run(const mechanics::Scene& scene,
                                  std::size_t setting) const override {
    return SimulateAt(scene, setting,
                      [](const mechanics::Scene& s) { return mechanics::Simulate(s); });
  }
  mechanics::SimulationResult RunClosedLoop(
      const mechanics::Scene& scene, std::size_t setting,
      const mechanics::PusherCommandSource& commands) const override {
    return SimulateAt(scene, setting, [&commands](const mechanics::Scene& s) {
      return mechanics::Simulate(s, commands);
    });
  }
  std::string EffectiveKey(const mechanics::Scene& scene, std::size_t setting) const override {
    auto extended = [](const mechanics::ContactSpec& c) {
      return c.type != mechanics::ContactType::kPoint;
    };
    bool points_matter = std::any_of(scene.fingers.begin(), scene.fingers.end(), extended) ||
                         (scene.pusher && extended(*scene.pusher));
    if (points_matter) return settings_.at(setting).key;
    mechanics::ModelOptions m = models_.at(setting);
    m.points = 0;  // irrelevant here: every contact is a point
    return ModelKey(m);
  }

 private:
  // The scene at one of this predictor's settings; a setting the scene
  // cannot take is an invalid-scene result, not an exception.
  template <class Simulation>
  mechanics::SimulationResult SimulateAt(const mechanics::Scene& scene, std::size_t setting,
                                         const Simulation& run) const {
    mechanics::Scene s = scene;
    s.model = models_.at(setting);
    try {
      mechanics::ValidateScene(s);
    } catch (const std::exception& e) {
      return InvalidScene(e.what());
    }
    return run(s);
  }

  std::string name_ = "arena";
  std::vector<mechanics::ModelOptions> models_;
  std::vector<PredictorSetting> settings_;
};

// "0.002:1" for a key.
template <std::size_t N>
std::string FormatList(const std::array<double, N>& values) {
  std::string out;
  for (double v : values) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    if (!out.empty()) out += ':';
    out += buf;
  }
  return out;
}

std::array<double, 2> DefaultSolref() {
  const simulators::MujocoSettings d;
  return {d.solref_timeconst, d.solref_damping};
}
std::array<double, 5> DefaultSolimp() {
  const simulators::MujocoSettings d;
  std::array<double, 5> out;
  std::copy(std::begin(d.solimp), std::end(d.solimp), out.begin());
  return out;
}

class MujocoPredictor final : public Predictor {
 public:
  explicit MujocoPredictor(const MujocoGrid& grid) {
    auto nonempty_unique = [](const auto& list, const char* name) {
      if (list.empty()) {
        throw std::invalid_argument(std::string("mujoco ") + name + ": needs at least one value");
      }
      std::set<std::decay_t<decltype(list[0])>> seen(list.begin(), list.end());
      if (seen.size() != list.size())
        throw std::invalid_argument(std::string("mujoco ") + name + ": a value is repeated");
    };
    nonempty_unique(grid.timestep, "timestep");
    nonempty_unique(grid.cone, "cone");
    nonempty_unique(grid.noslip, "noslip");
    nonempty_unique(grid.solref, "solref");
    nonempty_unique(grid.solimp, "solimp");
    struct Point {
      double timestep;
      std::string cone;
      int noslip;
      std::array<double, 2> solref;
      std::array<double, 5> solimp;
    };
    std::vector<Point> points;
    for (double ts : grid.timestep)
      for (const auto& cone : grid.cone)
        for (int ns : grid.noslip)
          for (const auto& sr : grid.solref)
            for (const auto& si : grid.solimp) points.push_back(Point{ts, cone, ns, sr, si});
    for (const auto& pt : points) {
      nlohmann::json knobs = {
          {"timestep", pt.timestep}, {"cone", pt.cone}, {"noslip_iterations", pt.noslip}};
      // Knobs (and keys) name solref/solimp only where they differ from the
      // defaults, so the keys of earlier evaluations stay the same.
      if (pt.solref != DefaultSolref()) knobs["solref"] = pt.solref;
      if (pt.solimp != DefaultSolimp()) knobs["solimp"] = pt.solimp;
      try {
        simulators_.push_back(simulators::MakeSimulator("mujoco", knobs.dump(), cache_));
      } catch (const simulators::SimulatorError& e) {
        throw std::invalid_argument(std::string("mujoco grid: ") + e.what());
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(std::string("mujoco grid: ") + e.what());
      }
      PredictorSetting s;
      s.key = MujocoSettingKey(knobs);
      nlohmann::json stored = knobs;
      stored["predictor"] = "mujoco";
      s.knobs_json = stored.dump();
      s.step = pt.timestep;
      settings_.push_back(std::move(s));
    }
    // Finer: smaller timestep, then elliptic over pyramidal, then more noslip.
    RankByRefinement(points, &settings_, [](const auto& x, const auto& y) {
      if (x.timestep != y.timestep) return x.timestep > y.timestep;
      if (x.cone != y.cone) return x.cone == "pyramidal";
      return x.noslip < y.noslip;
    });
  }
  const std::string& name() const override { return name_; }
  const std::vector<PredictorSetting>& settings() const override { return settings_; }
  mechanics::SimulationResult Run(const mechanics::Scene& scene,
                                  std::size_t setting) const override {
    const auto& sim = *simulators_.at(setting);
    if (std::string why = sim.CheckScene(scene); !why.empty()) return InvalidScene(why);
    return sim.Simulate(scene);
  }
  mechanics::SimulationResult RunClosedLoop(
      const mechanics::Scene& scene, std::size_t setting,
      const mechanics::PusherCommandSource& commands) const override {
    const auto& sim = *simulators_.at(setting);
    if (std::string why = sim.CheckScene(scene); !why.empty()) return InvalidScene(why);
    return sim.SimulateClosedLoop(scene, commands);
  }

 private:
  std::string name_ = "mujoco";
  // Shared by the settings: an evaluation runs all of them on one scene in a
  // row, and they differ only in MuJoCo's <option> knobs (simulator.hpp). One
  // idle model per worker thread is what that needs.
  std::shared_ptr<simulators::MujocoModelCache> cache_ = simulators::MakeMujocoModelCache(
      std::clamp<std::size_t>(std::thread::hardware_concurrency(), 2, 8));
  std::vector<std::unique_ptr<simulators::Simulator>> simulators_;
  std::vector<PredictorSetting> settings_;
};

}  // namespace

std::string MujocoSettingKey(const nlohmann::json& knobs) {
  const simulators::MujocoSettings d;
  char key[96];
  std::snprintf(key, sizeof key, "mujoco_ts%g_%s_ns%d", knobs.value("timestep", d.timestep),
                knobs.value("cone", std::string("elliptic")).c_str(),
                knobs.value("noslip_iterations", d.noslip_iterations));
  std::string out = key;
  if (knobs.contains("solref")) {
    const auto v = knobs["solref"].get<std::array<double, 2>>();
    if (v != DefaultSolref()) out += "_sr" + FormatList(v);
  }
  if (knobs.contains("solimp")) {
    const auto v = knobs["solimp"].get<std::array<double, 5>>();
    if (v != DefaultSolimp()) out += "_si" + FormatList(v);
  }
  return out;
}

std::unique_ptr<Predictor> MakeMujocoPredictor(const MujocoGrid& grid) {
  return std::make_unique<MujocoPredictor>(grid);
}

std::unique_ptr<Predictor> MakeArenaPredictor(std::vector<mechanics::ModelOptions> grid) {
  return std::make_unique<ArenaPredictor>(std::move(grid));
}

std::size_t FinestSetting(const Predictor& predictor) {
  const auto& s = predictor.settings();
  std::size_t best = 0;
  for (std::size_t i = 1; i < s.size(); ++i) {
    if (s[i].refinement > s[best].refinement) best = i;
  }
  return best;
}

}  // namespace arena::assessment
