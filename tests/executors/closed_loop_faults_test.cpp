// A controller that dies mid-trial: the cell holds its last command for the
// scene's hold time, then stops the pusher and fails the phase with the
// reason, and goes on serving trials. Real processes; the controller is
// SIGKILLed.
#include <signal.h>

#include "closed_loop_support.hpp"

namespace arena {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

void DeadControllerFailsThePhase(double speed) {
  test::LoopRig rig(test::TestDomain(speed > 0 ? 191 : 190), speed);
  ASSERT_TRUE(rig.Ready());
  auto& d = rig.driver;
  auto& live = rig.live;
  auto& controller = rig.controller;

  const double hold_s = 0.3;
  // Long enough that the controller dies in the middle (lockstep: the
  // controller's answers pace the trial, ~1 ms a sample).
  const std::string scene = test::PivotScene(speed > 0 ? 4.0 : 60.0, 0.5, 0.2, hold_s);
  ASSERT_TRUE(d.Send(d.Command("c1", 1, msg::PHASE_EXECUTE, scene)));
  // Wait until the loop runs, then kill the controller.
  std::size_t seen = 0;
  const auto give_up = Clock::now() + 30s;
  while (seen < 50 && Clock::now() < give_up) {
    if (auto m = live.Take(100ms); m && m->trial_id() == 1 && m->closed_loop()) ++seen;
  }
  if (seen < 50) {  // say why: the phase's own status (seen once under load 20+)
    const auto early = d.FinalStatus(1, 5s);
    FAIL() << "the closed loop never ran (" << seen << " live samples); the phase: "
           << (early ? std::to_string(early->state()) + " " + early->reason() : "no status");
  }
  controller->Signal(SIGKILL);
  const auto killed = Clock::now();
  auto st = d.FinalStatus(1, 30s);
  const double after_s = std::chrono::duration<double>(Clock::now() - killed).count();
  ASSERT_TRUE(st);
  EXPECT_EQ(st->state(), msg::STATE_FAILED);
  EXPECT_NE(st->reason().find("no command for"), std::string::npos) << st->reason();
  EXPECT_NE(st->reason().find("pusher stopped"), std::string::npos) << st->reason();
  // Within the hold time (plus the ground truth's flush and a loaded host's slack).
  EXPECT_LT(after_s, hold_s + 2.0);
  const auto detail = test::ClosedLoopDetail(*st);
  ASSERT_TRUE(detail.is_object()) << st->detail_json();
  const auto& last = detail["commands"][detail["commands"].size() - 1];
  EXPECT_EQ(last[5].get<double>(), 0.0);  // the pusher was stopped
  EXPECT_EQ(last[6].get<double>(), 0.0);
  EXPECT_EQ(last[7].get<double>(), 0.0);

  // The cell survives: an open-loop trial runs to the end.
  ASSERT_TRUE(d.Send(d.Command("c1", 2, msg::PHASE_EXECUTE, test::CanonicalScene(0.2))));
  auto next = d.FinalStatus(2, 30s);
  ASSERT_TRUE(next);
  EXPECT_EQ(next->state(), msg::STATE_EXECUTED) << next->reason();
  EXPECT_FALSE(rig.cell->Wait(0ms).has_value()) << "the cell process ended";
}

TEST(ClosedLoopFaults, DeadControllerFailsThePhaseWithinItsHoldTimeInLockstep) {
  DeadControllerFailsThePhase(0);
}

TEST(ClosedLoopFaults, DeadControllerFailsThePhaseWithinItsHoldTimeOnTheWallClock) {
  DeadControllerFailsThePhase(1);
}

}  // namespace
}  // namespace arena
