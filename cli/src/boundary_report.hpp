// The boundary an adaptive boundary campaign found, stated in the units of
// its parameters with an interval (issue 26): where the outcome class
// changes between neighbouring classified trials. `arena status` and
// `arena query --decisions` print it.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "arena/db/store.hpp"

namespace arena::cli {

struct BoundaryCrossing {
  std::vector<double> at;    // midpoint, one value per sampled parameter (SI)
  std::vector<double> half;  // half the bracket along each (SI): the interval is at +- half
};

struct BoundaryStatement {
  std::string outcome;                      // e.g. "pivoted"
  std::string positive, negative;           // class names, e.g. "pivoted", "not pivoted"
  std::vector<std::string> parameters;      // the sampled parameters
  int classified = 0;                       // trials with a class
  std::vector<BoundaryCrossing> crossings;  // by the first parameter, then the others
};

// nullopt for a campaign that is not an adaptive boundary campaign.
std::optional<BoundaryStatement> FindBoundary(const db::Store& store, std::int64_t campaign_id);

// "boundary between pivoted and not pivoted (12 classified trials):\n
//   grip_force 2.25 +- 0.25 N at pivot_offset 10 +- 0.5 mm\n ..."
std::string FormatBoundary(const BoundaryStatement& b, const std::string& indent);

}  // namespace arena::cli
