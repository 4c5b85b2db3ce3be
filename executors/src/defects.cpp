#include "arena/executors/defects.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/mechanics/pusher_motion.hpp"
#include "arena/reset/rng.hpp"
#include "defects_json.hpp"
#include "vector_json.hpp"

namespace arena::executors {
namespace {

using nlohmann::json;
using reset::Rng;
using reset::StreamPurpose;

void CheckKeys(const json& obj, const std::string& path, const std::set<std::string>& known) {
  for (auto it = obj.begin(); it != obj.end(); ++it) {
    if (!known.count(it.key())) {
      throw DefectError(path.empty() ? it.key() : path + "." + it.key(), "unknown field");
    }
  }
}

const json* Object(const json& parent, const std::string& key, const std::string& path) {
  auto it = parent.find(key);
  if (it == parent.end()) return nullptr;
  if (!it->is_object()) throw DefectError(path, "must be an object");
  return &*it;
}

double Number(const json& v, const std::string& path) {
  if (!v.is_number()) throw DefectError(path, "must be a number");
  const double x = v.get<double>();
  if (!std::isfinite(x)) throw DefectError(path, "must be finite");
  return x;
}

void ReadScalar(const json& parent, const char* key, const std::string& prefix, double* out) {
  auto it = parent.find(key);
  if (it != parent.end()) *out = Number(*it, prefix + key);
}

// A 3-vector, or one number for all three axes.
void ReadAxes(const json& parent, const char* key, const std::string& prefix,
              Eigen::Vector3d* out) {
  auto it = parent.find(key);
  if (it == parent.end()) return;
  const std::string path = prefix + key;
  if (it->is_number()) {
    out->setConstant(Number(*it, path));
    return;
  }
  if (!it->is_array() || it->size() != 3)
    throw DefectError(path, "must be a number or an array of 3 numbers");
  for (int k = 0; k < 3; ++k) (*out)[k] = Number((*it)[k], path + "[" + std::to_string(k) + "]");
}

void NonNegative(const Eigen::Vector3d& v, const std::string& path) {
  for (int k = 0; k < 3; ++k) {
    if (!(v[k] >= 0)) throw DefectError(path + "[" + std::to_string(k) + "]", "must be >= 0");
  }
}
void NonNegative(double v, const std::string& path) {
  if (!(v >= 0) || !std::isfinite(v)) throw DefectError(path, "must be finite and >= 0");
}

const char* TypeName(mechanics::ContactType t) {
  switch (t) {
    case mechanics::ContactType::kPoint:
      return "point";
    case mechanics::ContactType::kLine:
      return "line";
    case mechanics::ContactType::kPatch:
      return "patch";
  }
  return "?";
}

using internal::Vec;

Eigen::Quaterniond Perturb(const Eigen::Quaterniond& q, const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle == 0.0) return q;
  return (q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle))).normalized();
}

}  // namespace

void ValidateDefectProfile(const DefectProfile& p) {
  NonNegative(p.position_std, "pose_noise.position_std");
  NonNegative(p.rotation_std, "pose_noise.rotation_std");
  NonNegative(p.force_std, "ft_noise.force_std");
  NonNegative(p.torque_std, "ft_noise.torque_std");
  NonNegative(p.velocity_scale_std, "actuation_noise.velocity_scale_std");
  NonNegative(p.velocity_offset_std, "actuation_noise.velocity_offset_std");
  NonNegative(p.latency_ms, "latency_ms");
  NonNegative(p.finger_change_s, "changes.finger_s");
  NonNegative(p.object_change_s, "changes.object_s");
  if (p.latency_ms > 10000) throw DefectError("latency_ms", "must be <= 10000");
  if (!(p.drop_probability >= 0 && p.drop_probability < 1)) {
    throw DefectError("drop_probability", "must be in [0, 1)");
  }
  if (!std::isfinite(p.mu_scale) || !(p.mu_scale > 0) || p.mu_scale > 10)
    throw DefectError("friction_variability.mu_scale", "must be in (0, 10]");
  NonNegative(p.mu_scale_std, "friction_variability.mu_scale_std");
  if (p.mu_scale_std > 0.5)
    throw DefectError("friction_variability.mu_scale_std", "must be <= 0.5");
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(p.workspace_min[k]) || !std::isfinite(p.workspace_max[k]) ||
        !(p.workspace_min[k] < p.workspace_max[k])) {
      throw DefectError("workspace.min[" + std::to_string(k) + "]",
                        "must be finite and below workspace.max");
    }
  }
  if (!(p.max_pusher_speed > 0) || !std::isfinite(p.max_pusher_speed)) {
    throw DefectError("max_pusher_speed", "must be finite and > 0");
  }
  if (p.contact_types.empty()) throw DefectError("contact_types", "must list at least one type");
  try {
    reset::ValidateResetParams(EffectiveResetParams(p));
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    const auto colon = what.find(':');
    throw DefectError(what.substr(0, colon), what.substr(colon + 2));
  }
}

DefectProfile ParseDefectProfile(std::string_view text) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::out_of_range& e) {  // 1e999: valid JSON, no double holds it
    throw DefectError("(document)",
                      std::string("a number out of range (beyond a double): ") + e.what());
  } catch (const json::parse_error& e) {
    throw DefectError("(document)", std::string("not valid JSON: ") + e.what());
  }
  if (!root.is_object()) throw DefectError("(document)", "must be a JSON object");
  CheckKeys(root, "",
            {"pose_noise", "ft_noise", "actuation_noise", "latency_ms", "drop_probability",
             "friction_variability", "workspace", "max_pusher_speed", "contact_types", "reset",
             "comment", "fault_injection", "changes"});
  DefectProfile p;
  if (const json* o = Object(root, "pose_noise", "pose_noise")) {
    CheckKeys(*o, "pose_noise", {"position_std", "rotation_std"});
    ReadAxes(*o, "position_std", "pose_noise.", &p.position_std);
    ReadAxes(*o, "rotation_std", "pose_noise.", &p.rotation_std);
  }
  if (const json* o = Object(root, "ft_noise", "ft_noise")) {
    CheckKeys(*o, "ft_noise", {"force_std", "torque_std"});
    ReadAxes(*o, "force_std", "ft_noise.", &p.force_std);
    ReadAxes(*o, "torque_std", "ft_noise.", &p.torque_std);
  }
  if (const json* o = Object(root, "actuation_noise", "actuation_noise")) {
    CheckKeys(*o, "actuation_noise", {"velocity_scale_std", "velocity_offset_std"});
    ReadScalar(*o, "velocity_scale_std", "actuation_noise.", &p.velocity_scale_std);
    ReadAxes(*o, "velocity_offset_std", "actuation_noise.", &p.velocity_offset_std);
  }
  ReadScalar(root, "latency_ms", "", &p.latency_ms);
  ReadScalar(root, "drop_probability", "", &p.drop_probability);
  if (const json* o = Object(root, "friction_variability", "friction_variability")) {
    CheckKeys(*o, "friction_variability", {"mu_scale", "mu_scale_std"});
    ReadScalar(*o, "mu_scale", "friction_variability.", &p.mu_scale);
    ReadScalar(*o, "mu_scale_std", "friction_variability.", &p.mu_scale_std);
  }
  if (const json* o = Object(root, "workspace", "workspace")) {
    CheckKeys(*o, "workspace", {"min", "max"});
    ReadAxes(*o, "min", "workspace.", &p.workspace_min);
    ReadAxes(*o, "max", "workspace.", &p.workspace_max);
  }
  ReadScalar(root, "max_pusher_speed", "", &p.max_pusher_speed);
  if (auto it = root.find("contact_types"); it != root.end()) {
    if (!it->is_array()) throw DefectError("contact_types", "must be an array of strings");
    p.contact_types.clear();
    for (size_t i = 0; i < it->size(); ++i) {
      const std::string path = "contact_types[" + std::to_string(i) + "]";
      const json& v = (*it)[i];
      if (!v.is_string()) throw DefectError(path, "must be a string");
      const std::string s = v.get<std::string>();
      if (s == "point")
        p.contact_types.push_back(mechanics::ContactType::kPoint);
      else if (s == "line")
        p.contact_types.push_back(mechanics::ContactType::kLine);
      else if (s == "patch")
        p.contact_types.push_back(mechanics::ContactType::kPatch);
      else
        throw DefectError(path, "must be point, line or patch, got '" + s + "'");
    }
  }
  if (const json* o = Object(root, "reset", "reset")) {
    CheckKeys(*o, "reset",
              {"failure_probability", "max_attempts", "position_tolerance", "angle_tolerance",
               "placement_position_std", "placement_angle_std", "translate_speed", "rotate_speed",
               "grasp_time", "swap_time"});
    auto& r = p.reset;
    ReadScalar(*o, "failure_probability", "reset.", &r.failure_probability);
    if (auto it = o->find("max_attempts"); it != o->end()) {
      if (!it->is_number_integer()) throw DefectError("reset.max_attempts", "must be an integer");
      r.max_attempts = it->get<int>();
    }
    ReadScalar(*o, "position_tolerance", "reset.", &r.position_tolerance);
    ReadScalar(*o, "angle_tolerance", "reset.", &r.angle_tolerance);
    ReadScalar(*o, "placement_position_std", "reset.", &r.placement_position_std);
    ReadScalar(*o, "placement_angle_std", "reset.", &r.placement_angle_std);
    ReadScalar(*o, "translate_speed", "reset.", &r.translate_speed);
    ReadScalar(*o, "rotate_speed", "reset.", &r.rotate_speed);
    ReadScalar(*o, "grasp_time", "reset.", &r.grasp_time);
    ReadScalar(*o, "swap_time", "reset.", &r.swap_time);
  }
  if (const json* o = Object(root, "changes", "changes")) {
    if (o->contains("pusher_s"))
      throw DefectError("changes.pusher_s", "the pusher's change time is reset.swap_time");
    CheckKeys(*o, "changes", {"finger_s", "object_s"});
    ReadScalar(*o, "finger_s", "changes.", &p.finger_change_s);
    ReadScalar(*o, "object_s", "changes.", &p.object_change_s);
  }
  if (const json* o = Object(root, "fault_injection", "fault_injection")) {
    CheckKeys(*o, "fault_injection", {"hang_after_accept", "stream"});
    if (auto it = o->find("hang_after_accept"); it != o->end()) {
      if (!it->is_boolean())
        throw DefectError("fault_injection.hang_after_accept", "must be true or false");
      p.hang_after_accept = it->get<bool>();
    }
    if (auto it = o->find("stream"); it != o->end()) {
      const std::string s = it->is_string() ? it->get<std::string>() : "?";
      if (s != "" && s != "nan" && s != "gap")
        throw DefectError("fault_injection.stream", "must be \"\", \"nan\" or \"gap\"");
      p.corrupt_stream = s;
    }
  }
  ValidateDefectProfile(p);
  return p;
}

namespace internal {

json DefectProfileTree(const DefectProfile& p) {
  json types = json::array();
  for (auto t : p.contact_types) types.push_back(TypeName(t));
  const auto& r = p.reset;
  json j = {{"pose_noise",
             {{"position_std", Vec(p.position_std)}, {"rotation_std", Vec(p.rotation_std)}}},
            {"ft_noise", {{"force_std", Vec(p.force_std)}, {"torque_std", Vec(p.torque_std)}}},
            {"actuation_noise",
             {{"velocity_scale_std", p.velocity_scale_std},
              {"velocity_offset_std", Vec(p.velocity_offset_std)}}},
            {"latency_ms", p.latency_ms},
            {"drop_probability", p.drop_probability},
            {"friction_variability", {{"mu_scale", p.mu_scale}, {"mu_scale_std", p.mu_scale_std}}},
            {"workspace", {{"min", Vec(p.workspace_min)}, {"max", Vec(p.workspace_max)}}},
            {"max_pusher_speed", p.max_pusher_speed},
            {"contact_types", types},
            {"reset",
             {{"failure_probability", r.failure_probability},
              {"max_attempts", r.max_attempts},
              {"position_tolerance", r.position_tolerance},
              {"angle_tolerance", r.angle_tolerance},
              {"placement_position_std", r.placement_position_std},
              {"placement_angle_std", r.placement_angle_std},
              {"translate_speed", r.translate_speed},
              {"rotate_speed", r.rotate_speed},
              {"grasp_time", r.grasp_time},
              {"swap_time", r.swap_time}}}};
  if (p.hang_after_accept || !p.corrupt_stream.empty())
    j["fault_injection"] = {{"hang_after_accept", p.hang_after_accept},
                            {"stream", p.corrupt_stream}};
  return j;
}

}  // namespace internal

std::string DefectProfileToJson(const DefectProfile& p) {
  return internal::DefectProfileTree(p).dump();
}

reset::ResetParams EffectiveResetParams(const DefectProfile& p) {
  reset::ResetParams r = p.reset;
  r.workspace_min = p.workspace_min;
  r.workspace_max = p.workspace_max;
  r.sensing_position_std = p.position_std.maxCoeff();
  r.sensing_angle_std = p.rotation_std.maxCoeff();
  return r;
}

TrialPerturbation DrawPerturbation(const DefectProfile& p, std::uint64_t seed,
                                   std::uint64_t trial_id) {
  TrialPerturbation out;
  Rng friction(seed, trial_id, StreamPurpose::kFriction);
  // 1 + N(0, std) is redrawn (not clamped) in the rare case it is <= 0;
  // std <= 0.5 keeps that below 3e-5 per draw.
  do {
    out.mu_scale = 1.0 + friction.Normal(p.mu_scale_std);
  } while (out.mu_scale <= 0.0);
  out.mu_scale *= p.mu_scale;
  Rng actuation(seed, trial_id, StreamPurpose::kActuation);
  out.velocity_scale = 1.0 + actuation.Normal(p.velocity_scale_std);
  for (int k = 0; k < 3; ++k) out.velocity_offset[k] = actuation.Normal(p.velocity_offset_std[k]);
  return out;
}

mechanics::Scene ApplyPerturbation(const mechanics::Scene& scene, const TrialPerturbation& p) {
  mechanics::Scene s = scene;
  for (auto& f : s.fingers) f.mu *= p.mu_scale;
  if (s.pusher) {
    s.pusher->mu *= p.mu_scale;
    s.pusher->motion.velocity = s.pusher->motion.velocity * p.velocity_scale + p.velocity_offset;
    // A recorded path is actuated the same way: each displacement from the
    // start scaled, the offset velocity added over time.
    if (s.pusher->path) {
      auto& path = *s.pusher->path;
      const Eigen::Vector3d p0 = path.position.front();
      for (size_t k = 0; k < path.t.size(); ++k) {
        path.position[k] =
            p0 + (path.position[k] - p0) * p.velocity_scale + p.velocity_offset * path.t[k];
      }
    }
  }
  return s;
}

std::string CheckCapabilities(const DefectProfile& p, const mechanics::Scene& scene) {
  auto supported = [&](mechanics::ContactType t) {
    return std::find(p.contact_types.begin(), p.contact_types.end(), t) != p.contact_types.end();
  };
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    if (!supported(scene.fingers[i].type)) {
      return "fingers[" + std::to_string(i) + "].type: this cell has no " +
             TypeName(scene.fingers[i].type) + " contacts";
    }
  }
  if (scene.pusher && !supported(scene.pusher->type)) {
    return std::string("pusher.type: this cell has no ") + TypeName(scene.pusher->type) + " pusher";
  }
  auto inside = [&](const Eigen::Vector3d& x) {
    return (x.array() >= p.workspace_min.array()).all() &&
           (x.array() <= p.workspace_max.array()).all();
  };
  auto str = [](const Eigen::Vector3d& v) { return Vec(v).dump(); };
  const Eigen::Vector3d start = scene.object.pose.position;
  if (!inside(start)) {
    return "object.pose.position: " + str(start) + " m is outside the workspace " +
           str(p.workspace_min) + ".." + str(p.workspace_max);
  }
  if (scene.pusher) {
    const mechanics::PusherSpec& pusher = *scene.pusher;
    // A path pusher's speed is the fastest of its segments; its velocity
    // field is unused (zero) and would pass any limit.
    const std::string speed_field = pusher.path ? "pusher.motion.path" : "pusher.motion.velocity";
    const double speed = mechanics::PusherPeakRates(pusher).velocity.norm();
    if (speed > p.max_pusher_speed) {
      return speed_field + ": " + std::to_string(speed) + " m/s exceeds this cell's " +
             std::to_string(p.max_pusher_speed) + " m/s";
    }
    // The object cannot travel further than the pusher moves it: check the
    // end of a constant motion, every sample of a path up to the duration.
    std::vector<double> times = {scene.duration};
    if (pusher.path) {
      for (double t : pusher.path->t) {
        if (t < scene.duration) times.push_back(t);
      }
    }
    const Eigen::Vector3d p0 = mechanics::PusherPoseAt(pusher, 0).position;
    for (double t : times) {
      const Eigen::Vector3d end = start + (mechanics::PusherPoseAt(pusher, t).position - p0);
      if (!inside(end)) {
        return (pusher.path ? std::string("pusher.motion.path") : std::string("pusher.motion")) +
               ": pushing for " + std::to_string(t) + " s moves the object to " + str(end) +
               " m, outside the workspace " + str(p.workspace_min) + ".." + str(p.workspace_max);
      }
    }
  }
  return "";
}

struct Observer::State {
  State(const mechanics::Scene& s, const DefectProfile& p, std::uint64_t seed,
        std::uint64_t trial_id)
      : scene(s),
        profile(p),
        pose(seed, trial_id, StreamPurpose::kPoseNoise),
        ft(seed, trial_id, StreamPurpose::kForceTorqueNoise),
        drops(seed, trial_id, StreamPurpose::kDrops),
        lag(std::lround(p.latency_ms * 1e-3 * mechanics::kSampleRateHz)) {}
  mechanics::Scene scene;
  DefectProfile profile;
  Rng pose, ft, drops;
  long lag;
};

Observer::Observer(const mechanics::Scene& scene, const DefectProfile& profile, std::uint64_t seed,
                   std::uint64_t trial_id)
    : state_(std::make_unique<State>(scene, profile, seed, trial_id)) {}
Observer::~Observer() = default;
Observer::Observer(Observer&&) noexcept = default;
Observer& Observer::operator=(Observer&&) noexcept = default;

dds::Observation Observer::Next(const std::vector<mechanics::TrajectorySample>& truth) {
  State& st = *state_;
  const DefectProfile& p = st.profile;
  const mechanics::Scene& scene = st.scene;
  auto noisy = [&](const Eigen::Vector3d& v, const Eigen::Vector3d& std_dev) {
    return Eigen::Vector3d(v.x() + st.ft.Normal(std_dev.x()), v.y() + st.ft.Normal(std_dev.y()),
                           v.z() + st.ft.Normal(std_dev.z()));
  };
  const size_t i = truth.size() - 1;
  // Every draw happens for every sample, in a fixed order, so that a drop
  // or the latency never shifts the noise of later samples.
  const bool dropped = st.drops.Uniform() < p.drop_probability;
  const Eigen::Vector3d dp(st.pose.Normal(p.position_std.x()), st.pose.Normal(p.position_std.y()),
                           st.pose.Normal(p.position_std.z()));
  const Eigen::Vector3d dr(st.pose.Normal(p.rotation_std.x()), st.pose.Normal(p.rotation_std.y()),
                           st.pose.Normal(p.rotation_std.z()));
  dds::Observation o;
  const long source = static_cast<long>(i) - st.lag;
  const mechanics::TrajectorySample& s = truth[source < 0 ? 0 : static_cast<size_t>(source)];
  o.valid = !dropped && source >= 0;
  // Noise is drawn even when the sample is not valid (fixed stream usage).
  o.position = s.position + dp;
  o.orientation = Perturb(s.orientation, dr);
  const Eigen::Vector3d pusher_torque =
      s.contacts.size() > scene.fingers.size() ? s.contacts.back().torque : Eigen::Vector3d::Zero();
  const Eigen::Vector3d pf = noisy(s.pusher_force, p.force_std);
  const Eigen::Vector3d pt = noisy(pusher_torque, p.torque_std);
  o.pusher_wrench << pf, pt;
  o.finger_wrenches.resize(scene.fingers.size());
  for (size_t f = 0; f < scene.fingers.size(); ++f) {
    Eigen::Vector3d force = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
    if (f < s.contacts.size()) {
      force = s.contacts[f].normal_force * scene.fingers[f].normal + s.contacts[f].tangential_force;
      torque = s.contacts[f].torque;
    }
    const Eigen::Vector3d ff = noisy(force, p.force_std);
    const Eigen::Vector3d ftq = noisy(torque, p.torque_std);
    o.finger_wrenches[f] << ff, ftq;
  }
  o.t = s.t;
  if (!o.valid) {
    // Not a measurement: zeros, but as many finger wrenches as the scene
    // has fingers, so every sample of a trial has the same shape (the
    // store and the export rely on it; latency makes the first ones invalid).
    o = dds::Observation{};
    o.finger_wrenches.assign(scene.fingers.size(), dds::Wrench::Zero());
  }
  return o;
}

std::vector<dds::Observation> Observe(const std::vector<mechanics::TrajectorySample>& truth,
                                      const mechanics::Scene& scene, const DefectProfile& p,
                                      std::uint64_t seed, std::uint64_t trial_id) {
  Observer observer(scene, p, seed, trial_id);
  std::vector<mechanics::TrajectorySample> so_far;
  so_far.reserve(truth.size());
  std::vector<dds::Observation> out;
  out.reserve(truth.size());
  for (const auto& s : truth) {
    so_far.push_back(s);
    out.push_back(observer.Next(so_far));
  }
  return out;
}

dds::PusherState PusherAt(const mechanics::Scene& scene,
                          const mechanics::TrajectorySample& sample) {
  dds::PusherState p;
  p.position = sample.pusher_position;
  if (!scene.pusher) return p;
  if (scene.pusher->path) {
    // A recorded path: its velocity over the segment the sample lies in
    // (ahead of it, so the last sample reads the rest after the path).
    const auto& t = scene.pusher->path->t;
    const auto it = std::upper_bound(t.begin(), t.end(), sample.t);
    const double dt = it == t.end() ? 1e-3 : std::max(*it - sample.t, 1e-9);
    const mechanics::PusherTwist tw = mechanics::PusherTwistOver(*scene.pusher, sample.t, dt);
    p.velocity = tw.velocity;
    p.angular_velocity = tw.angular_velocity;
    p.orientation = Eigen::Quaterniond(mechanics::PusherPoseAt(*scene.pusher, sample.t).rotation);
    return p;
  }
  p.velocity = scene.pusher->motion.velocity;
  p.angular_velocity = scene.pusher->motion.angular_velocity;
  const double angle = p.angular_velocity.norm() * sample.t;
  if (angle > 0) {
    p.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(angle, p.angular_velocity.normalized()));
  }
  return p;
}

}  // namespace arena::executors
