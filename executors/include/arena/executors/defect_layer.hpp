// The defect layer: defect emulation wrapped around any backend.
//
// For a trial it combines the cell's own profile with the campaign's (sent
// in TrialCommand.defects_json; CombineProfiles says how), checks the
// combined limits (workspace, contact types, pusher speed), perturbs the
// scene the backend runs (friction, pusher velocity) and, once the backend
// has streamed the truth, emulates what the sensors saw (noise, latency,
// drops). Sensing defects are computed from the truth, so they apply on every
// backend. On a backend whose physics cannot be perturbed (a robot, recorded
// data: BackendCapabilities::emulates_defects false) a profile with friction
// variability or actuation noise is refused with the reason: a defect is
// applied or refused, never silently dropped.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "arena/executors/backend.hpp"
#include "arena/executors/defects.hpp"
#include "arena/schemas/ground_truth.hpp"

namespace arena::executors {

// The profile a trial runs with: the cell's own (its hardware: limits,
// reset, and whatever defects the lab wants the cell to emulate) and the
// campaign's. Independent sources combine as such:
//   noise standard deviations (pose, rotation, force, torque, actuation,
//     friction variability): root sum of squares;
//   latency: the sum; drop probability: 1 - (1 - a)(1 - b);
//   limits (workspace, pusher speed, contact types): the cell's (a campaign
//     cannot widen hardware; its own limits are ignored);
//   reset parameters and fault injection: the cell's.
DefectProfile CombineProfiles(const DefectProfile& cell, const DefectProfile& campaign);

// The cell's profile with the backend's own workspace (a recording's extent,
// BackendCapabilities::workspace) when the profile leaves the workspace at
// its default; a profile that sets one keeps it. The cell and `arena run`'s
// check before submitting both apply this one rule.
DefectProfile WithBackendWorkspace(DefectProfile cell, const BackendCapabilities& caps);

// True when the profile perturbs the physics (friction variability,
// actuation noise): only a simulated backend can apply that.
bool PerturbsPhysics(const DefectProfile& profile);

class DefectLayer {
 public:
  DefectLayer(std::unique_ptr<Backend> inner, DefectProfile cell_profile);
  const Backend& inner() const { return *inner_; }
  Backend& inner() { return *inner_; }
  const BackendCapabilities& capabilities() const { return caps_; }
  // The inner backend's word on the prepared trial's truth (Backend::PreparedTruth).
  TrialTruth PreparedTruth() const { return inner_->PreparedTruth(); }
  const DefectProfile& cell_profile() const { return cell_; }
  // The prepared trial's campaign profile (none: the campaign sets none) and
  // the combination it runs with.
  const std::optional<DefectProfile>& campaign_profile() const { return campaign_; }
  const DefectProfile& effective_profile() const { return effective_; }

  // Sets the trial's campaign profile ("" or "{}" = none) and checks the
  // scene against the combined limits and the backend. "" = can run it.
  std::string Prepare(const mechanics::Scene& scene, std::string_view campaign_defects_json,
                      const TrialContext& trial);
  // Runs the perturbed scene on the backend.
  ExecuteOutcome Execute(const mechanics::Scene& scene, const TrialContext& trial,
                         const SampleSink& sink);
  // Closed loop (issue 19): perturbs the scene as Execute does (friction; the
  // actuation noise the cell applies to every command is perturbation()), puts
  // its pusher at rest until the first command and runs it on the backend's
  // SimulateClosedLoop. Only for a backend whose capabilities say closed_loop.
  mechanics::SimulationResult ExecuteClosedLoop(const mechanics::Scene& scene,
                                                const TrialContext& trial,
                                                const mechanics::PusherCommandSource& commands);
  // The sensors of this trial (after Execute perturbed the scene), sample by
  // sample as the backend streams them: the same observations as Observe.
  Observer MakeObserver(const TrialContext& trial) const;
  // What the sensors saw of the truth the backend streamed.
  std::vector<dds::Observation> Observe(const std::vector<mechanics::TrajectorySample>& truth,
                                        const TrialContext& trial) const;
  // The scene as really run (after Execute) and what was applied, as JSON:
  // {"emulated": bool, "cell": {...}, "campaign": {...}|null, "effective": {...},
  //  "perturbation": {"mu_scale", "velocity_scale", "velocity_offset"}}
  const mechanics::Scene& actual_scene() const { return actual_; }
  const TrialPerturbation& perturbation() const { return perturbation_; }
  std::string AppliedJson() const;
  // AppliedJson's text without its "perturbation" and closing brace, built
  // once per campaign profile (Prepare keeps it while the profile text is
  // the same): the trees were most of a cell's time from its last sample to
  // its status (issue 27).
  const std::string& AppliedProfilesText() const;

 private:
  std::unique_ptr<Backend> inner_;
  BackendCapabilities caps_;
  DefectProfile cell_;
  std::optional<DefectProfile> campaign_;
  DefectProfile effective_;
  TrialPerturbation perturbation_;
  mechanics::Scene actual_;
  std::string profiles_key_;                   // the campaign profile text the cache is of
  mutable std::string applied_profiles_text_;  // "" = not built for it yet
};

}  // namespace arena::executors
