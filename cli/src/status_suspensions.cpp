#include "status_suspensions.hpp"

#include <cstdio>

#include "progress.hpp"

namespace arena::cli {

namespace {
std::string Where(const db::Suspension& s) {
  if (s.scope == "cell") return "cell " + s.cell_id;
  if (s.scope == "campaign") return "campaign " + std::to_string(s.campaign_id);
  return "every campaign";
}
}  // namespace

std::string FormatSuspensions(const std::vector<db::Suspension>& all, double now,
                              std::size_t recent_lifted) {
  std::string out;
  for (const auto& s : all) {
    if (s.lifted_at) continue;
    if (out.empty())
      out = "\nsuspended (dispatch held back; `arena resume CAMPAIGN [--cell C]`):\n";
    out += "  " + Where(s) + ": " + s.condition + " since " + IsoTime(s.fired_at) + " (" +
           FormatDuration(now - s.fired_at) + "): " + s.evidence + "\n";
  }
  std::size_t shown = 0;
  for (const auto& s : all) {
    if (!s.lifted_at || shown >= recent_lifted) continue;
    if (shown++ == 0) out += "\nlast suspensions lifted:\n";
    out += "  " + Where(s) + ": " + s.condition + " " + IsoTime(s.fired_at) + " .. " +
           IsoTime(*s.lifted_at) + " by " + s.lifted_by + ": " + s.evidence + "\n";
  }
  return out;
}

nlohmann::json SuspensionsJson(const std::vector<db::Suspension>& all) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& s : all) {
    nlohmann::json j = {{"id", s.id},
                        {"condition", s.condition},
                        {"scope", s.scope},
                        {"rule", s.rule},
                        {"evidence", s.evidence},
                        {"fired", IsoTime(s.fired_at)},
                        {"active", !s.lifted_at.has_value()}};
    if (s.scope == "campaign") j["campaign"] = s.campaign_id;
    if (s.scope == "cell") j["cell"] = s.cell_id;
    if (s.lifted_at) {
      j["lifted"] = IsoTime(*s.lifted_at);
      j["lifted_by"] = s.lifted_by;
    }
    out.push_back(std::move(j));
  }
  return out;
}

}  // namespace arena::cli
