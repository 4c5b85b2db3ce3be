// Simulators by name, with settings read from JSON (every key checked).
#include <nlohmann/json.hpp>

#include "arena/simulators/simulator.hpp"

namespace arena::simulators {
namespace {

using nlohmann::json;

json ParseObject(std::string_view name, std::string_view text) {
  if (text.empty()) return json::object();
  json j;
  try {
    j = json::parse(text);
  } catch (const json::out_of_range& e) {  // 1e999: valid JSON, no double holds it
    throw SimulatorError(
        std::string(name),
        std::string("settings hold a number out of range (beyond a double): ") + e.what());
  } catch (const json::exception& e) {
    throw SimulatorError(std::string(name), std::string("settings are not JSON: ") + e.what());
  }
  if (!j.is_object()) throw SimulatorError(std::string(name), "settings must be a JSON object");
  return j;
}

// Reads key into *out when present; throws naming "<sim>.<key>" on a wrong type.
template <typename T>
void Read(const json& j, const std::string& sim, const char* key, T* out) {
  auto it = j.find(key);
  if (it == j.end()) return;
  const std::string field = sim + "." + key;
  if constexpr (std::is_same_v<T, bool>) {
    if (!it->is_boolean()) throw SimulatorError(field, "must be true or false");
    *out = it->get<bool>();
  } else if constexpr (std::is_integral_v<T>) {
    if (!it->is_number_integer()) throw SimulatorError(field, "must be an integer");
    *out = it->get<T>();
  } else {
    if (!it->is_number()) throw SimulatorError(field, "must be a number");
    *out = it->get<T>();
  }
}

void CheckKeys(const json& j, const std::string& sim, std::initializer_list<const char*> known) {
  for (const auto& [key, value] : j.items()) {
    bool ok = false;
    for (const char* k : known) ok = ok || key == k;
    if (!ok) throw SimulatorError(sim + "." + key, "unknown setting");
  }
}

}  // namespace

std::vector<std::string> SimulatorNames() { return {"arena", "mujoco"}; }

std::unique_ptr<Simulator> MakeSimulator(std::string_view name, std::string_view settings_json) {
  return MakeSimulator(name, settings_json, nullptr);
}

std::unique_ptr<Simulator> MakeSimulator(std::string_view name, std::string_view settings_json,
                                         std::shared_ptr<MujocoModelCache> cache) {
  const json j = ParseObject(name, settings_json);
  if (name == "arena") {
    ArenaSettings s;
    CheckKeys(j, "arena", {"facets", "points", "dt", "at_least"});
    Read(j, "arena", "facets", &s.facets);
    Read(j, "arena", "points", &s.points);
    Read(j, "arena", "dt", &s.dt);
    Read(j, "arena", "at_least", &s.at_least);
    return MakeArenaSimulator(s);
  }
  if (name == "mujoco") {
    MujocoSettings s;
    CheckKeys(j, "mujoco",
              {"timestep", "cone", "solref", "solimp", "impratio", "noslip_iterations", "tolerance",
               "iterations", "object_damping", "finger_mass", "slip_speed", "pads", "forces",
               "scale_to_scene"});
    Read(j, "mujoco", "timestep", &s.timestep);
    if (auto it = j.find("cone"); it != j.end()) {
      if (*it == "elliptic")
        s.elliptic = true;
      else if (*it == "pyramidal")
        s.elliptic = false;
      else
        throw SimulatorError("mujoco.cone", "must be \"elliptic\" or \"pyramidal\"");
    }
    if (auto it = j.find("solref"); it != j.end()) {
      if (!it->is_array() || it->size() != 2 || !(*it)[0].is_number() || !(*it)[1].is_number())
        throw SimulatorError("mujoco.solref", "must be [timeconst, dampratio]");
      s.solref_timeconst = (*it)[0].get<double>();
      s.solref_damping = (*it)[1].get<double>();
    }
    if (auto it = j.find("solimp"); it != j.end()) {
      if (!it->is_array() || it->size() != 5)
        throw SimulatorError("mujoco.solimp", "must be [dmin, dmax, width, midpoint, power]");
      for (int k = 0; k < 5; ++k) {
        if (!(*it)[k].is_number()) throw SimulatorError("mujoco.solimp", "must hold numbers");
        s.solimp[k] = (*it)[k].get<double>();
      }
    }
    Read(j, "mujoco", "impratio", &s.impratio);
    Read(j, "mujoco", "noslip_iterations", &s.noslip_iterations);
    Read(j, "mujoco", "tolerance", &s.tolerance);
    Read(j, "mujoco", "iterations", &s.iterations);
    Read(j, "mujoco", "object_damping", &s.object_damping);
    Read(j, "mujoco", "finger_mass", &s.finger_mass);
    Read(j, "mujoco", "slip_speed", &s.slip_speed);
    Read(j, "mujoco", "scale_to_scene", &s.scale_to_scene);
    if (auto it = j.find("pads"); it != j.end()) {
      if (*it == "spheres")
        s.pads = PadShapes::kSpheres;
      else if (*it == "shapes")
        s.pads = PadShapes::kShapes;
      else
        throw SimulatorError("mujoco.pads", "must be \"spheres\" or \"shapes\"");
    }
    if (auto it = j.find("forces"); it != j.end()) {
      if (*it == "interval")
        s.interval_forces = true;
      else if (*it == "instant")
        s.interval_forces = false;
      else
        throw SimulatorError("mujoco.forces", "must be \"interval\" or \"instant\"");
    }
    return MakeMujocoSimulator(s, std::move(cache));
  }
  throw SimulatorError("simulator",
                       "unknown name '" + std::string(name) + "' (known: arena, mujoco)");
}

}  // namespace arena::simulators
