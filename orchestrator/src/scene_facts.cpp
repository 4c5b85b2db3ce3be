#include "arena/orchestrator/scene_facts.hpp"

#include <cmath>

#include <Eigen/Geometry>

#include "arena/db/store.hpp"
#include "arena/mechanics/frames.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/trial_data.hpp"

namespace arena::orchestrator {
namespace {

// |v| summed in x, y, z order: the stored speeds keep the bits they always had.
double Norm(const Eigen::Vector3d& v) {
  double sum = 0;
  for (int i = 0; i < 3; ++i) sum += v[i] * v[i];
  return std::sqrt(sum);
}

}  // namespace

db::SceneFacts SceneFactsOf(const mechanics::Scene& scene) {
  db::SceneFacts f;
  f.object_shape = mechanics::ToString(scene.object.shape);
  f.object_mass = scene.object.mass;
  f.grip_force = scene.grip_force;
  f.duration = scene.duration;
  double mu_sum = 0;
  for (const auto& finger : scene.fingers) {
    const std::string type = mechanics::ToString(finger.type);
    f.contact_mask |= db::ContactTypeMask({type});
    f.finger_type = !f.finger_type || *f.finger_type == type ? type : "mixed";
    mu_sum += finger.mu;
  }
  f.finger_count = static_cast<int>(scene.fingers.size());
  if (!scene.fingers.empty()) f.finger_mu = mu_sum / static_cast<double>(scene.fingers.size());
  if (const auto& p = scene.pusher) {
    f.pusher_type = mechanics::ToString(p->type);
    f.contact_mask |= db::ContactTypeMask({*f.pusher_type});
    f.pusher_mu = p->mu;
    if (!p->path && !p->controller) {  // a velocity motion: its speeds
      f.pusher_speed = Norm(p->motion.velocity);
      f.pusher_angular_speed = Norm(p->motion.angular_velocity);
    }
  }
  // The model's own start orientation (mechanics' RotationFromRpy).
  const Eigen::Quaterniond q(mechanics::RotationFromRpy(scene.object.pose.rpy));
  const Eigen::Vector3d& x = scene.object.pose.position;
  f.nominal = {x.x(), x.y(), x.z(), q.w(), q.x(), q.y(), q.z()};
  f.contacts = ContactSitesOf(scene);
  return f;
}

db::SceneFacts SceneFactsOfJson(const std::string& scene_json) {
  return SceneFactsOf(mechanics::ParseScene(scene_json));
}

}  // namespace arena::orchestrator
