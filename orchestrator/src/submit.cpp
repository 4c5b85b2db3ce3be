#include "arena/orchestrator/submit.hpp"

#include <algorithm>
#include <map>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/adaptive.hpp"
#include "arena/orchestrator/scene_facts.hpp"

namespace arena::orchestrator {

namespace {
std::vector<db::PlannedTrial> PlanChunk(const Campaign& campaign, std::int64_t begin,
                                        std::int64_t end) {
  std::vector<db::PlannedTrial> out;
  out.reserve(static_cast<size_t>(end - begin));
  for (std::int64_t i = begin; i < end; ++i) {
    const PlannedTrial t = PlanTrial(campaign, i);
    db::PlannedTrial p;
    p.condition = static_cast<int>(t.condition);
    p.replicate = t.replicate;
    p.seed = t.seed;
    p.scene_json = mechanics::SceneToJson(t.scene);
    p.facts = SceneFactsOf(t.scene);
    p.facts = SceneFactsOf(t.scene);
    p.params_json = t.parameters_json;
    p.defects_json = campaign.defects_json;
    out.push_back(std::move(p));
  }
  return out;
}

std::string SamplerState(const Campaign& campaign, std::int64_t next_index) {
  return nlohmann::json({{"sampler", ToString(campaign.sampler)},
                         {"next_index", next_index},
                         {"trials", TrialCount(campaign)}})
      .dump();
}
}  // namespace

std::int64_t SubmitCampaign(db::Store& store, const Campaign& given,
                            const std::function<bool()>& interrupted) {
  Campaign campaign = given;
  if (campaign.calibration_id > 0) {
    // prediction.calibration: ID -> the fitted scales, recorded in the stored
    // spec (prediction.calibrated) so the predictor needs no second lookup.
    const db::Calibration cal = store.GetCalibration(campaign.calibration_id);  // kNotFound
    if (!cal.applied) {
      throw db::StoreError(db::StoreError::Kind::kBadInput,
                           "prediction.calibration: calibration " + std::to_string(cal.id) +
                               " did not improve the held-out error and is not applied");
    }
    // Scales fitted for one predictor also absorb that predictor's own
    // errors: they are not moved to another.
    const nlohmann::json fit_settings = nlohmann::json::parse(cal.settings_json, nullptr, false);
    const std::string fitted_for = fit_settings.is_object() && fit_settings.contains("predictor") &&
                                           fit_settings["predictor"].is_string()
                                       ? fit_settings["predictor"].get<std::string>()
                                       : "arena";
    if (fitted_for != campaign.predictor) {
      throw db::StoreError(db::StoreError::Kind::kBadInput,
                           "prediction.calibration: calibration " + std::to_string(cal.id) +
                               " was fitted for the " + fitted_for +
                               " predictor; this campaign predicts with " + campaign.predictor);
    }
    nlohmann::json spec = nlohmann::json::parse(campaign.source_json);
    nlohmann::json scales = nlohmann::json::object();
    const nlohmann::json fitted = nlohmann::json::parse(cal.params_json);
    for (const auto& item : fitted.items())
      scales[item.key()] = item.value().at("scale").get<double>();
    spec["prediction"]["calibrated"] = scales;
    campaign.source_json = spec.dump();
    campaign.calibrated_scales = scales.get<std::map<std::string, double>>();
  }
  if (campaign.adaptive && !campaign.adaptive->pipeline_given) {
    // The default is stored with the campaign: the service reads it from
    // there on every restart, whatever a later binary's default is.
    nlohmann::json spec = nlohmann::json::parse(campaign.source_json);
    spec["sampler"]["pipeline"] = kPipelineDefault;
    campaign.source_json = spec.dump();
    campaign.adaptive->pipeline = kPipelineDefault;
    campaign.adaptive->pipeline_given = true;
  }
  if (campaign.adaptive) {
    // Round 0 (the coarse batch, or min_replicates of every condition) is
    // planned now; later rounds by the service's AdaptivePlanner.
    db::NewCampaign c;
    c.name = campaign.name;
    c.spec_json = campaign.source_json;
    c.priority = campaign.priority;
    c.seed = campaign.seed;
    c.sampler_open = true;
    // One transaction: a crash or an interrupt leaves nothing or both.
    return CreateAdaptiveCampaign(store, c, campaign, interrupted);
  }
  const std::int64_t total = TrialCount(campaign);
  db::NewCampaign c;
  c.name = campaign.name;
  c.spec_json = campaign.source_json;
  c.priority = campaign.priority;
  c.seed = campaign.seed;
  c.sampler_state_json = SamplerState(campaign, total);
  // One transaction: a crash, a full disk or an interrupt leaves nothing.
  std::int64_t next = 0;
  return store.CreateCampaign(c, [&]() -> std::vector<db::PlannedTrial> {
    if (interrupted && interrupted()) throw SubmitInterrupted();
    if (next >= total) return {};
    const std::int64_t end = std::min(total, next + kPlanChunk);
    auto chunk = PlanChunk(campaign, next, end);
    next = end;
    return chunk;
  });
}

}  // namespace arena::orchestrator
