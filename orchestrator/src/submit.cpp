#include "arena/orchestrator/submit.hpp"

#include <algorithm>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/mechanics/scene_json.hpp"

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

std::int64_t SubmitCampaign(db::Store& store, const Campaign& campaign,
                            const std::function<bool()>& interrupted) {
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
