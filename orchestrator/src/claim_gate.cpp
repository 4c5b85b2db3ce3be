// The claim gate's rule (claim_gate.hpp).
#include "arena/orchestrator/claim_gate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <nlohmann/json.hpp>

namespace arena::orchestrator {

namespace {

constexpr int kPointBit = 1, kLineBit = 2, kPatchBit = 4;  // db's contact_mask bits

std::string MaskNames(int mask) {
  std::string out;
  for (auto [bit, name] : {std::pair{kPointBit, "point"}, std::pair{kLineBit, "line"},
                           std::pair{kPatchBit, "patch"}}) {
    if ((mask & bit) == 0) continue;
    if (!out.empty()) out += ", ";
    out += name;
  }
  return out.empty() ? "none" : out;
}

std::string Vec(const std::array<double, 3>& v) {
  return fmt::format("[{:.3g}, {:.3g}, {:.3g}]", v[0], v[1], v[2]);
}

std::string Join(const std::vector<std::string>& parts) {
  std::string out;
  for (const auto& p : parts) out += (out.empty() ? "" : ", ") + p;
  return out;
}

// "cells a, b: replay backend" / "cell a: model backend" / "cells a, b: model, replay backends"
std::string CellList(const std::vector<const HostCell*>& cells) {
  std::vector<std::string> ids, backends;
  for (const HostCell* c : cells) {
    ids.push_back(c->id);
    if (std::find(backends.begin(), backends.end(), c->backend) == backends.end())
      backends.push_back(c->backend);
  }
  return fmt::format("{} {}: {} backend{}", ids.size() == 1 ? "cell" : "cells", Join(ids),
                     Join(backends), backends.size() == 1 ? "" : "s");
}

}  // namespace

std::string_view ToString(WaitKind kind) {
  switch (kind) {
    case WaitKind::kDefects:
      return "defects";
    case WaitKind::kContactTypes:
      return "contact_types";
    case WaitKind::kWorkspace:
      return "workspace";
    case WaitKind::kPusherSpeed:
      return "pusher_speed";
  }
  return "?";
}

std::vector<std::string> PhysicsDefects(std::string_view defects_json) {
  std::vector<std::string> out;
  if (defects_json.empty()) return out;
  const auto j = nlohmann::json::parse(defects_json, nullptr, false);
  if (!j.is_object()) return out;
  auto positive = [](const nlohmann::json& v) {
    if (v.is_number()) return v.get<double>() > 0;
    if (v.is_array()) {
      for (const auto& x : v)
        if (x.is_number() && x.get<double>() > 0) return true;
    }
    return false;
  };
  // The fields executors' PerturbsPhysics reads (the profile's JSON names).
  const std::pair<const char*, const char*> fields[] = {{"friction_variability", "mu_scale_std"},
                                                        {"actuation_noise", "velocity_scale_std"},
                                                        {"actuation_noise", "velocity_offset_std"}};
  for (const auto& [block, field] : fields) {
    if (j.contains(block) && j[block].is_object() && j[block].contains(field) &&
        positive(j[block][field]))
      out.push_back(std::string(block) + "." + field);
  }
  return out;
}

std::optional<CannotHost> WhyCellCannotHost(const HostCell& cell, const TrialNeed& trial,
                                            const std::vector<std::string>& physics_defects) {
  if (!physics_defects.empty() && !cell.emulates_defects)
    return CannotHost{WaitKind::kDefects, "emulate defect " + Join(physics_defects)};
  if ((trial.contact_mask & ~cell.contact_mask) != 0)
    return CannotHost{WaitKind::kContactTypes,
                      "offer " + MaskNames(trial.contact_mask & ~cell.contact_mask) +
                          " contacts (it offers " + MaskNames(cell.contact_mask) + ")"};
  for (int k = 0; k < 3; ++k) {
    if (trial.position[k] < cell.workspace_min[k] || trial.position[k] > cell.workspace_max[k])
      return CannotHost{WaitKind::kWorkspace, "place the object at " + Vec(trial.position) +
                                                  " m (workspace " + Vec(cell.workspace_min) +
                                                  ".." + Vec(cell.workspace_max) + " m)"};
  }
  if (trial.pusher_speed > cell.max_pusher_speed)
    return CannotHost{WaitKind::kPusherSpeed,
                      fmt::format("push at {:.3g} m/s (pusher limit {:.3g} m/s)",
                                  trial.pusher_speed, cell.max_pusher_speed)};
  return std::nullopt;
}

GateDecision DecideClaimGate(const CampaignNeeds& campaign, const std::vector<HostCell>& live) {
  GateDecision d;
  if (live.empty()) {
    d.rule = "claim_gate.no_cells";
    return d;
  }
  if (campaign.trials.empty()) return d;
  // Each cell's reason: its first trial's (it can host none, or the gate is open).
  std::map<std::string, std::vector<const HostCell*>> by_reason;  // ordered: a stable text
  std::map<WaitKind, int> kinds;
  std::vector<std::pair<WaitKind, std::string>> order;
  for (const HostCell& cell : live) {
    std::optional<CannotHost> first;
    bool hosts_one = false;
    for (const TrialNeed& t : campaign.trials) {
      auto why = WhyCellCannotHost(cell, t, campaign.physics_defects);
      if (!why) {
        hosts_one = true;
        break;
      }
      if (!first) first = std::move(why);
    }
    if (hosts_one) return d;  // open: this cell can run some of it
    auto& group = by_reason[first->reason];
    if (group.empty()) order.emplace_back(first->kind, first->reason);
    group.push_back(&cell);
    ++kinds[first->kind];
  }
  d.waits = true;
  d.rule = "claim_gate.waits";
  int most = 0;
  for (const auto& [kind, n] : kinds) {
    if (n > most) {
      most = n;
      d.kind = kind;
    }
  }
  std::string text;
  for (const auto& [kind, reason] : order)
    text += (text.empty() ? "" : "; ") + reason + " (" + CellList(by_reason[reason]) + ")";
  d.reason = (order.size() == 1 ? "no live cell can " : "no live cell can host it: ") + text;
  if (order.size() > 1) {
    // "no live cell can host it: emulate defect X (cell a: ...); push at ... (cell b: ...)"
    // reads badly with a bare verb: say who cannot.
    text.clear();
    for (const auto& [kind, reason] : order)
      text += (text.empty() ? "" : "; ") + CellList(by_reason[reason]) + " cannot " + reason;
    d.reason = "no live cell can host it: " + text;
  }
  return d;
}

}  // namespace arena::orchestrator
