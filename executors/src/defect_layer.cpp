#include "arena/executors/defect_layer.hpp"

#include <cmath>

#include <nlohmann/json.hpp>

#include "defects_json.hpp"

namespace arena::executors {
namespace {

double Rss(double a, double b) { return std::sqrt(a * a + b * b); }
Eigen::Vector3d Rss(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return (a.array().square() + b.array().square()).sqrt().matrix();
}

}  // namespace

DefectProfile WithBackendWorkspace(DefectProfile cell, const BackendCapabilities& caps) {
  const DefectProfile defaults;
  if (caps.workspace && cell.workspace_min == defaults.workspace_min &&
      cell.workspace_max == defaults.workspace_max) {
    cell.workspace_min = caps.workspace->first;
    cell.workspace_max = caps.workspace->second;
  }
  return cell;
}

DefectProfile CombineProfiles(const DefectProfile& cell, const DefectProfile& campaign) {
  DefectProfile p = cell;  // limits, reset and fault injection: the cell's
  p.position_std = Rss(cell.position_std, campaign.position_std);
  p.rotation_std = Rss(cell.rotation_std, campaign.rotation_std);
  p.force_std = Rss(cell.force_std, campaign.force_std);
  p.torque_std = Rss(cell.torque_std, campaign.torque_std);
  p.velocity_scale_std = Rss(cell.velocity_scale_std, campaign.velocity_scale_std);
  p.velocity_offset_std = Rss(cell.velocity_offset_std, campaign.velocity_offset_std);
  p.mu_scale_std = Rss(cell.mu_scale_std, campaign.mu_scale_std);
  p.latency_ms = cell.latency_ms + campaign.latency_ms;
  p.drop_probability = 1 - (1 - cell.drop_probability) * (1 - campaign.drop_probability);
  return p;
}

bool PerturbsPhysics(const DefectProfile& p) {
  return p.velocity_scale_std > 0 || (p.velocity_offset_std.array() > 0).any() ||
         p.mu_scale_std > 0;
}

DefectLayer::DefectLayer(std::unique_ptr<Backend> inner, DefectProfile cell_profile)
    : inner_(std::move(inner)), caps_(inner_->Capabilities()), cell_(std::move(cell_profile)) {
  if (!caps_.emulates_defects && PerturbsPhysics(cell_)) {
    throw std::invalid_argument("--defects: the " + caps_.name +
                                " backend's physics cannot be perturbed (it is not simulated); "
                                "remove friction_variability and actuation noise from the cell's "
                                "profile");
  }
  effective_ = cell_;
}

std::string DefectLayer::Prepare(const mechanics::Scene& scene,
                                 std::string_view campaign_defects_json,
                                 const TrialContext& trial) {
  if (campaign_defects_json != profiles_key_) {
    profiles_key_ = campaign_defects_json;
    applied_profiles_text_.clear();
  }
  campaign_.reset();
  effective_ = cell_;
  if (!campaign_defects_json.empty() && campaign_defects_json != "{}") {
    try {
      campaign_ = ParseDefectProfile(campaign_defects_json);
    } catch (const DefectError& e) {
      return std::string("defects_json: ") + e.what();
    }
    if (!caps_.emulates_defects && PerturbsPhysics(*campaign_)) {
      return "defects: the campaign perturbs the physics (friction_variability or actuation "
             "noise), and the " +
             caps_.name + " backend cannot (" + ToString(caps_.truth) +
             " truth is not simulated); run it on a simulated cell or without those defects";
    }
    effective_ = CombineProfiles(cell_, *campaign_);
  }
  if (std::string why = CheckCapabilities(effective_, scene); !why.empty()) return why;
  if (!caps_.contact_types.empty()) {
    auto has = [&](mechanics::ContactType t) {
      for (auto c : caps_.contact_types)
        if (c == t) return true;
      return false;
    };
    for (size_t i = 0; i < scene.fingers.size(); ++i) {
      if (!has(scene.fingers[i].type))
        return "fingers[" + std::to_string(i) + "].type: the " + caps_.name + " backend has no " +
               mechanics::ToString(scene.fingers[i].type) + " contacts";
    }
  }
  return inner_->Prepare(scene, trial);
}

ExecuteOutcome DefectLayer::Execute(const mechanics::Scene& scene, const TrialContext& trial,
                                    const SampleSink& sink) {
  perturbation_ = caps_.emulates_defects ? DrawPerturbation(effective_, trial.seed, trial.trial_id)
                                         : TrialPerturbation{};
  actual_ = caps_.emulates_defects ? ApplyPerturbation(scene, perturbation_) : scene;
  return inner_->Execute(actual_, trial, sink);
}

mechanics::SimulationResult DefectLayer::ExecuteClosedLoop(
    const mechanics::Scene& scene, const TrialContext& trial,
    const mechanics::PusherCommandSource& commands) {
  perturbation_ = caps_.emulates_defects ? DrawPerturbation(effective_, trial.seed, trial.trial_id)
                                         : TrialPerturbation{};
  actual_ = caps_.emulates_defects ? ApplyPerturbation(scene, perturbation_) : scene;
  if (actual_.pusher) actual_.pusher->motion = mechanics::PusherMotion{};  // until the first answer
  return inner_->SimulateClosedLoop(actual_, commands);
}

std::vector<dds::Observation> DefectLayer::Observe(
    const std::vector<mechanics::TrajectorySample>& truth, const TrialContext& trial) const {
  // Sensing defects (noise, latency, drops) are computed from the truth, so
  // they apply to every backend's stream.
  return executors::Observe(truth, actual_, effective_, trial.seed, trial.trial_id);
}

Observer DefectLayer::MakeObserver(const TrialContext& trial) const {
  return Observer(actual_, effective_, trial.seed, trial.trial_id);
}

std::string DefectLayer::AppliedJson() const { return internal::AppliedDefectsTree(*this).dump(); }

const std::string& DefectLayer::AppliedProfilesText() const {
  if (applied_profiles_text_.empty()) {
    nlohmann::json tree = internal::AppliedDefectsTree(*this);
    tree.erase("perturbation");
    applied_profiles_text_ = tree.dump();
    applied_profiles_text_.pop_back();  // the closing brace: the perturbation follows
  }
  return applied_profiles_text_;
}

namespace internal {

std::string AppliedDefectsText(const DefectLayer& layer) {
  const TrialPerturbation& p = layer.perturbation();
  // "perturbation" sorts after every other key: this is the tree's own dump.
  return layer.AppliedProfilesText() + ",\"perturbation\":" +
         nlohmann::json({{"mu_scale", p.mu_scale},
                         {"velocity_scale", p.velocity_scale},
                         {"velocity_offset",
                          {p.velocity_offset.x(), p.velocity_offset.y(), p.velocity_offset.z()}}})
             .dump() +
         "}";
}

nlohmann::json AppliedDefectsTree(const DefectLayer& layer) {
  using nlohmann::json;
  const TrialPerturbation& perturbation = layer.perturbation();
  const auto& campaign = layer.campaign_profile();
  return json({{"emulated", layer.capabilities().emulates_defects},
               {"cell", DefectProfileTree(layer.cell_profile())},
               {"campaign", campaign ? DefectProfileTree(*campaign) : json(nullptr)},
               {"effective", DefectProfileTree(layer.effective_profile())},
               {"perturbation",
                {{"mu_scale", perturbation.mu_scale},
                 {"velocity_scale", perturbation.velocity_scale},
                 {"velocity_offset",
                  {perturbation.velocity_offset.x(), perturbation.velocity_offset.y(),
                   perturbation.velocity_offset.z()}}}}});
}

}  // namespace internal

}  // namespace arena::executors
