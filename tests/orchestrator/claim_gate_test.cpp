// The claim gate (claim_gate.hpp) as one table: which campaign waits, why,
// and the reason an operator reads. Pins issue 26's "refused at claim":
// before the gate, `arena serve` dispatched a campaign no live cell could
// host and ran it to 100 % failure.
#include "arena/orchestrator/claim_gate.hpp"

#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace arena::orchestrator {
namespace {

HostCell Cell(std::string id, std::string backend, bool emulates, int mask = 7,
              double max_speed = 0.5) {
  HostCell c;
  c.id = std::move(id);
  c.backend = std::move(backend);
  c.emulates_defects = emulates;
  c.contact_mask = mask;
  c.workspace_min = {-0.1, -0.1, -0.1};
  c.workspace_max = {0.1, 0.1, 0.1};
  c.max_pusher_speed = max_speed;
  return c;
}

TrialNeed Trial(double x = 0, double speed = 0.01, int mask = 1) {
  TrialNeed t;
  t.contact_mask = mask;
  t.position = {x, 0, 0};
  t.pusher_speed = speed;
  return t;
}

struct Row {
  const char* name;
  std::vector<std::string> physics;
  std::vector<TrialNeed> trials;
  std::vector<HostCell> live;
  bool waits;
  WaitKind kind;
  const char* rule;
  const char* reason;  // the exact text (empty: not checked, the gate is open)
};

TEST(ClaimGate, Table) {
  const std::vector<std::string> friction = {"friction_variability.mu_scale_std"};
  const std::vector<Row> rows = {
      {"no live cell: nothing to dispatch to",
       friction,
       {Trial()},
       {},
       false,
       WaitKind::kDefects,
       "claim_gate.no_cells",
       ""},
      {"no planned trial",
       friction,
       {},
       {Cell("a", "replay:r", false)},
       false,
       WaitKind::kDefects,
       "claim_gate.open",
       ""},
      {"a simulated cell emulates the defect",
       friction,
       {Trial()},
       {Cell("a", "replay:r", false), Cell("m", "model", true)},
       false,
       WaitKind::kDefects,
       "claim_gate.open",
       ""},
      {"replay cells cannot emulate friction variability",
       friction,
       {Trial()},
       {Cell("a", "replay:r", false), Cell("b", "replay:r", false)},
       true,
       WaitKind::kDefects,
       "claim_gate.waits",
       "no live cell can emulate defect friction_variability.mu_scale_std (cells a, b: replay:r "
       "backend)"},
      {"no defects: replay hosts it",
       {},
       {Trial()},
       {Cell("a", "replay:r", false)},
       false,
       WaitKind::kDefects,
       "claim_gate.open",
       ""},
      {"every push is above the pusher limit",
       {},
       {Trial(0, 0.8), Trial(0, 0.9)},
       {Cell("a", "model", true, 7, 0.5)},
       true,
       WaitKind::kPusherSpeed,
       "claim_gate.waits",
       "no live cell can push at 0.8 m/s (pusher limit 0.5 m/s) (cell a: model backend)"},
      {"one push within the limit opens the campaign",
       {},
       {Trial(0, 0.8), Trial(0, 0.1)},
       {Cell("a", "model", true, 7, 0.5)},
       false,
       WaitKind::kDefects,
       "claim_gate.open",
       ""},
      {"outside every workspace",
       {},
       {Trial(0.3)},
       {Cell("a", "model", true)},
       true,
       WaitKind::kWorkspace,
       "claim_gate.waits",
       "no live cell can place the object at [0.3, 0, 0] m (workspace [-0.1, -0.1, -0.1]..[0.1, "
       "0.1, 0.1] m) (cell a: model backend)"},
      {"no cell offers line contacts",
       {},
       {Trial(0, 0.01, 2)},
       {Cell("a", "model", true, 1)},
       true,
       WaitKind::kContactTypes,
       "claim_gate.waits",
       "no live cell can offer line contacts (it offers point) (cell a: model backend)"},
      {"cells fail for different reasons: the most common kind, each said",
       friction,
       {Trial(0, 0.8)},
       {Cell("a", "replay:r", false), Cell("b", "replay:r", false),
        Cell("m", "model", true, 7, 0.5)},
       true,
       WaitKind::kDefects,
       "claim_gate.waits",
       "no live cell can host it: cells a, b: replay:r backend cannot emulate defect "
       "friction_variability.mu_scale_std; cell m: model backend cannot push at 0.8 m/s (pusher "
       "limit 0.5 m/s)"},
  };
  for (const Row& r : rows) {
    SCOPED_TRACE(r.name);
    CampaignNeeds needs;
    needs.campaign_id = 3;
    needs.physics_defects = r.physics;
    needs.trials = r.trials;
    const GateDecision d = DecideClaimGate(needs, r.live);
    EXPECT_EQ(d.waits, r.waits);
    EXPECT_STREQ(d.rule, r.rule);
    if (r.waits) {
      EXPECT_EQ(d.kind, r.kind);
      EXPECT_EQ(d.reason, r.reason);
    }
  }
}

TEST(ClaimGate, PhysicsDefectsAreThoseAPhysicsBackendMustApply) {
  EXPECT_TRUE(PhysicsDefects("").empty());
  EXPECT_TRUE(PhysicsDefects("{}").empty());
  EXPECT_TRUE(PhysicsDefects("not json").empty());
  // Sensing defects apply on every backend: they do not gate.
  EXPECT_TRUE(PhysicsDefects(R"({"sensor_noise":{"position_std":0.001}})").empty());
  EXPECT_TRUE(PhysicsDefects(R"({"friction_variability":{"mu_scale_std":0}})").empty());
  EXPECT_EQ(PhysicsDefects(R"({"friction_variability":{"mu_scale_std":0.1}})"),
            std::vector<std::string>{"friction_variability.mu_scale_std"});
  EXPECT_EQ(PhysicsDefects(R"({"actuation_noise":{"velocity_offset_std":[0,0.001,0]}})"),
            std::vector<std::string>{"actuation_noise.velocity_offset_std"});
  EXPECT_EQ(PhysicsDefects(R"({"actuation_noise":{"velocity_scale_std":0.05}})"),
            std::vector<std::string>{"actuation_noise.velocity_scale_std"});
}

TEST(ClaimGate, KindsHaveStoredNames) {
  EXPECT_EQ(ToString(WaitKind::kDefects), "defects");
  EXPECT_EQ(ToString(WaitKind::kContactTypes), "contact_types");
  EXPECT_EQ(ToString(WaitKind::kWorkspace), "workspace");
  EXPECT_EQ(ToString(WaitKind::kPusherSpeed), "pusher_speed");
}

}  // namespace
}  // namespace arena::orchestrator
