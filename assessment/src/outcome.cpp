#include "arena/assessment/outcome.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "arena/mechanics/frames.hpp"
#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace arena::assessment {
namespace {

struct QuantityInfo {
  const char* name;
  const char* unit;
  QuantityKind kind;
};

constexpr QuantityInfo kQuantities[kQuantityCount] = {
    {"position_x", "m", QuantityKind::kLength},  {"position_y", "m", QuantityKind::kLength},
    {"position_z", "m", QuantityKind::kLength},  {"roll", "rad", QuantityKind::kAngle},
    {"pitch", "rad", QuantityKind::kAngle},      {"yaw", "rad", QuantityKind::kAngle},
    {"rotation", "rad", QuantityKind::kAngle},   {"displacement", "m", QuantityKind::kLength},
    {"pusher_force", "N", QuantityKind::kForce},
};

// Roll-pitch-yaw about fixed x, y, z (R = Rz(yaw) Ry(pitch) Rx(roll)).
Eigen::Vector3d Rpy(const Eigen::Quaterniond& q) {
  return mechanics::RpyFromRotation(q.normalized().toRotationMatrix());
}

// Is the finger's contact point (fixed in the gripper frame) still on the
// object's face once the object has moved to (c, q)?
bool StillOnFace(const mechanics::Scene& scene, const mechanics::ContactSpec& finger,
                 const Eigen::Vector3d& c, const Eigen::Quaterniond& q) {
  const auto& o = scene.object;
  const Eigen::Matrix3d R = q.toRotationMatrix();
  const Eigen::Vector3d p = R.transpose() * (finger.position - c);  // object frame
  const Eigen::Vector3d n = R.transpose() * finger.normal;
  const double slack = 1e-6 * mechanics::ObjectExtent(o);
  if (o.shape == mechanics::ObjectShape::kBox) {
    int face_axis = 0;
    n.cwiseAbs().maxCoeff(&face_axis);
    for (int k = 0; k < 3; ++k) {
      if (k != face_axis && std::abs(p[k]) > 0.5 * o.size[k] + slack) return false;
    }
    return true;
  }
  if (o.shape == mechanics::ObjectShape::kCylinder) {
    return std::abs(p.z()) <= 0.5 * o.height + slack;
  }
  return p.norm() <= mechanics::ObjectExtent(o) + slack;
}

std::vector<mechanics::ContactMode> Sequence(const std::vector<mechanics::TrajectorySample>& s,
                                             size_t contact) {
  std::vector<mechanics::ContactMode> out;
  size_t i = 0;
  while (i < s.size()) {
    const auto mode = s[i].contacts[contact].mode;
    size_t j = i;
    while (j < s.size() && s[j].contacts[contact].mode == mode) ++j;
    if (static_cast<int>(j - i) >= kMinModeRunSamples && (out.empty() || out.back() != mode)) {
      out.push_back(mode);
    }
    i = j;
  }
  return out;
}

}  // namespace

SimulateFn DefaultSimulate() {
  return [](const mechanics::Scene& scene) { return mechanics::Simulate(scene); };
}

const char* Name(Quantity q) { return kQuantities[static_cast<int>(q)].name; }
const char* Unit(Quantity q) { return kQuantities[static_cast<int>(q)].unit; }
QuantityKind KindOf(Quantity q) { return kQuantities[static_cast<int>(q)].kind; }

std::vector<std::string> ContactNames(const mechanics::Scene& scene) {
  std::vector<std::string> names;
  for (const auto& f : scene.fingers) names.push_back(f.name);
  if (scene.pusher) names.push_back("pusher");
  return names;
}

Outcome MeasureOutcome(const mechanics::Scene& scene, const mechanics::SimulationResult& r) {
  Outcome out;
  if (r.status != mechanics::SimulationStatus::kOk || r.samples.empty()) {
    out.error = r.error.empty() ? std::string("no samples") : r.error;
    return out;
  }
  out.ok = true;
  const auto& first = r.samples.front();
  const auto& last = r.samples.back();
  const Eigen::Vector3d rpy = Rpy(last.orientation);
  const Eigen::AngleAxisd turn(last.orientation * first.orientation.inverse());
  double angle = turn.angle();
  Eigen::Vector3d axis = turn.axis();
  if (angle > M_PI) {  // AngleAxis may return (2 pi - a) about -axis
    angle = 2 * M_PI - angle;
    axis = -axis;
  }
  double force = 0;
  for (const auto& s : r.samples) force += s.pusher_force.norm();
  force /= static_cast<double>(r.samples.size());
  out.values = {last.position.x(),
                last.position.y(),
                last.position.z(),
                rpy.x(),
                rpy.y(),
                rpy.z(),
                angle,
                (last.position - first.position).norm(),
                force};
  out.rotation_vector = angle * axis;
  out.grasp_kept = true;
  for (size_t f = 0; f < scene.fingers.size() && f < last.contacts.size(); ++f) {
    if (last.contacts[f].mode == mechanics::ContactMode::kSeparate ||
        !StillOnFace(scene, scene.fingers[f], last.position, last.orientation)) {
      out.grasp_kept = false;
    }
  }
  const size_t contacts = last.contacts.size();
  for (size_t c = 0; c < contacts; ++c) out.modes.push_back(Sequence(r.samples, c));
  return out;
}

std::string ModeSequenceText(const std::vector<mechanics::ContactMode>& modes) {
  if (modes.empty()) return "-";
  std::string s;
  for (auto m : modes) {
    if (!s.empty()) s += '>';
    s += mechanics::ToString(m);
  }
  return s;
}

bool SameDiscreteOutcome(const Outcome& a, const Outcome& b) {
  return a.ok == b.ok && (!a.ok || (a.grasp_kept == b.grasp_kept && a.modes == b.modes));
}

std::string DescribeDiscreteChange(const mechanics::Scene& scene, const Outcome& from,
                                   const Outcome& to) {
  if (from.ok != to.ok) return from.ok ? "model run fails: " + to.error : "model run succeeds";
  if (!from.ok) return "";
  std::string out;
  auto add = [&](const std::string& s) { out += (out.empty() ? "" : "; ") + s; };
  const auto names = ContactNames(scene);
  for (size_t c = 0; c < from.modes.size() && c < to.modes.size(); ++c) {
    if (from.modes[c] != to.modes[c]) {
      add((c < names.size() ? names[c] : "contact " + std::to_string(c)) + ": " +
          ModeSequenceText(from.modes[c]) + " -> " + ModeSequenceText(to.modes[c]));
    }
  }
  if (from.grasp_kept != to.grasp_kept) {
    add(std::string("grasp ") + (from.grasp_kept ? "kept -> lost" : "lost -> kept"));
  }
  return out;
}

}  // namespace arena::assessment
