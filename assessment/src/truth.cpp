#include "arena/assessment/truth.hpp"

#include <stdexcept>
#include <string>

namespace arena::assessment {

namespace {
mechanics::ContactMode ToModel(db::ContactMode m) {
  switch (m) {
    case db::ContactMode::kStick:
      return mechanics::ContactMode::kStick;
    case db::ContactMode::kSlide:
      return mechanics::ContactMode::kSlide;
    case db::ContactMode::kSeparate:
      return mechanics::ContactMode::kSeparate;
  }
  return mechanics::ContactMode::kSeparate;
}
}  // namespace

std::vector<Eigen::Vector3d> ContactNormals(const mechanics::Scene& scene) {
  std::vector<Eigen::Vector3d> normals;
  for (const auto& f : scene.fingers) normals.push_back(f.normal.normalized());
  if (scene.pusher) normals.push_back(scene.pusher->normal.normalized());
  return normals;
}

mechanics::TrajectorySample ToTrajectorySample(const db::Sample& s,
                                               const std::vector<Eigen::Vector3d>& normals,
                                               bool has_pusher, bool forces_measured) {
  if (!forces_measured && !s.contacts.empty()) {
    throw std::invalid_argument("sample has " + std::to_string(s.contacts.size()) +
                                " contacts, and the trial's truth measured no forces");
  }
  if (forces_measured && s.contacts.size() != normals.size()) {
    throw std::invalid_argument("sample has " + std::to_string(s.contacts.size()) +
                                " contacts, the scene " + std::to_string(normals.size()));
  }
  mechanics::TrajectorySample out;
  out.t = s.t;
  out.position = {s.object_pose[0], s.object_pose[1], s.object_pose[2]};
  out.orientation =
      Eigen::Quaterniond(s.object_pose[3], s.object_pose[4], s.object_pose[5], s.object_pose[6]);
  out.velocity = {s.object_twist[0], s.object_twist[1], s.object_twist[2]};
  out.angular_velocity = {s.object_twist[3], s.object_twist[4], s.object_twist[5]};
  out.pusher_position = {s.pusher_pose[0], s.pusher_pose[1], s.pusher_pose[2]};
  out.contacts.resize(s.contacts.size());
  for (size_t i = 0; i < s.contacts.size(); ++i) {
    const Eigen::Vector3d force(s.contacts[i].force[0], s.contacts[i].force[1],
                                s.contacts[i].force[2]);
    auto& c = out.contacts[i];
    c.normal_force = force.dot(normals[i]);
    c.tangential_force = force - c.normal_force * normals[i];
    c.torque = {s.contacts[i].torque[0], s.contacts[i].torque[1], s.contacts[i].torque[2]};
    c.mode = ToModel(s.contacts[i].mode);
  }
  if (has_pusher && !s.contacts.empty()) {  // the pusher is the last contact
    const auto& f = s.contacts.back().force;
    out.pusher_force = {f[0], f[1], f[2]};
  }
  return out;
}

std::vector<mechanics::TrajectorySample> ReadTruth(const db::Store& store, std::int64_t trial_id,
                                                   const mechanics::Scene& scene) {
  const auto normals = ContactNormals(scene);
  const db::GroundTruth gt = store.ReadGroundTruth(trial_id);
  std::vector<mechanics::TrajectorySample> out;
  out.reserve(gt.samples.size());
  for (const auto& s : gt.samples) {
    out.push_back(ToTrajectorySample(s, normals, scene.pusher.has_value(), gt.forces_measured()));
  }
  return out;
}

}  // namespace arena::assessment
