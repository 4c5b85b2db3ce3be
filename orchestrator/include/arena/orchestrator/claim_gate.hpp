// The claim gate (issue 26): whether `arena serve` may dispatch a campaign's
// trials at all, given the cells alive now. A campaign that no live cell can
// host (defects a backend cannot emulate, a push outside every workspace, a
// speed above every pusher limit, contact types no cell offers) is not
// dispatched: run to the cells, every trial would fail. Its trials wait with
// a typed, stored reason (db campaign_waits, `arena status`), and dispatch
// resumes when a cell that can host it announces.
//
// The rule is a pure function of typed inputs, like trial_policy.hpp; its
// table test is tests/orchestrator/claim_gate_test.cpp.
//
//   live cells   some cell can host some planned trial   decision
//   none         -                                       open   (claim_gate.no_cells: nothing
//                                                                 to dispatch to, nothing to say)
//   >= 1         yes                                     open   (claim_gate.open)
//   >= 1         no                                      waits  (claim_gate.waits), the kind:
//                                                                 the reason most cells gave
//
// A cell can host a trial when (the cell's own checks, executors'
// CheckCapabilities, on what the store keeps of the trial):
//   - the campaign perturbs no physics, or the cell's backend emulates defects;
//   - the cell offers every contact type of the trial's fingers and pusher;
//   - the trial's planned object position lies in the cell's workspace;
//   - the trial's pusher speed is at most the cell's limit.
// The gate is a first sieve, not the cells' full check: a pusher's travel
// out of the workspace or a path pusher's peak speed are still refused by
// the cell, trial by trial.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace arena::orchestrator {

// What a cell announced it can do (msg::CellAnnounce).
struct HostCell {
  std::string id;
  std::string backend;                    // "model", "mujoco", "replay:...", "exec:..."
  bool emulates_defects = true;           // can perturb the physics (friction, actuation)
  int contact_mask = 0;                   // db's bits: point 1, line 2, patch 4
  std::array<double, 3> workspace_min{};  // object position limits, gripper frame (m)
  std::array<double, 3> workspace_max{};
  double max_pusher_speed = 0;  // m/s
};

// What the store keeps of one planned trial (or of many alike).
struct TrialNeed {
  int contact_mask = 0;
  std::array<double, 3> position{};  // planned object position, gripper frame (m)
  double pusher_speed = 0;           // m/s (pusher.motion.velocity's norm)
};

// A campaign's planned trials, and the physics defects its profile applies
// (their field names; empty: none).
struct CampaignNeeds {
  std::int64_t campaign_id = 0;
  std::vector<std::string> physics_defects;
  std::vector<TrialNeed> trials;
};

// Why a campaign waits.
enum class WaitKind { kDefects, kContactTypes, kWorkspace, kPusherSpeed };
std::string_view ToString(
    WaitKind kind);  // "defects", "contact_types", "workspace", "pusher_speed"

struct GateDecision {
  bool waits = false;
  WaitKind kind = WaitKind::kDefects;
  std::string reason;  // e.g. "no live cell can emulate defect friction_variability.mu_scale_std
                       //       (cells a, b: replay backend)"
  const char* rule = "claim_gate.open";
};

// The physics defects a campaign's defect profile (JSON, "" = none) applies,
// by field name (friction_variability.mu_scale_std, actuation_noise.*):
// the fields executors' PerturbsPhysics reads. A profile that does not parse
// names none (the submit checks it; the cell refuses it with the reason).
std::vector<std::string> PhysicsDefects(std::string_view defects_json);

// Why `cell` cannot host `trial` of a campaign with `physics_defects`, with
// its reason; nullopt when it can.
struct CannotHost {
  WaitKind kind;
  std::string reason;  // without the cell's name, e.g. "pusher speed 0.5 m/s above its 0.1 m/s"
};
std::optional<CannotHost> WhyCellCannotHost(const HostCell& cell, const TrialNeed& trial,
                                            const std::vector<std::string>& physics_defects);

// The gate for one campaign (see the table above). A campaign with no
// planned trial is open (nothing to dispatch).
GateDecision DecideClaimGate(const CampaignNeeds& campaign, const std::vector<HostCell>& live);

}  // namespace arena::orchestrator
