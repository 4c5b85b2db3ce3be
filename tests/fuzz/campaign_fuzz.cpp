// libFuzzer target for the campaign reader (scripts/fuzz.sh builds and runs it).
// Oracle: ParseCampaign either returns a campaign or throws CampaignError; an
// accepted campaign plans trials whose scenes pass ValidateScene.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/campaign.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace arena;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  orchestrator::Campaign campaign;
  try {
    // No files: a path in "scene" or "defects" must fail cleanly.
    campaign = orchestrator::ParseCampaign(text, "/nonexistent-arena-fuzz-dir");
  } catch (const orchestrator::CampaignError&) {
    return 0;
  }
  const int64_t n = orchestrator::TrialCount(campaign);
  for (int64_t i = 0; i < n && i < 8; ++i) {
    try {
      mechanics::ValidateScene(orchestrator::PlanTrial(campaign, i).scene);
    } catch (const mechanics::SceneError&) {
      std::abort();  // an accepted campaign planned an invalid scene
    }
  }
  return 0;
}
