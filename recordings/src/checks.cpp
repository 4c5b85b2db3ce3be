// Every recorded trial checked against its geometry and for the defects
// real recordings have (recording.hpp: CheckTrial; docs/real_data.md).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "arena/recordings/recording.hpp"

namespace arena::recordings {
namespace {

std::string Mm(double m) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f mm", m * 1e3);
  return b;
}
std::string N(double f) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f N", f);
  return b;
}
std::string S(double t) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3f s", t);
  return b;
}

// Pusher disk to outline at sample k (m; < 0: the disk overlaps the outline).
double Gap(const Recording& r, const Resampled& s, std::size_t k) {
  const double c = std::cos(s.object[k][2]), sn = std::sin(s.object[k][2]);
  const double dx = s.pusher[k][0] - s.object[k][0], dy = s.pusher[k][1] - s.object[k][1];
  return SignedDistance(r.shape.outline, c * dx + sn * dy, -sn * dx + c * dy) - r.pusher_radius;
}

// How far the outline's farthest point has moved from the start (m).
double Motion(const Recording& r, const Resampled& s, std::size_t k) {
  double extent = 0;
  for (const auto& v : r.shape.outline) extent = std::max(extent, std::hypot(v[0], v[1]));
  return std::hypot(s.object[k][0] - s.object[0][0], s.object[k][1] - s.object[0][1]) +
         extent * std::abs(s.object[k][2] - s.object[0][2]);
}

// A finding written into the checks: one that fails the pose or the force
// stream, or a note that keeps both usable.
void FailPose(TrialChecks* c, std::string check, std::string detail) {
  c->findings.push_back({std::move(check), std::move(detail), true});
  c->pose_usable = false;
}
void FailForce(TrialChecks* c, std::string check, std::string detail) {
  c->findings.push_back({std::move(check), std::move(detail), true});
  c->force_usable = false;
}
void Note(TrialChecks* c, std::string check, std::string detail) {
  c->findings.push_back({std::move(check), std::move(detail), false});
}

void CheckStampOrder(const Recording& r, const Resampled& s, TrialChecks* c) {
  for (const auto& [count, stream] : {std::pair{s.object_out_of_order, r.object_pose.name},
                                      std::pair{s.pusher_out_of_order, r.pusher_pose.name},
                                      std::pair{s.force_out_of_order, r.force.name}}) {
    if (count > 0)
      Note(
          c, "out_of_order_stamps",
          stream + ": " + std::to_string(count) + " stamp(s) earlier than the one before (sorted)");
  }
}

// Geometry: the pusher must start outside the outline (a calibration error
// shows as a start inside it) and touch it when the object starts to move.
void CheckContactGeometry(const Recording& r, const Resampled& s, const CheckOptions& o,
                          TrialChecks* c) {
  const std::size_t n = s.t.size();
  c->start_gap = Gap(r, s, 0);
  if (c->start_gap < -o.inside_fail)
    FailPose(c, "pusher_inside_at_start",
             "the pusher disk starts " + Mm(-c->start_gap) + " inside the outline (more than " +
                 Mm(o.inside_fail) + ": the poses or the outline are off)");
  else if (c->start_gap < -o.inside_warn)
    Note(c, "pusher_inside_at_start",
         "the pusher disk starts " + Mm(-c->start_gap) +
             " inside the outline (calibration; within " + Mm(o.inside_fail) + ", kept)");
  c->onset_t = NAN;
  c->onset_gap = NAN;
  for (std::size_t k = 0; k < n; ++k) {
    if (Motion(r, s, k) > o.onset_motion) {
      c->onset_t = s.t[k];
      c->onset_gap = Gap(r, s, k);
      break;
    }
  }
  if (std::isnan(c->onset_t)) {
    Note(c, "object_did_not_move", "no point of the outline moved more than " + Mm(o.onset_motion));
  } else if (std::abs(c->onset_gap) > o.onset_gap_tol) {
    FailPose(c, "contact_gap_at_onset",
             "the object starts to move at " + S(c->onset_t) + " with the pusher disk " +
                 Mm(c->onset_gap) + " from the outline (tolerance " + Mm(o.onset_gap_tol) +
                 "): frame or calibration off");
  }
}

// The push angle: from the inward normal at the start contact to the
// pusher's travel, in the object's start frame; against the lab's own.
void CheckPushAngle(const Recording& r, const Resampled& s, const CheckOptions& o, TrialChecks* c) {
  constexpr double kDeg = 180 / 3.14159265358979323846;
  const std::size_t n = s.t.size();
  const double c0 = std::cos(s.object[0][2]), s0 = std::sin(s.object[0][2]);
  const auto local = [&](double dx, double dy) {
    return std::array<double, 2>{c0 * dx + s0 * dy, -s0 * dx + c0 * dy};
  };
  const auto p0 = local(s.pusher[0][0] - s.object[0][0], s.pusher[0][1] - s.object[0][1]);
  const auto q = NearestPoint(r.shape.outline, p0[0], p0[1]);
  const double side = SignedDistance(r.shape.outline, p0[0], p0[1]) < 0 ? -1.0 : 1.0;
  const double nx = side * (q[0] - p0[0]), ny = side * (q[1] - p0[1]);
  const auto d = local(s.pusher[n - 1][0] - s.pusher[0][0], s.pusher[n - 1][1] - s.pusher[0][1]);
  c->push_angle = std::atan2(nx * d[1] - ny * d[0], nx * d[0] + ny * d[1]);
  if (std::isnan(r.stated_push_angle)) return;
  const double diff =
      std::remainder(c->push_angle - r.stated_push_angle, 2 * 3.14159265358979323846);
  if (std::abs(diff) > o.angle_fail) {
    char b[200];
    std::snprintf(b, sizeof b,
                  "the pusher travels at %.1f deg from the inward normal, the recording "
                  "states %.1f deg (tolerance %.1f): frame, outline or parameters off",
                  c->push_angle * kDeg, r.stated_push_angle * kDeg, o.angle_fail * kDeg);
    FailPose(c, "push_angle_mismatch", b);
  }
}

// A sensor that stopped updating repeats its last row.
void CheckForceFrozen(const Recording& r, const CheckOptions& o, TrialChecks* c) {
  std::size_t repeats = 0;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::size_t i = 0; i < r.force.values.size(); ++i) {
    if (i > 0 && r.force.values[i] == r.force.values[i - 1]) ++repeats;
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], r.force.values[i][k]);
      hi[k] = std::max(hi[k], r.force.values[i][k]);
    }
  }
  const bool constant = hi[0] - lo[0] <= o.frozen_range && hi[1] - lo[1] <= o.frozen_range &&
                        hi[2] - lo[2] <= o.frozen_range;
  if (constant || 2 * repeats > r.force.values.size()) {
    FailForce(c, "force_frozen",
              std::to_string(repeats) + " of " + std::to_string(r.force.values.size()) +
                  " force rows repeat the row before (a sensor that stopped "
                  "updating)");
  }
}

// The zero: the mean force before the pusher starts to move (nothing pushes
// yet) and, where the pusher is clear of the object at the end, again.
void CheckForceZero(const Recording& r, const Resampled& s, const CheckOptions& o, TrialChecks* c) {
  const std::size_t n = s.t.size();
  std::size_t moves = n;
  for (std::size_t k = 0; k < n; ++k) {
    if (std::hypot(s.pusher[k][0] - s.pusher[0][0], s.pusher[k][1] - s.pusher[0][1]) >
        o.onset_motion) {
      moves = k;
      break;
    }
  }
  if (moves < 5) {
    Note(c, "force_zero_unknown",
         "the pusher moves from the first sample: the zero is not measured");
    return;
  }
  double fx = 0, fy = 0;
  for (std::size_t k = 0; k < moves; ++k) {
    fx += s.force[k][0];
    fy += s.force[k][1];
  }
  fx /= static_cast<double>(moves);
  fy /= static_cast<double>(moves);
  c->force_offset = std::hypot(fx, fy);
  std::size_t clear = 0;
  double ex = 0, ey = 0;
  for (std::size_t k = n; k-- > moves && Gap(r, s, k) > o.clear_gap;) {
    ex += s.force[k][0];
    ey += s.force[k][1];
    ++clear;
  }
  if (clear >= 5) c->force_drift = std::hypot(ex / clear - fx, ey / clear - fy);
  if (c->force_usable && c->force_offset > o.offset_fail)
    FailForce(c, "force_offset_drift",
              "the force reads " + N(c->force_offset) + " before the pusher moves (over " +
                  S(s.t[moves]) + "; more than " + N(o.offset_fail) +
                  "): the sensor's zero has drifted");
  else if (c->force_usable && !std::isnan(c->force_drift) && c->force_drift > o.drift_fail)
    FailForce(c, "force_offset_drift",
              "the force's zero moved by " + N(c->force_drift) +
                  " between the start and the end (more than " + N(o.drift_fail) + ")");
}

}  // namespace

TrialChecks CheckTrial(const Recording& r, const Resampled& s, const CheckOptions& o) {
  TrialChecks c;
  const std::size_t n = s.t.size();
  CheckStampOrder(r, s, &c);
  c.object_travel =
      std::hypot(s.object[n - 1][0] - s.object[0][0], s.object[n - 1][1] - s.object[0][1]);
  c.object_rotation = s.object[n - 1][2] - s.object[0][2];
  CheckContactGeometry(r, s, o, &c);
  CheckPushAngle(r, s, o, &c);
  // Force stream: frozen, and its zero (the force read while nothing pushes).
  c.force_offset = NAN;
  c.force_drift = NAN;
  if (r.force.values.empty()) {
    c.force_usable = false;
    Note(&c, "force_not_measured", "the recording has no force stream");
    return c;
  }
  CheckForceFrozen(r, o, &c);
  CheckForceZero(r, s, o, &c);
  return c;
}

}  // namespace arena::recordings
