// Per-contact and object outcomes of a trial (outcomes.hpp).
#include "arena/db/outcomes.hpp"

#include <algorithm>
#include <cmath>

namespace arena::db {
namespace {

using V3 = std::array<double, 3>;

V3 Sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double Dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 Cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double Norm(const V3& a) { return std::sqrt(Dot(a, a)); }

// Quaternions (w, x, y, z).
using Q = std::array<double, 4>;
Q QuatOf(const std::array<double, 7>& pose) {
  Q q{pose[3], pose[4], pose[5], pose[6]};
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (n == 0) return {1, 0, 0, 0};
  for (double& v : q) v /= n;
  return q;
}
Q Mul(const Q& a, const Q& b) {
  return {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
          a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
          a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
          a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
}
Q Conj(const Q& q) { return {q[0], -q[1], -q[2], -q[3]}; }
V3 Rotate(const Q& q, const V3& v) {
  const Q r = Mul(Mul(q, {0, v[0], v[1], v[2]}), Conj(q));
  return {r[1], r[2], r[3]};
}
// Rotation vector (axis * angle, angle in [0, pi]) of a unit quaternion.
V3 RotationVector(Q q) {
  if (q[0] < 0)
    for (double& v : q) v = -v;  // the shorter way round
  const double s = std::sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (s < 1e-15) return {2 * q[1], 2 * q[2], 2 * q[3]};
  const double angle = 2 * std::atan2(s, q[0]);
  return {q[1] / s * angle, q[2] / s * angle, q[3] / s * angle};
}

}  // namespace

OutcomeAccumulator::OutcomeAccumulator(std::vector<ContactSite> sites) : sites_(std::move(sites)) {}

void OutcomeAccumulator::Add(const Sample& s) {
  if (s.contacts.size() != sites_.size()) {
    // The cell reported another set of contacts than the scene has: keep the
    // mode fractions (by position) but no geometry-based slip.
    slip_known_ = false;
  }
  if (per_contact_.size() < s.contacts.size()) per_contact_.resize(s.contacts.size());
  const double dt = samples_ == 0 ? 0.0 : std::max(0.0, s.t - last_t_);
  const V3 x{s.object_pose[0], s.object_pose[1], s.object_pose[2]};
  const V3 v{s.object_twist[0], s.object_twist[1], s.object_twist[2]};
  const V3 w{s.object_twist[3], s.object_twist[4], s.object_twist[5]};
  const V3 pusher_at{s.pusher_pose[0], s.pusher_pose[1], s.pusher_pose[2]};
  const V3 pusher_v{s.pusher_twist[0], s.pusher_twist[1], s.pusher_twist[2]};
  const Q pusher_turn =
      samples_ == 0 ? Q{1, 0, 0, 0} : Mul(QuatOf(s.pusher_pose), Conj(QuatOf(first_pusher_pose_)));
  for (std::size_t c = 0; c < s.contacts.size(); ++c) {
    auto& pc = per_contact_[c];
    const auto& contact = s.contacts[c];
    ++pc.modes[static_cast<int>(contact.mode)];
    const bool geometry = slip_known_ && c < sites_.size() && sites_[c].known;
    if (!geometry) continue;
    const ContactSite& site = sites_[c];
    const V3 n = site.pusher ? Rotate(pusher_turn, site.normal) : site.normal;
    pc.max_normal =
        std::max(pc.max_normal, Dot({contact.force[0], contact.force[1], contact.force[2]}, n));
    if (contact.mode == ContactMode::kSeparate || dt <= 0) continue;
    const V3 p = site.pusher ? pusher_at : site.position;
    const V3 wr = Cross(w, Sub(p, x));
    V3 rel{v[0] + wr[0], v[1] + wr[1], v[2] + wr[2]};
    if (site.pusher) rel = Sub(rel, pusher_v);
    const double along = Dot(rel, n);
    const V3 tangential{rel[0] - along * n[0], rel[1] - along * n[1], rel[2] - along * n[2]};
    pc.slip += Norm(tangential) * dt;
  }
  if (samples_ == 0) {
    first_pose_ = s.object_pose;
    first_pusher_pose_ = s.pusher_pose;
  }
  last_pose_ = s.object_pose;
  last_t_ = s.t;
  last_modes_.resize(s.contacts.size());
  for (std::size_t c = 0; c < s.contacts.size(); ++c) last_modes_[c] = s.contacts[c].mode;
  ++samples_;
}

TrialOutcome OutcomeAccumulator::Result() const {
  TrialOutcome out;
  for (std::size_t c = 0; c < per_contact_.size(); ++c) {
    const auto& pc = per_contact_[c];
    ContactOutcome o;
    o.contact = c;
    const bool named = slip_known_ && c < sites_.size();
    o.name = named ? sites_[c].name : "contact" + std::to_string(c);
    o.pusher = named && sites_[c].pusher;
    const double n = static_cast<double>(pc.modes[0] + pc.modes[1] + pc.modes[2]);
    if (n > 0) {
      o.stick_fraction = pc.modes[0] / n;
      o.slide_fraction = pc.modes[1] / n;
      o.separate_fraction = pc.modes[2] / n;
    }
    if (named && sites_[c].known && samples_ >= 2) o.slip_distance = pc.slip;
    o.max_normal_force = pc.max_normal;
    out.contacts.push_back(std::move(o));
  }
  if (samples_ == 0) return out;
  out.net_translation = Sub({last_pose_[0], last_pose_[1], last_pose_[2]},
                            {first_pose_[0], first_pose_[1], first_pose_[2]});
  out.net_rotation = RotationVector(Mul(QuatOf(last_pose_), Conj(QuatOf(first_pose_))));
  bool any_finger = false, kept = true;
  for (std::size_t c = 0; c < last_modes_.size(); ++c) {
    const bool finger = slip_known_ ? (c < sites_.size() && !sites_[c].pusher) : false;
    if (!finger) continue;
    any_finger = true;
    kept = kept && last_modes_[c] != ContactMode::kSeparate;
  }
  if (any_finger) out.grasp_kept = kept;
  return out;
}

TrialOutcome ComputeOutcome(const std::vector<Sample>& samples,
                            const std::vector<ContactSite>& sites) {
  OutcomeAccumulator acc(sites);
  for (const auto& s : samples) acc.Add(s);
  return acc.Result();
}

}  // namespace arena::db
