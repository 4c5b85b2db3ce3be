// A cell's fixtures and their changes (issue 29): what a trial's scene asks
// the cell to have mounted, and what going from one mounting to another
// costs. Shared by the cell (which emulates the change), the service (which
// chooses which trial a cell claims and records each change) and an `exec:`
// driver's hello (which declares its own costs), so both ends judge a change
// by the same rule.
//
//   fixture   what is changed by hand or by a tool changer between trials
//     finger  the finger pads: type, size, friction, stiffness of every finger
//     pusher  the pusher tool: type, size, normal and axis -- exactly what makes
//             a reset swap it (executors/trial_start.hpp, ChangeOfPusher);
//             another contact point is a move of the arm, no change
//     object  the object: shape, size, mass
//   key       a canonical text of the fixture's parameters ("line l=0.03 ..."):
//             two scenes need the same fixture iff their keys are equal
//   cost      seconds the cell spends on a change of that fixture (>= 0)
//
// A cell declares its costs in its announcement: CellAnnounce.backend_json
// gains the key kChangeCostsKey, {"finger_s": s, "pusher_s": s, "object_s": s}.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "arena/mechanics/scene.hpp"

namespace arena::schemas {

// The three fixtures a trial needs, as keys.
struct Fixtures {
  std::string finger;
  std::string pusher;
  std::string object;
  bool operator==(const Fixtures&) const = default;
};

Fixtures FixturesOf(const mechanics::Scene& scene);

// Seconds per change of each fixture (all >= 0 and finite).
struct ChangeCosts {
  double finger_s = 0;
  double pusher_s = 0;
  double object_s = 0;
};

// The key of a cell's costs in CellAnnounce.backend_json (and of an exec:
// driver's hello line).
inline constexpr const char* kChangeCostsKey = "fixture_changes";

// @returns "" or why the costs are unusable ("finger_s: must be finite and >= 0").
std::string CheckChangeCosts(const ChangeCosts& costs);

// One change: `what` is "finger", "pusher" or "object".
struct FixtureChange {
  std::string what;
  std::string from;
  std::string to;
  double seconds = 0;
};

// The changes from `mounted` to `next`, in the order finger, pusher,
// object; empty when nothing differs. `mounted` nullopt (a fresh cell, or
// one the service has not seen run yet): none -- a cell is set up for the
// first trial it runs, as before issue 29 (no change is charged for it).
std::vector<FixtureChange> ChangesBetween(const std::optional<Fixtures>& mounted,
                                          const Fixtures& next, const ChangeCosts& costs);
// The sum of their seconds.
double ChangeSeconds(const std::vector<FixtureChange>& changes);

}  // namespace arena::schemas
