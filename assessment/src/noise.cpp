#include "arena/assessment/noise.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/mechanics/frames.hpp"
#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"

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

double PositiveNumber(const json& v, const std::string& path) {
  const double x = NonNegativeNumber(v, path);
  if (x <= 0) throw NoiseError(path, "must be > 0");
  return x;
}

// The largest axis of a number or an array of 3 (pose_noise.*_std).
double LargestAxis(const json& v, const std::string& path) {
  if (v.is_number()) return NonNegativeNumber(v, path);
  if (!v.is_array() || v.size() != 3)
    throw NoiseError(path, "must be a number or an array of 3 numbers");
  double m = 0;
  for (int k = 0; k < 3; ++k)
    m = std::max(m, NonNegativeNumber(v[k], path + "[" + std::to_string(k) + "]"));
  return m;
}

json ParseObject(std::string_view text) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::out_of_range& e) {  // 1e999: valid JSON, no double holds it
    throw NoiseError("defects",
                     std::string("a number out of range (beyond a double): ") + e.what());
  } catch (const json::parse_error& e) {
    throw NoiseError("defects", std::string("not valid JSON: ") + e.what());
  }
  if (!root.is_object()) throw NoiseError("defects", "must be a JSON object");
  return root;
}

Eigen::Vector3d NormalVector(double std_dev, std::normal_distribution<double>* normal,
                             std::mt19937_64* rng) {
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) v[k] = std_dev * (*normal)(*rng);
  return v;
}

Eigen::Quaterniond Turned(const Eigen::Quaterniond& q, const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle == 0.0) return q;
  return (q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle))).normalized();
}

}  // namespace

StartPoseNoise ParseStartPoseNoise(std::string_view text) {
  const json root = ParseObject(text);
  StartPoseNoise n;
  if (const json* e = Member(root, "emulated")) {
    if (e->is_boolean()) {
      n.emulated = e->get<bool>();
    } else if (e->is_number()) {
      n.emulated = e->get<double>() != 0;
    } else {
      throw NoiseError("emulated", "must be true or false");
    }
  }
  if (const json* r = Member(root, "reset")) {
    if (!r->is_object()) throw NoiseError("reset", "must be an object");
    if (const json* v = Member(*r, "placement_position_std"))
      n.position_std = NonNegativeNumber(*v, "reset.placement_position_std");
    if (const json* v = Member(*r, "placement_angle_std"))
      n.angle_std = NonNegativeNumber(*v, "reset.placement_angle_std");
    if (const json* v = Member(*r, "position_tolerance"))
      n.position_tolerance = PositiveNumber(*v, "reset.position_tolerance");
    if (const json* v = Member(*r, "angle_tolerance"))
      n.angle_tolerance = PositiveNumber(*v, "reset.angle_tolerance");
    if (const json* v = Member(*r, "max_attempts")) {
      if (!v->is_number_integer() || v->get<int>() < 1 || v->get<int>() > 100)
        throw NoiseError("reset.max_attempts", "must be an integer in 1..100");
      n.max_attempts = v->get<int>();
    }
  }
  if (const json* p = Member(root, "pose_noise")) {
    if (!p->is_object()) throw NoiseError("pose_noise", "must be an object");
    if (const json* v = Member(*p, "position_std"))
      n.sensing_position_std = LargestAxis(*v, "pose_noise.position_std");
    if (const json* v = Member(*p, "rotation_std"))
      n.sensing_angle_std = LargestAxis(*v, "pose_noise.rotation_std");
  }
  return n;
}

StartPoseDraw DrawStartPose(const StartPoseNoise& noise, std::mt19937_64* rng) {
  StartPoseDraw d;
  if (!noise.any()) return d;
  std::normal_distribution<double> normal(0.0, 1.0);
  // As the reset verifies (reset.cpp): keep the first placement seen within
  // tolerance, else the last one. Orientations relative to the nominal.
  for (int k = 0; k < noise.max_attempts; ++k) {
    d.offset = NormalVector(noise.position_std, &normal, rng);
    d.rotation = NormalVector(noise.angle_std, &normal, rng);
    const Eigen::Quaterniond placed = Turned(Eigen::Quaterniond::Identity(), d.rotation);
    const Eigen::Vector3d seen = d.offset + NormalVector(noise.sensing_position_std, &normal, rng);
    const Eigen::Quaterniond seen_q =
        Turned(placed, NormalVector(noise.sensing_angle_std, &normal, rng));
    if (seen.norm() <= noise.position_tolerance &&
        seen_q.angularDistance(Eigen::Quaterniond::Identity()) <= noise.angle_tolerance) {
      break;
    }
  }
  return d;
}

mechanics::Scene ApplyStartPose(const mechanics::Scene& scene, const StartPoseDraw& d) {
  if (d.offset.isZero(0) && d.rotation.isZero(0)) return scene;
  mechanics::Scene s = scene;
  const Eigen::Matrix3d nominal = mechanics::RotationFromRpy(scene.object.pose.rpy);
  Eigen::Matrix3d R = nominal;
  if (const double angle = d.rotation.norm(); angle > 0)
    R = nominal * Eigen::AngleAxisd(angle, d.rotation / angle).toRotationMatrix();
  s.object.pose.position = scene.object.pose.position + d.offset;
  s.object.pose.rpy = mechanics::RpyFromRotation(R);
  mechanics::SeatFingers(&s);
  return s;
}

ActuationNoise ParseActuationNoise(std::string_view text) {
  const json root = ParseObject(text);
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
    // A recorded path takes the same actuation error: each displacement from
    // the start scaled, the offset velocity added over time.
    if (s.pusher->path) {
      auto& path = *s.pusher->path;
      const Eigen::Vector3d p0 = path.position.front();
      for (size_t k = 0; k < path.t.size(); ++k) {
        path.position[k] =
            p0 + (path.position[k] - p0) * d.velocity_scale + d.velocity_offset * path.t[k];
      }
    }
  }
  return s;
}

}  // namespace arena::assessment
