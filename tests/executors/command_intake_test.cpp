// Which service a cell serves (executors/src/command_intake.hpp): claims,
// leases, successors, releases and the worker's queue, without processes.
// The DDS tests (cell_process_test, several_hosts_test) run the same rules
// between real services and cells; here every transition is driven by hand,
// with the clock as an argument.
#include "command_intake.hpp"

#include <gtest/gtest.h>

#include <limits>

namespace arena::executors {
namespace {

using Clock = CommandIntake::Clock;
constexpr const char* kCell = "c1";

msg::TrialCommand Command(std::uint64_t session, msg::Phase phase, std::uint64_t trial = 1,
                          const std::string& store = "/lab/a.db", double lease_s = 0) {
  msg::TrialCommand c;
  c.cell_id(kCell);
  c.service_session(session);
  c.service_store(store);
  c.service_host("host");
  c.service_pid(42);
  c.phase(phase);
  c.trial_id(trial);
  c.lease_s(lease_s);
  return c;
}

msg::TrialCommand Claim(std::uint64_t session, double lease_s,
                        const std::string& store = "/lab/a.db") {
  return Command(session, msg::PHASE_CLAIM, 0, store, lease_s);
}

Clock::time_point After(Clock::time_point t, double s) {
  return t + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

TEST(CommandIntake, AFreeCellServesTheFirstPhaseCommandsSessionOnAnImplicitLease) {
  CommandIntake intake;
  const auto t0 = Clock::now();
  const auto taken = intake.Take(Command(7, msg::PHASE_EXECUTE), t0, kCell);
  EXPECT_TRUE(taken.queued);
  EXPECT_TRUE(taken.announce);
  EXPECT_TRUE(intake.Serves(7));
  EXPECT_EQ(intake.serving().lease_s, CommandIntake::kImplicitLease_s);
  EXPECT_EQ(intake.serving().store, "/lab/a.db");
  ASSERT_TRUE(intake.Pop().has_value());
  EXPECT_FALSE(intake.Pop().has_value());
}

TEST(CommandIntake, AnotherSessionsCommandsAreDroppedWhileTheLeaseHolds) {
  CommandIntake intake;
  const auto t0 = Clock::now();
  EXPECT_TRUE(intake.Take(Claim(7, 5.0), t0, kCell).announce);
  // A second service on another store cannot take the cell nor queue work.
  EXPECT_FALSE(intake.Take(Claim(8, 5.0, "/lab/b.db"), After(t0, 1), kCell).announce);
  const auto other =
      intake.Take(Command(8, msg::PHASE_EXECUTE, 1, "/lab/b.db"), After(t0, 1), kCell);
  EXPECT_FALSE(other.queued);
  EXPECT_TRUE(intake.Serves(7));
  EXPECT_TRUE(intake.empty());
  // The lease runs out: the cell is free, and the other service may claim it.
  EXPECT_FALSE(intake.Expire(After(t0, 4.9), kCell));
  EXPECT_TRUE(intake.Expire(After(t0, 5.1), kCell));
  EXPECT_TRUE(intake.Serves(0));
  EXPECT_TRUE(intake.Take(Claim(8, 5.0, "/lab/b.db"), After(t0, 5.2), kCell).announce);
  EXPECT_TRUE(intake.Serves(8));
}

TEST(CommandIntake, APhaseCommandRenewsTheServedSessionsLease) {
  CommandIntake intake;
  const auto t0 = Clock::now();
  intake.Take(Claim(7, 5.0), t0, kCell);
  intake.Take(Command(7, msg::PHASE_RESET), After(t0, 4), kCell);
  EXPECT_FALSE(intake.Expire(After(t0, 8), kCell));  // renewed at t0 + 4 for 5 s
  EXPECT_TRUE(intake.Expire(After(t0, 9.1), kCell));
}

TEST(CommandIntake, TheSameStoresNewServiceTakesOverAndTheOldSessionIsNeverServedAgain) {
  CommandIntake intake;
  const auto t0 = Clock::now();
  intake.Take(Claim(7, 30.0), t0, kCell);
  intake.Take(Command(7, msg::PHASE_EXECUTE, 1), t0, kCell);
  intake.Take(Command(7, msg::PHASE_RESET, 2), t0, kCell);
  // A restarted service on the same store: the old one is dead.
  EXPECT_TRUE(intake.Take(Claim(9, 30.0), After(t0, 1), kCell).announce);
  EXPECT_TRUE(intake.Serves(9));
  EXPECT_TRUE(intake.empty()) << "the dead session's queued commands must not run";
  // Its late commands are dropped, even once the cell is free again.
  EXPECT_FALSE(intake.Take(Command(7, msg::PHASE_EXECUTE, 3), After(t0, 2), kCell).queued);
  EXPECT_TRUE(intake.Expire(After(t0, 40), kCell));
  EXPECT_FALSE(intake.Take(Command(7, msg::PHASE_EXECUTE, 3), After(t0, 41), kCell).queued);
  EXPECT_FALSE(intake.Take(Claim(7, 30.0), After(t0, 41), kCell).announce);
  EXPECT_TRUE(intake.Serves(0));
}

TEST(CommandIntake, OnlyTheServedSessionCanReleaseTheCell) {
  CommandIntake intake;
  const auto t0 = Clock::now();
  intake.Take(Claim(7, 30.0), t0, kCell);
  EXPECT_FALSE(intake.Take(Claim(8, 0.0, "/lab/b.db"), t0, kCell).announce);
  EXPECT_TRUE(intake.Serves(7));
  EXPECT_TRUE(intake.Take(Claim(7, 0.0), t0, kCell).announce);
  EXPECT_TRUE(intake.Serves(0));
  EXPECT_FALSE(intake.Take(Command(7, msg::PHASE_EXECUTE), t0, kCell).queued)
      << "a released session is retired";
  EXPECT_TRUE(intake.Take(Command(8, msg::PHASE_EXECUTE, 1, "/lab/b.db"), t0, kCell).queued);
}

TEST(CommandIntake, AClaimWithABadLeaseIsIgnoredAndALongOneIsCapped) {
  CommandIntake intake;
  const auto t0 = Clock::now();
  for (double bad :
       {-1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    EXPECT_FALSE(intake.Take(Claim(7, bad), t0, kCell).announce) << bad;
    EXPECT_TRUE(intake.Serves(0)) << bad;
  }
  intake.Take(Claim(7, 1e9), t0, kCell);
  EXPECT_EQ(intake.serving().lease_s, CommandIntake::kMaxLease_s);
}

TEST(CommandIntake, RenewingAClaimWithTheSameLeaseNeedsNoNewAnnouncement) {
  CommandIntake intake;
  const auto t0 = Clock::now();
  EXPECT_TRUE(intake.Take(Claim(7, 5.0), t0, kCell).announce);
  EXPECT_FALSE(intake.Take(Claim(7, 5.0), After(t0, 1), kCell).announce);
  EXPECT_TRUE(intake.Take(Claim(7, 6.0), After(t0, 2), kCell).announce);
}

TEST(CommandIntake, RetiredSessionsAreRememberedUpToABound) {
  CommandIntake intake;
  auto t = Clock::now();
  // Sessions 1..kRetiredKept+1, each taken over by the next on the same store.
  const std::uint64_t last = CommandIntake::kRetiredKept + 2;
  for (std::uint64_t s = 1; s <= last; ++s) intake.Take(Claim(s, 30.0), t, kCell);
  EXPECT_TRUE(intake.Serves(last));
  t = After(t, 31);
  EXPECT_TRUE(intake.Expire(t, kCell));
  // The newest retired sessions are still refused; the oldest was forgotten
  // (months of restarts cost bounded memory).
  EXPECT_FALSE(intake.Take(Command(last - 1, msg::PHASE_EXECUTE), t, kCell).queued);
  EXPECT_TRUE(intake.Take(Command(1, msg::PHASE_EXECUTE), t, kCell).queued);
}

// ResetGate: an EXECUTE sent ahead runs only right after its RESET ended done.
msg::TrialCommand Ahead(std::uint64_t session, std::uint64_t trial, std::uint64_t after,
                        std::uint32_t after_attempt) {
  msg::TrialCommand c = Command(session, msg::PHASE_EXECUTE, trial);
  c.after_reset_trial_id(after);
  c.after_reset_attempt(after_attempt);
  return c;
}

// A gate whose cell just ended the RESET after trial 2 attempt 1 of session 7.
ResetGate AfterReset(bool done, const std::string& why = "") {
  ResetGate gate;
  msg::TrialCommand reset = Command(7, msg::PHASE_RESET, 2);
  reset.attempt(1);
  gate.ResetEnded(reset, done, why);
  return gate;
}

TEST(ResetGate, AnExecuteNotSentAheadAlwaysRuns) {
  ResetGate gate;
  EXPECT_EQ(gate.Check(Command(7, msg::PHASE_EXECUTE, 3)), "");
  gate.ResetEnded(Command(7, msg::PHASE_RESET, 2), false, "object dropped");
  EXPECT_EQ(gate.Check(Command(7, msg::PHASE_EXECUTE, 3)), "");
}

TEST(ResetGate, AnAttemptWithoutItsTrialIsRefusedNamingTheField) {
  ResetGate gate = AfterReset(true);
  const std::string why = gate.Check(Ahead(7, 3, 0, 1));
  EXPECT_EQ(why.rfind("after_reset_attempt:", 0), 0u) << why;
}

TEST(ResetGate, AnExecuteSentAheadRunsRightAfterItsResetEndedDone) {
  ResetGate gate = AfterReset(true);
  EXPECT_EQ(gate.Check(Ahead(7, 3, 2, 1)), "");
}

TEST(ResetGate, AnExecuteSentAheadIsRefusedAfterAFailedReset) {
  ResetGate gate = AfterReset(false, "object dropped");
  const std::string why = gate.Check(Ahead(7, 3, 2, 1));
  EXPECT_NE(why.find("did not end done (object dropped)"), std::string::npos) << why;
  EXPECT_NE(why.find("after trial 2 attempt 1"), std::string::npos) << why;
}

TEST(ResetGate, AnExecuteSentAheadIsRefusedAfterAnyOtherResetOrCommand) {
  ResetGate gate;
  EXPECT_NE(gate.Check(Ahead(7, 3, 2, 1)), "");  // nothing ran yet
  gate = AfterReset(true);
  EXPECT_NE(gate.Check(Ahead(7, 3, 2, 2)), "");  // another attempt
  EXPECT_NE(gate.Check(Ahead(7, 3, 9, 1)), "");  // another trial
  EXPECT_NE(gate.Check(Ahead(8, 3, 2, 1)), "");  // another session
  gate.OtherEnded();                             // an EXECUTE ran in between
  const std::string why = gate.Check(Ahead(7, 3, 2, 1));
  EXPECT_NE(why.find("not what this cell ran last"), std::string::npos) << why;
}

}  // namespace
}  // namespace arena::executors
