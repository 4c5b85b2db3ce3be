// Scenes built in code for the mechanics tests (docs/scene.md's example scene
// and the textbook set-ups of the validation tests).
#pragma once

#include <cmath>

#include "arena/mechanics/scene.hpp"

namespace arena::mechanics::testing {

inline ContactSpec Finger(const char* name, ContactType type, Eigen::Vector3d position,
                          Eigen::Vector3d normal, double mu) {
  ContactSpec f;
  f.name = name;
  f.type = type;
  f.position = position;
  f.normal = normal;
  f.mu = mu;
  return f;
}

// docs/scene.md's example: a point finger and a line finger, pusher from below.
inline Scene CanonicalScene() {
  Scene s;
  s.object.shape = ObjectShape::kBox;
  s.object.size = {0.05, 0.03, 0.10};
  s.object.mass = 0.2;
  s.gravity = {0, 0, -9.81};
  s.duration = 1.0;
  s.grip_force = 10.0;
  s.fingers.push_back(Finger("left", ContactType::kPoint, {-0.025, 0, 0}, {1, 0, 0}, 0.5));
  ContactSpec right = Finger("right", ContactType::kLine, {0.025, 0, 0}, {-1, 0, 0}, 0.5);
  right.axis = {0, 0, 1};
  right.length = 0.02;
  s.fingers.push_back(right);
  PusherSpec p;
  p.name = "pusher";
  p.type = ContactType::kPoint;
  p.position = {0, 0, -0.05};
  p.normal = {0, 0, 1};
  p.mu = 0.3;
  p.motion.velocity = {0, 0, 0.01};
  s.pusher = p;
  s.model = {8, 3, 0.004, Reduce::kAuto};
  return s;
}

// Two point fingers along ±x holding a box, no pusher.
// A point pusher (scene defaults otherwise) at `position` pressing along
// `normal`, moving at constant `velocity`.
inline PusherSpec Pusher(const Eigen::Vector3d& position, const Eigen::Vector3d& normal,
                         const Eigen::Vector3d& velocity, double mu) {
  PusherSpec p;
  p.name = "pusher";
  p.position = position;
  p.normal = normal;
  p.mu = mu;
  p.motion.velocity = velocity;
  return p;
}

inline Scene HeldBox(double mass, double grip, double mu, int facets = 8) {
  Scene s;
  s.object.shape = ObjectShape::kBox;
  s.object.size = {0.05, 0.03, 0.10};
  s.object.mass = mass;
  s.gravity = {0, 0, -9.81};
  s.duration = 0.2;
  s.grip_force = grip;
  s.fingers.push_back(Finger("left", ContactType::kPoint, {-0.025, 0, 0}, {1, 0, 0}, mu));
  s.fingers.push_back(Finger("right", ContactType::kPoint, {0.025, 0, 0}, {-1, 0, 0}, mu));
  s.model = {facets, 3, 0.004, Reduce::kAuto};
  return s;
}

// Issue 31's pivot past its stall: a 0.2 kg box held at 1 kN by two point
// fingers (μ 0.5), no gravity, a frictionless point pusher 1 cm off the grip
// axis pushing up at 1 cm/s for 0.6 s. Its closed form is
// PivotPastTheStallRoll(): the roll atan(d / (h − v T)).
inline Scene PivotPastTheStall() {
  Scene s = HeldBox(0.2, 1000, 0.5);
  s.gravity = Eigen::Vector3d::Zero();
  s.duration = 0.6;
  PusherSpec p;
  p.name = "pusher";
  p.position = {0, 0.01, -0.05};
  p.normal = {0, 0, 1};
  p.mu = 0.0;
  p.motion.velocity = {0, 0, 0.01};
  s.pusher = p;
  return s;
}
inline double PivotPastTheStallRoll() { return std::atan(0.01 / (0.05 - 0.01 * 0.6)); }

}  // namespace arena::mechanics::testing
