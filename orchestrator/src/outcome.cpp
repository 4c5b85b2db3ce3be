// Outcome functions (outcome.hpp).
#include "arena/orchestrator/outcome.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

namespace arena::orchestrator {
namespace {

template <typename Sample, typename Pos, typename Rot, typename Mode>
TrialOutcome Compute(const std::vector<Sample>& samples, int fingers, Pos position, Rot rotation,
                     Mode finger_mode) {
  TrialOutcome out;
  out.samples = static_cast<int>(samples.size());
  if (samples.empty()) return out;
  const Eigen::Vector3d p0 = position(samples.front());
  const Eigen::Vector3d p1 = position(samples.back());
  for (int k = 0; k < 3; ++k) out.final_position[static_cast<size_t>(k)] = p1[k];
  out.displacement = (p1 - p0).norm();
  out.rotation = rotation(samples.front()).angularDistance(rotation(samples.back()));
  long sliding = 0, pairs = 0;
  const size_t tail = samples.size() - std::max<size_t>(1, samples.size() / 10);
  for (size_t i = 0; i < samples.size(); ++i) {
    for (int f = 0; f < fingers; ++f) {
      const int mode = finger_mode(samples[i], f);  // 0 stick, 1 slide, 2 separate, -1 absent
      if (mode < 0) continue;
      ++pairs;
      sliding += mode == 1;
      if (i >= tail && mode == 2) out.fingers_touching_at_end = false;
    }
  }
  out.finger_slide_fraction = pairs ? static_cast<double>(sliding) / static_cast<double>(pairs) : 0;
  return out;
}

}  // namespace

TrialOutcome ComputeOutcome(const std::vector<db::Sample>& samples, int fingers) {
  return Compute(
      samples, fingers,
      [](const db::Sample& s) {
        return Eigen::Vector3d(s.object_pose[0], s.object_pose[1], s.object_pose[2]);
      },
      [](const db::Sample& s) {
        return Eigen::Quaterniond(s.object_pose[3], s.object_pose[4], s.object_pose[5],
                                  s.object_pose[6])
            .normalized();
      },
      [](const db::Sample& s, int f) {
        return f < static_cast<int>(s.contacts.size())
                   ? static_cast<int>(s.contacts[static_cast<size_t>(f)].mode)
                   : -1;
      });
}

TrialOutcome ComputeOutcome(const std::vector<mechanics::TrajectorySample>& samples, int fingers) {
  return Compute(
      samples, fingers, [](const mechanics::TrajectorySample& s) { return s.position; },
      [](const mechanics::TrajectorySample& s) { return s.orientation.normalized(); },
      [](const mechanics::TrajectorySample& s, int f) {
        if (f >= static_cast<int>(s.contacts.size())) return -1;
        switch (s.contacts[static_cast<size_t>(f)].mode) {
          case mechanics::ContactMode::kStick:
            return 0;
          case mechanics::ContactMode::kSlide:
            return 1;
          case mechanics::ContactMode::kSeparate:
            return 2;
        }
        return -1;
      });
}

bool Classify(OutcomeKind kind, double threshold, const TrialOutcome& o) {
  switch (kind) {
    case OutcomeKind::kPivoted:
      return o.rotation > threshold;
    case OutcomeKind::kFingerSlip:
      return o.finger_slide_fraction > threshold;
    case OutcomeKind::kGraspKept:
      return o.fingers_touching_at_end && o.displacement <= threshold;
  }
  return false;
}

const char* ClassName(OutcomeKind kind, bool positive) {
  switch (kind) {
    case OutcomeKind::kPivoted:
      return positive ? "pivoted" : "not pivoted";
    case OutcomeKind::kFingerSlip:
      return positive ? "slide" : "stick";
    case OutcomeKind::kGraspKept:
      return positive ? "kept" : "lost";
  }
  return "?";
}

}  // namespace arena::orchestrator
