// The campaign view of reliability (`arena sensitivity --db F --campaign ID`):
// per condition (its replicates share one scene), the spread of the outcome
// the model predicts under the campaign's defect profile -- an ensemble of N
// model runs, each with friction, pusher velocity and the start pose the
// cell's reset leaves drawn as the cell draws them (noise.hpp), seeded --
// beside the spread the replicates' ground truth
// showed, and the condition's stability (sensitivity.hpp) with the cell's
// noise levels as tolerances.
//
// Whose profile: the one each replicate really ran under -- the effective
// profile its cell recorded (the cell's own and the campaign's combined,
// trials.defects_applied), or for older stores the cell's announced profile;
// ensemble member k draws from replicate k mod n's. Only when no trial of
// the condition ran is the campaign's stored profile used.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "arena/assessment/sensitivity.hpp"
#include "arena/db/sensitivity.hpp"
#include "arena/db/store.hpp"

namespace arena::assessment {

struct CampaignSensitivityOptions {
  int ensemble = 32;       // model runs per condition, [2, 10000]
  std::uint64_t seed = 1;  // the ensemble's random streams derive from (seed, condition)
  int threads = 0;         // conditions run in parallel; 0: one per core
  bool check_stability = true;
  // Draw the start pose each replicate began from (the reset's placement
  // accuracy in the profiles the trials ran under); false leaves it nominal,
  // to tell its share of the spread.
  bool draw_start_pose = true;
  // Tolerances beyond the cell's noise (relative_tolerance 0: only the noise).
  StabilityOptions stability = [] {
    StabilityOptions s;
    s.relative_tolerance = 0;
    return s;
  }();
  std::vector<std::string> params;  // extra parameters to probe (filters); noise ones always
  // Floors under which a spread counts as zero: 1 um, 10 urad.
  double position_floor = 1e-6;
  double rotation_floor = 1e-5;
  // Model settings for every run instead of the campaign's "prediction"
  // ones (0: keep), e.g. a cell's own fidelity, to tell the noise's share of
  // the spread from the model settings'.
  int facets = 0, points = 0;
  double dt = 0;
  SimulateFn simulate;                       // empty: DefaultSimulate()
  std::string simulator_name = "arena";      // recorded in the run's settings
  std::function<void(long, long)> progress;  // (conditions done, total), from worker threads
  const std::atomic<bool>* cancel = nullptr;
};

struct CampaignSensitivityReport {
  std::int64_t campaign_id = 0;
  std::vector<db::SensitivityCondition> conditions;
  int matches = 0, underestimates = 0, overestimates = 0, too_few = 0, no_prediction = 0;
  int unstable = 0;
  // Pooled over conditions with a predicted spread: sqrt(sum (n-1) r^2 / sum (n-1)).
  std::optional<double> pooled_position_ratio, pooled_rotation_ratio;
  std::string pooled_position_verdict, pooled_rotation_verdict;
  long model_runs = 0;
  double wall_s = 0;
  int threads = 1;
  bool cancelled = false;
};

// The verdict of an observed spread against a predicted one (see above).
std::string SpreadVerdict(std::optional<double> observed, std::optional<double> predicted,
                          int replicates, double floor);
// Central 95 % interval of chi^2(dof) (table to 10, Wilson-Hilferty above).
std::pair<double, double> ChiSquare95(int dof);
// RMS distance from the mean (n - 1 denominator); nullopt for < 2 points.
std::optional<double> Spread(const std::vector<Eigen::Vector3d>& points);

// Reads the campaign's trials and ground truth from `store` (in the calling
// thread), runs the analysis on worker threads. Trials without published
// ground truth are left out of the observed spread.
// @throws db::StoreError (unknown campaign, store failure); NoiseError for a
//   trial's unreadable defect profile; std::invalid_argument for bad options.
CampaignSensitivityReport AnalyseCampaign(const db::Store& store, std::int64_t campaign_id,
                                          const CampaignSensitivityOptions& options);

nlohmann::json SettingsJson(const CampaignSensitivityOptions& options);
nlohmann::json SummaryJson(const CampaignSensitivityReport& report);

}  // namespace arena::assessment
