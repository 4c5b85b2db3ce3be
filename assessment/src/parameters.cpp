// Parameters of a scene for sensitivity analysis (sensitivity.hpp): which
// there are, how each is moved, its tolerance; and the worker pool.
#include "arena/assessment/sensitivity.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "number_text.hpp"

namespace arena::assessment {
namespace {

using mechanics::Scene;

constexpr double kRelativeStep = 1e-2;  // of the scale, for magnitudes
constexpr double kPositionStep = 2e-3;  // of the object's extent
constexpr double kTiltStep = 2e-3;      // rad

std::string ContactName(const Scene& s, int contact) {
  return contact < static_cast<int>(s.fingers.size()) ? s.fingers[static_cast<size_t>(contact)].name
                                                      : "pusher";
}

const mechanics::ContactSpec& ContactOf(const Scene& s, int contact) {
  if (contact < static_cast<int>(s.fingers.size())) return s.fingers[static_cast<size_t>(contact)];
  return *s.pusher;
}
mechanics::ContactSpec& ContactOf(Scene& s, int contact) {
  if (contact < static_cast<int>(s.fingers.size())) return s.fingers[static_cast<size_t>(contact)];
  return *s.pusher;
}

Eigen::Vector3d Tangent(const Eigen::Vector3d& normal, int axis) {
  const Eigen::Vector3d t1 = mechanics::FirstTangent(normal);
  return axis == 0 ? t1 : Eigen::Vector3d(normal.cross(t1));
}

const char kAxes[] = {'x', 'y', 'z'};

using internal::Num;

}  // namespace

// ---------------------------------------------------------------- threads

int ThreadCount(int requested) {
  if (requested > 0) return requested;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

void RunParallel(long n, int threads, const std::function<void(long)>& fn) {
  const int t = static_cast<int>(std::min<long>(ThreadCount(threads), std::max(1L, n)));
  if (t <= 1) {
    for (long i = 0; i < n; ++i) fn(i);
    return;
  }
  std::atomic<long> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    for (long i = next++; i < n; i = next++) {
      try {
        fn(i);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
      }
    }
  };
  std::vector<std::thread> pool;
  for (int k = 0; k < t; ++k) pool.emplace_back(work);
  for (auto& th : pool) th.join();
  if (error) std::rethrow_exception(error);
}

// ---------------------------------------------------------------- parameters

std::vector<Parameter> SceneParameters(const Scene& scene) {
  std::vector<Parameter> out;
  const double extent = mechanics::ObjectExtent(scene.object);
  auto add = [&](Parameter p) {
    if (p.step == 0) p.step = kRelativeStep * p.scale;
    out.push_back(std::move(p));
  };
  const double weight = scene.object.mass * std::max(scene.gravity.norm(), 1.0);
  add({"grip_force", "grip_force", "N", ParameterKind::kGripForce, -1, 0, scene.grip_force,
       scene.grip_force > 1e-9 ? scene.grip_force : weight, 0, 0});
  add({"object.mass", "mass", "kg", ParameterKind::kMass, -1, 0, scene.object.mass,
       scene.object.mass, 0, 1e-3 * scene.object.mass});
  const int contacts = static_cast<int>(scene.fingers.size()) + (scene.pusher ? 1 : 0);
  bool any_mu = false;
  for (int c = 0; c < contacts; ++c) {
    const double mu = ContactOf(scene, c).mu;
    any_mu = any_mu || mu > 0;
    add({ContactName(scene, c) + ".mu", "friction", "1", ParameterKind::kMu, c, 0, mu,
         std::max(mu, 0.05), 0, 0});
  }
  if (!scene.fingers.empty()) {
    double mean = 0, least = std::numeric_limits<double>::infinity();
    for (const auto& f : scene.fingers) {
      mean += f.mu;
      least = std::min(least, f.mu);
    }
    mean /= static_cast<double>(scene.fingers.size());
    add({"fingers.mu", "friction", "1", ParameterKind::kFingersMu, -1, 0, mean,
         std::max(mean, 0.05), 0, mean - least});
  }
  if (any_mu) add({"mu_scale", "friction", "1", ParameterKind::kMuScale, -1, 0, 1, 1, 0, 0});
  // A recorded path has no velocity to perturb (its motion fields are
  // unused, zero): it has no velocity parameters, and PerturbScene refuses.
  if (scene.pusher && !scene.pusher->path) {
    const auto& m = scene.pusher->motion;
    const double speed = m.velocity.norm();
    if (speed > 0) {
      add({"push_speed", "velocity", "m/s", ParameterKind::kPushSpeed, -1, 0, speed, speed, 0, 0});
    }
    const double vscale = std::max(speed, 1e-3);
    for (int k = 0; k < 3; ++k) {
      add({std::string("pusher.velocity.") + kAxes[k], "velocity", "m/s",
           ParameterKind::kPusherVelocity, -1, k, m.velocity[k], vscale, 0,
           -std::numeric_limits<double>::infinity()});
    }
    const double wscale = std::max({m.angular_velocity.norm(), speed / extent, 1e-3});
    for (int k = 0; k < 3; ++k) {
      add({std::string("pusher.angular_velocity.") + kAxes[k], "angular_velocity", "rad/s",
           ParameterKind::kPusherAngularVelocity, -1, k, m.angular_velocity[k], wscale, 0,
           -std::numeric_limits<double>::infinity()});
    }
  }
  for (int c = 0; c < contacts; ++c) {
    for (int axis = 0; axis < 2; ++axis) {
      const std::string t = axis == 0 ? "t1" : "t2";
      add({ContactName(scene, c) + ".position." + t, "position", "m",
           ParameterKind::kContactPosition, c, axis, 0, extent, kPositionStep * extent,
           -std::numeric_limits<double>::infinity()});
    }
  }
  for (int axis = 0; axis < 2; ++axis) {
    const std::string t = axis == 0 ? "t1" : "t2";
    if (!scene.fingers.empty()) {
      add({"fingers.normal." + t, "normal", "rad", ParameterKind::kFingerNormals, 0, axis, 0, 1.0,
           kTiltStep, -std::numeric_limits<double>::infinity()});
    }
    if (scene.pusher) {
      add({"pusher.normal." + t, "normal", "rad", ParameterKind::kContactNormal,
           static_cast<int>(scene.fingers.size()), axis, 0, 1.0, kTiltStep,
           -std::numeric_limits<double>::infinity()});
    }
  }
  return out;
}

std::vector<Parameter> SelectParameters(const std::vector<Parameter>& all,
                                        const std::vector<std::string>& filters) {
  if (filters.empty()) return all;
  std::vector<Parameter> out;
  std::set<std::string> used;
  for (const auto& p : all) {
    bool take = false;
    for (const auto& f : filters) {
      const bool match = f == p.name || f == p.group ||
                         (f == "kinematics" && (p.group == "position" || p.group == "normal")) ||
                         (p.name.size() > f.size() && p.name.compare(0, f.size(), f) == 0 &&
                          p.name[f.size()] == '.');
      if (match) {
        used.insert(f);
        take = true;
      }
    }
    if (take) out.push_back(p);
  }
  for (const auto& f : filters) {
    if (!used.count(f)) {
      std::string names;
      for (const auto& p : all) names += (names.empty() ? "" : ", ") + p.name;
      throw std::invalid_argument("--params: '" + f +
                                  "' matches no parameter of this scene (names: " + names +
                                  "; groups: grip_force, mass, friction, velocity, "
                                  "angular_velocity, position, normal, kinematics)");
    }
  }
  return out;
}

Scene PerturbScene(const Scene& scene, const Parameter& p, double delta) {
  Scene s = scene;
  const double value = p.nominal + delta;
  if (value < p.lower) {
    throw mechanics::SceneError(p.name, "below its admissible minimum " + Num(p.lower));
  }
  const bool velocity = p.kind == ParameterKind::kPushSpeed ||
                        p.kind == ParameterKind::kPusherVelocity ||
                        p.kind == ParameterKind::kPusherAngularVelocity;
  if (velocity && s.pusher && s.pusher->path) {
    throw mechanics::SceneError("pusher.motion.path",
                                "a recorded path has no velocity to perturb (" + p.name + ")");
  }
  switch (p.kind) {
    case ParameterKind::kGripForce:
      s.grip_force = value;
      break;
    case ParameterKind::kMass:
      if (s.object.inertia) *s.object.inertia *= value / s.object.mass;
      s.object.mass = value;
      break;
    case ParameterKind::kMu:
      ContactOf(s, p.contact).mu = value;
      break;
    case ParameterKind::kFingersMu:
      for (auto& f : s.fingers) f.mu += delta;
      break;
    case ParameterKind::kMuScale:
      for (auto& f : s.fingers) f.mu *= value;
      if (s.pusher) s.pusher->mu *= value;
      break;
    case ParameterKind::kPushSpeed:
      s.pusher->motion.velocity *= value / p.nominal;
      break;
    case ParameterKind::kPusherVelocity:
      s.pusher->motion.velocity[p.axis] = value;
      break;
    case ParameterKind::kPusherAngularVelocity:
      s.pusher->motion.angular_velocity[p.axis] = value;
      break;
    case ParameterKind::kContactPosition: {
      auto& c = ContactOf(s, p.contact);
      c.position += delta * Tangent(c.normal, p.axis);
      break;
    }
    case ParameterKind::kContactNormal:
    case ParameterKind::kFingerNormals: {
      // Tilt towards t: rotate about n x t by delta; a line's axis turns with
      // it. Finger normals turn together (about the first finger's n x t), so
      // opposing fingers stay opposed.
      const auto& ref = ContactOf(s, p.contact);
      const Eigen::Vector3d t = Tangent(ref.normal, p.axis);
      const Eigen::AngleAxisd turn(delta, ref.normal.cross(t).normalized());
      auto tilt = [&](mechanics::ContactSpec& c) {
        c.normal = (turn * c.normal).normalized();
        c.axis = (turn * c.axis).normalized();
      };
      if (p.kind == ParameterKind::kFingerNormals) {
        for (auto& f : s.fingers) tilt(f);
      } else {
        tilt(ContactOf(s, p.contact));
      }
      break;
    }
  }
  mechanics::ValidateScene(s);
  return s;
}

std::pair<double, std::string> ToleranceFor(const Parameter& p, const StabilityOptions& o) {
  if (auto it = o.tolerances.find(p.name); it != o.tolerances.end()) {
    return {it->second, "--tolerance " + p.name};
  }
  const double k = o.noise_sigmas;
  const std::string sig = " x " + Num(k) + " sigma";
  if (p.kind == ParameterKind::kMuScale && o.noise.mu_scale_std > 0) {
    return {k * o.noise.mu_scale_std, "friction_variability.mu_scale_std" + sig};
  }
  if (p.kind == ParameterKind::kPushSpeed && o.noise.velocity_scale_std > 0) {
    return {k * o.noise.velocity_scale_std * p.nominal, "actuation_noise.velocity_scale_std" + sig};
  }
  if (p.kind == ParameterKind::kPusherVelocity && o.noise.velocity_offset_std[p.axis] > 0) {
    return {
        k * o.noise.velocity_offset_std[p.axis],
        std::string("actuation_noise.velocity_offset_std[") + std::to_string(p.axis) + "]" + sig};
  }
  if (o.relative_tolerance > 0) {
    return {o.relative_tolerance * p.scale, "--tolerance " + Num(o.relative_tolerance * 100) +
                                                "% of " + Num(p.scale) + " " + p.unit};
  }
  return {0, ""};
}

}  // namespace arena::assessment
