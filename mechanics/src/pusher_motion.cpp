// The pusher's pose along its motion (pusher_motion.hpp).
#include "arena/mechanics/pusher_motion.hpp"

#include <algorithm>
#include <cmath>

#include "arena/mechanics/model.hpp"

namespace arena::mechanics {

namespace {

// The index k of the path segment [t_k, t_k+1] holding t (the last sample
// when t is past the end: the pusher rests there).
size_t SegmentOf(const PusherPath& path, double t) {
  const auto it = std::upper_bound(path.t.begin(), path.t.end(), t);
  const size_t k = static_cast<size_t>(it - path.t.begin());
  return k == 0 ? 0 : k - 1;
}

Eigen::Quaterniond PathOrientation(const PusherPath& path, double t) {
  if (path.rpy.empty()) return Eigen::Quaterniond::Identity();
  const size_t k = SegmentOf(path, t);
  const Eigen::Quaterniond q0(RotationFromRpy(path.rpy[0]));
  const Eigen::Quaterniond qk(RotationFromRpy(path.rpy[k]));
  if (k + 1 >= path.t.size()) return (qk * q0.conjugate()).normalized();
  const Eigen::Quaterniond qn(RotationFromRpy(path.rpy[k + 1]));
  const double s = (t - path.t[k]) / (path.t[k + 1] - path.t[k]);
  return (qk.slerp(std::clamp(s, 0.0, 1.0), qn) * q0.conjugate()).normalized();
}

}  // namespace

PusherPose PusherPoseAt(const PusherSpec& pusher, double t) {
  PusherPose out;
  if (!pusher.path) {
    const Eigen::Vector3d& w = pusher.motion.angular_velocity;
    out.position = pusher.position + pusher.motion.velocity * t;
    const double a = w.norm() * t;
    out.turned = a > 0;
    if (out.turned) out.rotation = Eigen::AngleAxisd(a, w.normalized()).toRotationMatrix();
    return out;
  }
  const PusherPath& path = *pusher.path;
  const size_t k = SegmentOf(path, t);
  if (k + 1 >= path.t.size()) {
    out.position = path.position.back();
  } else {
    const double s = std::clamp((t - path.t[k]) / (path.t[k + 1] - path.t[k]), 0.0, 1.0);
    out.position = path.position[k] + s * (path.position[k + 1] - path.position[k]);
  }
  if (!path.rpy.empty()) {
    const Eigen::Quaterniond q = PathOrientation(path, t);
    out.turned = q.vec().norm() > 0;
    out.rotation = q.toRotationMatrix();
  }
  return out;
}

PusherTwist PusherTwistOver(const PusherSpec& pusher, double t, double dt) {
  PusherTwist out;
  if (!pusher.path) {
    out.velocity = pusher.motion.velocity;
    out.angular_velocity = pusher.motion.angular_velocity;
    return out;
  }
  const PusherPose a = PusherPoseAt(pusher, t), b = PusherPoseAt(pusher, t + dt);
  out.velocity = (b.position - a.position) / dt;
  if (!pusher.path->rpy.empty()) {
    const Eigen::AngleAxisd turn(b.rotation * a.rotation.transpose());
    out.angular_velocity = turn.axis() * (turn.angle() / dt);
  }
  return out;
}

PusherTwist PusherPeakRates(const PusherSpec& pusher) {
  PusherTwist out;
  if (!pusher.path) {
    out.velocity = pusher.motion.velocity;
    out.angular_velocity = pusher.motion.angular_velocity;
    return out;
  }
  const PusherPath& path = *pusher.path;
  for (size_t k = 0; k + 1 < path.t.size(); ++k) {
    const double span = path.t[k + 1] - path.t[k];
    const Eigen::Vector3d v = (path.position[k + 1] - path.position[k]) / span;
    if (v.norm() > out.velocity.norm()) out.velocity = v;
    if (!path.rpy.empty()) {
      const Eigen::AngleAxisd turn(RotationFromRpy(path.rpy[k + 1]) *
                                   RotationFromRpy(path.rpy[k]).transpose());
      const Eigen::Vector3d w = turn.axis() * (turn.angle() / span);
      if (w.norm() > out.angular_velocity.norm()) out.angular_velocity = w;
    }
  }
  return out;
}

}  // namespace arena::mechanics
