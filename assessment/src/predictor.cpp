#include "arena/assessment/predictor.hpp"

#include <algorithm>
#include <numeric>
#include <set>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace arena::assessment {

namespace {

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
      s.knobs_json = nlohmann::json({{"predictor", "arena"},
                                     {"facets", m.facets},
                                     {"points", m.points},
                                     {"dt", m.dt},
                                     {"reduce", mechanics::ToString(m.reduce)}})
                         .dump();
      s.step = m.dt;
      settings_.push_back(std::move(s));
    }
    // Finer: smaller step first, then more facets, then more points.
    std::vector<std::size_t> order(models_.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      const auto &x = models_[a], &y = models_[b];
      if (x.dt != y.dt) return x.dt > y.dt;
      if (x.facets != y.facets) return x.facets < y.facets;
      return x.points < y.points;
    });
    for (std::size_t rank = 0; rank < order.size(); ++rank) {
      settings_[order[rank]].refinement = static_cast<int>(rank);
    }
  }
  const std::string& name() const override { return name_; }
  const std::vector<PredictorSetting>& settings() const override { return settings_; }
  mechanics::SimulationResult Run(const mechanics::Scene& scene,
                                  std::size_t setting) const override {
    mechanics::Scene s = scene;
    s.model = models_.at(setting);
    try {
      mechanics::ValidateScene(s);
    } catch (const std::exception& e) {
      mechanics::SimulationResult r;
      r.status = mechanics::SimulationStatus::kInvalidScene;
      r.error = e.what();
      return r;
    }
    return mechanics::Simulate(s);
  }

 private:
  std::string name_ = "arena";
  std::vector<mechanics::ModelOptions> models_;
  std::vector<PredictorSetting> settings_;
};

}  // namespace

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
