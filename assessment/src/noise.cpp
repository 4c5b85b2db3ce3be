#include "arena/assessment/noise.hpp"

#include <cmath>

#include <nlohmann/json.hpp>

namespace arena::assessment {
namespace {

using nlohmann::json;

double NonNegativeNumber(const json& v, const std::string& path) {
  if (!v.is_number()) throw NoiseError(path, "must be a number");
  const double x = v.get<double>();
  if (!std::isfinite(x) || x < 0) throw NoiseError(path, "must be finite and >= 0");
  return x;
}

const json* Member(const json& o, const char* key) {
  auto it = o.find(key);
  return it == o.end() ? nullptr : &*it;
}

}  // namespace

ActuationNoise ParseActuationNoise(std::string_view text) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::parse_error& e) {
    throw NoiseError("defects", std::string("not valid JSON: ") + e.what());
  }
  if (!root.is_object()) throw NoiseError("defects", "must be a JSON object");
  ActuationNoise n;
  if (const json* f = Member(root, "friction_variability")) {
    if (!f->is_object()) throw NoiseError("friction_variability", "must be an object");
    if (auto it = f->find("mu_scale_std"); it != f->end()) {
      n.mu_scale_std = NonNegativeNumber(*it, "friction_variability.mu_scale_std");
      if (n.mu_scale_std > 0.5)
        throw NoiseError("friction_variability.mu_scale_std", "must be <= 0.5");
    }
  }
  if (const json* a = Member(root, "actuation_noise")) {
    if (!a->is_object()) throw NoiseError("actuation_noise", "must be an object");
    if (auto it = a->find("velocity_scale_std"); it != a->end()) {
      n.velocity_scale_std = NonNegativeNumber(*it, "actuation_noise.velocity_scale_std");
    }
    if (auto it = a->find("velocity_offset_std"); it != a->end()) {
      const std::string path = "actuation_noise.velocity_offset_std";
      if (it->is_number()) {
        n.velocity_offset_std.setConstant(NonNegativeNumber(*it, path));
      } else if (it->is_array() && it->size() == 3) {
        for (int k = 0; k < 3; ++k) {
          n.velocity_offset_std[k] =
              NonNegativeNumber((*it)[k], path + "[" + std::to_string(k) + "]");
        }
      } else {
        throw NoiseError(path, "must be a number or an array of 3 numbers");
      }
    }
  }
  return n;
}

NoiseDraw DrawNoise(const ActuationNoise& noise, std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  NoiseDraw d;
  do {
    d.mu_scale = 1.0 + noise.mu_scale_std * normal(*rng);
  } while (d.mu_scale <= 0.0);
  d.velocity_scale = 1.0 + noise.velocity_scale_std * normal(*rng);
  for (int k = 0; k < 3; ++k) d.velocity_offset[k] = noise.velocity_offset_std[k] * normal(*rng);
  return d;
}

mechanics::Scene ApplyNoise(const mechanics::Scene& scene, const NoiseDraw& d) {
  mechanics::Scene s = scene;
  for (auto& f : s.fingers) f.mu *= d.mu_scale;
  if (s.pusher) {
    s.pusher->mu *= d.mu_scale;
    s.pusher->motion.velocity = s.pusher->motion.velocity * d.velocity_scale + d.velocity_offset;
  }
  return s;
}

}  // namespace arena::assessment
