// What happened in a trial, per contact and for the object, computed from its
// ground-truth samples alone (a pure function: the same samples and contact
// geometry always give the same outcome). The ingest stores the result with
// the stream (tables contact_outcomes and gt_summary, db/README.md), so
// "which grip force made the fingers slip?" is one query.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "arena/db/sample.hpp"

namespace arena::db {

// Where a contact sits, from the scene (gripper frame G at the start of the
// trial), as the caller read it (db reads no scene: SceneFacts::contacts). Fingers are fixed in G;
// the pusher's contact point moves with the pusher (its position and normal follow the sample's
// pusher pose).
struct ContactSite {
  std::string name;                  // the finger's name, "pusher", or "contact<i>"
  bool pusher = false;               // the pusher (last contact) rather than a finger
  std::array<double, 3> position{};  // m, in G (for the pusher: relative to its pose)
  std::array<double, 3> normal{};    // unit, in G (pusher: in its own frame at t = 0)
  bool known = false;                // false: no geometry (slip distance not computed)
};

struct ContactOutcome {
  std::size_t contact = 0;  // index in scene order
  std::string name;
  bool pusher = false;
  double stick_fraction = 0, slide_fraction = 0, separate_fraction = 0;  // of its samples
  // Path length of the object's material point at the contact relative to
  // the finger (or pusher), tangential to the contact, summed over samples in
  // contact (stick or slide): how far the contact slipped (m). Absent
  // without contact geometry or with fewer than two samples.
  std::optional<double> slip_distance;
  double max_normal_force = 0;  // N, largest force component along the contact normal
};

struct TrialOutcome {
  std::vector<ContactOutcome> contacts;
  // Object, gripper frame G: last minus first position (m) and the rotation
  // from the first to the last orientation as a rotation vector (axis * angle,
  // rad, in G). Absent without samples.
  std::optional<std::array<double, 3>> net_translation;
  std::optional<std::array<double, 3>> net_rotation;
  // Every finger still touches the object (stick or slide) at the last
  // sample. Absent without fingers or samples.
  std::optional<bool> grasp_kept;
};

// Accumulates samples as they arrive (the ingest) with the result of
// ComputeOutcome over the same samples.
class OutcomeAccumulator {
 public:
  explicit OutcomeAccumulator(std::vector<ContactSite> sites);
  void Add(const Sample& s);
  TrialOutcome Result() const;

 private:
  struct PerContact {
    std::size_t modes[3] = {0, 0, 0};
    double slip = 0;
    double max_normal = 0;
  };
  std::vector<ContactSite> sites_;
  std::vector<PerContact> per_contact_;
  std::size_t samples_ = 0;
  // Only what Result() needs of the first and last samples (no per-sample allocation).
  std::array<double, 7> first_pose_{}, last_pose_{}, first_pusher_pose_{};
  double last_t_ = 0;
  std::vector<ContactMode> last_modes_;
  bool slip_known_ = true;
};

// The outcome of one trial from its samples and contact geometry.
TrialOutcome ComputeOutcome(const std::vector<Sample>& samples,
                            const std::vector<ContactSite>& sites);

}  // namespace arena::db
