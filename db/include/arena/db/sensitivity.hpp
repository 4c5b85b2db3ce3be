// Stored sensitivity runs (`arena sensitivity --db F --campaign ID`): per
// condition of a campaign, the spread the model predicts under the campaign's
// defect profile beside the spread its replicates showed, and whether the
// condition is unstable (docs/sensitivity.md). Tables sensitivity_runs and
// sensitivity_conditions (migration 8; db/README.md). A run never changes a
// trial, a prediction or a campaign.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "arena/db/store.hpp"

namespace arena::db {

// One condition's row. Spreads are RMS distances from the mean over the
// members (m for displacement vectors, rad for rotation vectors); absent
// when there were fewer than two members.
struct SensitivityCondition {
  int condition = 0;
  std::string params_json = "{}";  // the sampler's values for the condition
  int replicates = 0;              // trials with published ground truth
  int ensemble = 0;                // model runs of the ensemble that succeeded
  int ensemble_failed = 0;
  std::optional<double> predicted_position_spread;  // m
  std::optional<double> observed_position_spread;   // m
  std::optional<double> predicted_rotation_spread;  // rad
  std::optional<double> observed_rotation_spread;   // rad
  std::optional<double> predicted_displacement;     // m, the nominal model run
  std::optional<double> observed_displacement;      // m, mean over replicates
  std::optional<double> predicted_rotation;         // rad, nominal run's net rotation
  std::optional<double> observed_rotation;          // rad, mean over replicates
  std::string verdict;  // matches, model_underestimates, model_overestimates, too_few_replicates,
                        // no_prediction
  double flip_fraction = 0;  // ensemble members whose contact modes / grasp differ from nominal
  bool unstable = false;
  std::string boundary_parameter;             // nearest boundary found ("" none)
  std::optional<double> boundary_offset;      // signed, the parameter's unit
  std::optional<double> boundary_tolerances;  // |offset| / tolerance
  std::string reason;                         // why unstable (first reason), or ""
  std::string detail_json = "{}";             // the full per-condition analysis
};

struct SensitivityRun {
  std::int64_t id = 0;
  std::int64_t campaign_id = 0;
  double created_at = 0;
  std::string settings_json = "{}";  // ensemble size, seed, tolerances, simulator
  std::string report_json = "{}";    // campaign-level summary
};

// Stores the run and its rows in one transaction; @returns the run id.
// @throws StoreError kNotFound (campaign), kBadInput (a NaN or infinite
//   number, a repeated condition, a bad JSON text), kReadOnly.
std::int64_t RecordSensitivityRun(Store& store, std::int64_t campaign_id,
                                  const std::string& settings_json, const std::string& report_json,
                                  const std::vector<SensitivityCondition>& conditions);
// Oldest first.
std::vector<SensitivityRun> ListSensitivityRuns(const Store& store, std::int64_t campaign_id);
// By condition. @throws kNotFound for an unknown run.
std::vector<SensitivityCondition> ListSensitivityConditions(const Store& store,
                                                            std::int64_t run_id);

// The defect profile each trial of the campaign really ran under, by trial
// id: the effective profile the cell recorded with its execution
// (trials.defects_applied "effective": the cell's and the campaign's
// combined, schema version 10), else the cell's announced profile recorded
// at dispatch (trials.cell_defects_json; cells that applied only their own).
// The recorded profile carries "emulated" (false: the backend did not emulate
// defects, a robot or recorded data). Trials with neither are absent.
std::map<std::int64_t, std::string> AppliedDefectProfiles(const Store& store,
                                                          std::int64_t campaign_id);

// Writes <dir>/sensitivity.csv (one row per condition of the campaign's
// latest run; header only when there is none) for `arena export`; @returns
// its path relative to dir, "" when the campaign has no run.
std::string WriteSensitivityExport(const Store& store, std::int64_t campaign_id,
                                   const std::string& dir);

}  // namespace arena::db
