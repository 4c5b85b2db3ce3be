// The real mechanics behind the simulated cell (kept in its own file so that
// code which brings its own backend does not link the model).
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

}  // namespace arena::executors
