#include "arena/schemas/ground_truth.hpp"

#include <cmath>

#include "arena/schemas/arena.h"

namespace arena::dds {
namespace {

void PutPose(const Eigen::Vector3d& p, const Eigen::Quaterniond& q, std::array<double, 7>* out) {
  *out = {p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z()};
}
void GetPose(const std::array<double, 7>& in, Eigen::Vector3d* p, Eigen::Quaterniond* q) {
  *p = {in[0], in[1], in[2]};
  *q = Eigen::Quaterniond(in[3], in[4], in[5], in[6]);
}
void PutTwist(const Eigen::Vector3d& v, const Eigen::Vector3d& w, std::array<double, 6>* out) {
  *out = {v.x(), v.y(), v.z(), w.x(), w.y(), w.z()};
}
msg::ContactMode ToMsg(mechanics::ContactMode m) {
  switch (m) {
    case mechanics::ContactMode::kStick:
      return msg::MODE_STICK;
    case mechanics::ContactMode::kSlide:
      return msg::MODE_SLIDE;
    case mechanics::ContactMode::kSeparate:
      return msg::MODE_SEPARATE;
  }
  return msg::MODE_SEPARATE;
}
mechanics::ContactMode FromMsg(msg::ContactMode m) {
  switch (m) {
    case msg::MODE_STICK:
      return mechanics::ContactMode::kStick;
    case msg::MODE_SLIDE:
      return mechanics::ContactMode::kSlide;
    case msg::MODE_SEPARATE:
      return mechanics::ContactMode::kSeparate;
  }
  return mechanics::ContactMode::kSeparate;
}

template <class Array>
std::string CheckFinite(const Array& a, const std::string& field) {
  for (size_t i = 0; i < a.size(); ++i) {
    if (!std::isfinite(a[i])) return field + "[" + std::to_string(i) + "]: not finite";
  }
  return "";
}
std::string CheckQuaternion(const std::array<double, 7>& pose, const std::string& field) {
  const double n2 = pose[3] * pose[3] + pose[4] * pose[4] + pose[5] * pose[5] + pose[6] * pose[6];
  if (std::abs(n2 - 1.0) > 2e-6) return field + "[3..6]: quaternion is not unit length";
  return "";
}

}  // namespace

void EncodeSample(const mechanics::TrajectorySample& truth, const PusherState& pusher,
                  const Observation& observed, msg::GroundTruthSample* out) {
  out->t(truth.t);
  PutPose(truth.position, truth.orientation, &out->object_pose());
  PutTwist(truth.velocity, truth.angular_velocity, &out->object_twist());
  PutPose(pusher.position, pusher.orientation, &out->pusher_pose());
  PutTwist(pusher.velocity, pusher.angular_velocity, &out->pusher_twist());
  out->pusher_force() = {truth.pusher_force.x(), truth.pusher_force.y(), truth.pusher_force.z()};
  out->contacts().resize(truth.contacts.size());
  for (size_t i = 0; i < truth.contacts.size(); ++i) {
    const auto& c = truth.contacts[i];
    auto& m = out->contacts()[i];
    m.normal_force(c.normal_force);
    m.tangential_force() = {c.tangential_force.x(), c.tangential_force.y(), c.tangential_force.z()};
    m.torque() = {c.torque.x(), c.torque.y(), c.torque.z()};
    m.mode(ToMsg(c.mode));
  }
  out->observed_valid(observed.valid);
  out->observed_t(observed.valid ? observed.t : 0.0);
  if (observed.valid) {
    PutPose(observed.position, observed.orientation, &out->observed_object_pose());
    for (int k = 0; k < 6; ++k) out->observed_pusher_wrench()[k] = observed.pusher_wrench[k];
    out->observed_finger_wrenches().resize(6 * observed.finger_wrenches.size());
    for (size_t f = 0; f < observed.finger_wrenches.size(); ++f) {
      for (int k = 0; k < 6; ++k)
        out->observed_finger_wrenches()[6 * f + k] = observed.finger_wrenches[f][k];
    }
  } else {
    out->observed_object_pose() = {0, 0, 0, 1, 0, 0, 0};
    out->observed_pusher_wrench() = {0, 0, 0, 0, 0, 0};
    // Zeros, keeping the shape: a dropped sample has as many finger values as the others.
    out->observed_finger_wrenches().assign(6 * observed.finger_wrenches.size(), 0.0);
  }
}

mechanics::TrajectorySample DecodeSample(const msg::GroundTruthSample& in, PusherState* pusher,
                                         Observation* observed) {
  mechanics::TrajectorySample s;
  s.t = in.t();
  GetPose(in.object_pose(), &s.position, &s.orientation);
  const auto& tw = in.object_twist();
  s.velocity = {tw[0], tw[1], tw[2]};
  s.angular_velocity = {tw[3], tw[4], tw[5]};
  s.pusher_position = {in.pusher_pose()[0], in.pusher_pose()[1], in.pusher_pose()[2]};
  s.pusher_force = {in.pusher_force()[0], in.pusher_force()[1], in.pusher_force()[2]};
  s.contacts.resize(in.contacts().size());
  for (size_t i = 0; i < in.contacts().size(); ++i) {
    const auto& m = in.contacts()[i];
    auto& c = s.contacts[i];
    c.normal_force = m.normal_force();
    c.tangential_force = {m.tangential_force()[0], m.tangential_force()[1],
                          m.tangential_force()[2]};
    c.torque = {m.torque()[0], m.torque()[1], m.torque()[2]};
    c.mode = FromMsg(m.mode());
  }
  if (pusher != nullptr) {
    GetPose(in.pusher_pose(), &pusher->position, &pusher->orientation);
    const auto& pt = in.pusher_twist();
    pusher->velocity = {pt[0], pt[1], pt[2]};
    pusher->angular_velocity = {pt[3], pt[4], pt[5]};
  }
  if (observed != nullptr && !in.observed_valid()) {
    // A dropped observation carries no data; whatever the sender left in the
    // fields (CheckSample does not look at them) must not leak out as values.
    *observed = Observation{};
  } else if (observed != nullptr) {
    observed->valid = true;
    observed->t = in.observed_t();
    GetPose(in.observed_object_pose(), &observed->position, &observed->orientation);
    for (int k = 0; k < 6; ++k) observed->pusher_wrench[k] = in.observed_pusher_wrench()[k];
    observed->finger_wrenches.assign(in.observed_finger_wrenches().size() / 6, Wrench::Zero());
    for (size_t f = 0; f < observed->finger_wrenches.size(); ++f) {
      for (int k = 0; k < 6; ++k)
        observed->finger_wrenches[f][k] = in.observed_finger_wrenches()[6 * f + k];
    }
  }
  return s;
}

std::string CheckSample(const msg::GroundTruthSample& s) {
  if (!std::isfinite(s.t()) || s.t() < 0) return "samples[].t: must be finite and >= 0";
  for (const std::string& e : {CheckFinite(s.object_pose(), "samples[].object_pose"),
                               CheckQuaternion(s.object_pose(), "samples[].object_pose"),
                               CheckFinite(s.object_twist(), "samples[].object_twist"),
                               CheckFinite(s.pusher_pose(), "samples[].pusher_pose"),
                               CheckQuaternion(s.pusher_pose(), "samples[].pusher_pose"),
                               CheckFinite(s.pusher_twist(), "samples[].pusher_twist"),
                               CheckFinite(s.pusher_force(), "samples[].pusher_force")}) {
    if (!e.empty()) return e;
  }
  if (s.contacts().size() > kMaxContacts) return "samples[].contacts: more than 16 contacts";
  for (const auto& c : s.contacts()) {
    if (!std::isfinite(c.normal_force())) return "samples[].contacts[].normal_force: not finite";
    if (!CheckFinite(c.tangential_force(), "").empty())
      return "samples[].contacts[].tangential_force: not finite";
    if (!CheckFinite(c.torque(), "").empty()) return "samples[].contacts[].torque: not finite";
    if (c.mode() != msg::MODE_STICK && c.mode() != msg::MODE_SLIDE &&
        c.mode() != msg::MODE_SEPARATE) {
      return "samples[].contacts[].mode: unknown value";
    }
  }
  if (s.observed_valid()) {
    if (!std::isfinite(s.observed_t())) return "samples[].observed_t: not finite";
    for (const std::string& e :
         {CheckFinite(s.observed_object_pose(), "samples[].observed_object_pose"),
          CheckQuaternion(s.observed_object_pose(), "samples[].observed_object_pose"),
          CheckFinite(s.observed_pusher_wrench(), "samples[].observed_pusher_wrench"),
          CheckFinite(s.observed_finger_wrenches(), "samples[].observed_finger_wrenches")}) {
      if (!e.empty()) return e;
    }
    if (s.observed_finger_wrenches().size() % 6 != 0) {
      return "samples[].observed_finger_wrenches: length is not a multiple of 6";
    }
  }
  return "";
}

std::string CheckBatch(const msg::GroundTruth& batch, std::uint32_t next_sample) {
  if (batch.first_sample() != next_sample) {
    return "first_sample: expected " + std::to_string(next_sample) + ", got " +
           std::to_string(batch.first_sample());
  }
  if (batch.samples().empty() && !batch.last()) return "samples: empty batch that is not the last";
  double previous_t = -1;
  for (const auto& s : batch.samples()) {
    if (std::string e = CheckSample(s); !e.empty()) return e;
    if (!(s.t() > previous_t)) return "samples[].t: not increasing";
    previous_t = s.t();
  }
  return "";
}

}  // namespace arena::dds
