// A controller's name is bound to its identity (issue 28): real `arena cell`
// and `arena controller` processes on a test-unique domain.
//   - With DDS-Security, a second lab identity claiming a controller's name
//     can neither start as that controller nor publish where the cell reads
//     its commands; what it publishes on its own topic never reaches the
//     trial, whose commands come from the bound controller only.
//   - With or without security, a second controller of a name already held
//     on the domain is refused at its start (exit 2, naming the name and the
//     other controller), and the first one keeps running.
#include <sys/wait.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <thread>

#include "arena/schemas/security.hpp"
#include "closed_loop_support.hpp"

namespace arena {
namespace {

using namespace std::chrono_literals;

// The rogue's pusher speed (m/s): never one pivot_to_angle commands here.
constexpr double kRogueSpeed = 0.0777;

int RunArena(const std::vector<std::string>& args, const std::string& log) {
  std::vector<std::string> argv = {ARENA_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  test::Child child(argv, log);
  const auto st = child.Wait(60s);
  return st && WIFEXITED(*st) ? WEXITSTATUS(*st) : -1;
}

std::string Log(const std::string& what) {
  return ::testing::TempDir() + "controller_identity_" + what + "_" + std::to_string(getpid()) +
         ".log";
}

// The log of test::StartProcess(what, ...).
std::string ProcessLog(const std::string& what) {
  return ::testing::TempDir() + "closed_loop_" + what + "_" + std::to_string(getpid()) + ".log";
}

// The exit code of a child that must end within 30 s (-1: it did not).
int ExitCode(test::Child& child) {
  const auto st = child.Wait(30s);
  return st && WIFEXITED(*st) ? WEXITSTATUS(*st) : -1;
}

TEST(ControllerIdentity, ASecondIdentityClaimingTheNameCannotSteerTheTrial) {
  const std::string lab = ::testing::TempDir() + "ctlid_lab_" + std::to_string(getpid());
  std::filesystem::remove_all(lab);
  ASSERT_EQ(RunArena({"certs", "init", lab}, Log("certs")), 0) << test::ReadFile(Log("certs"));
  for (const auto& [role, name] :
       std::vector<std::pair<std::string, std::string>>{{"service", "service"},
                                                        {"cell", "c1"},
                                                        {"controller", "pivot_to_angle"},
                                                        {"controller", "rogue"}}) {
    ASSERT_EQ(RunArena({"certs", "issue", lab, "--role", role, "--name", name}, Log("certs")), 0)
        << test::ReadFile(Log("certs"));
  }
  const int domain = test::TestDomain(53);
  const std::string d = std::to_string(domain);
  auto cell = test::StartProcess(
      "sec_cell", {"cell", "--id", "c1", "--domain", d, "--speed", "0", "--security", lab + "/c1"});
  auto controller =
      test::StartProcess("sec_controller", {"controller", "--name", "pivot_to_angle", "--domain", d,
                                            "--security", lab + "/pivot_to_angle"});
  dds::NetworkOptions service_net;
  service_net.security_dir = lab + "/service";
  test::Driver driver(domain, service_net);
  ASSERT_TRUE(driver.WaitForCells({"c1"}, 30s)) << test::ReadFile(ProcessLog("sec_cell"));
  ASSERT_TRUE(driver.commands.WaitForMatched(1, 15s));
  ASSERT_TRUE(driver.participant.WaitForPeer("arena.controller.pivot_to_angle", 30s));

  // The rogue identity as `arena controller` under the name: refused.
  {
    auto impostor = test::StartProcess(
        "impostor", {"controller", "--name", "pivot_to_angle", "--law", "sliding_to_position",
                     "--domain", d, "--security", lab + "/rogue"});
    EXPECT_EQ(ExitCode(*impostor), 2);
    const std::string log = test::ReadFile(ProcessLog("impostor"));
    EXPECT_NE(log.find("may not publish pusher commands as controller 'pivot_to_angle'"),
              std::string::npos)
        << log;
  }
  // The bound identity started twice: the second is refused too.
  {
    auto twin = test::StartProcess("twin", {"controller", "--name", "pivot_to_angle", "--domain", d,
                                            "--security", lab + "/pivot_to_angle"});
    EXPECT_EQ(ExitCode(*twin), 2);
    const std::string log = test::ReadFile(ProcessLog("twin"));
    EXPECT_NE(log.find("controller 'pivot_to_angle' is registered already"), std::string::npos)
        << log;
    EXPECT_NE(log.find("pid " + std::to_string(controller->pid())), std::string::npos) << log;
  }

  // The rogue identity in this process, under the controller's participant
  // name: DDS access control refuses it a writer where the cell reads the
  // controller's commands, and on the plain PusherCommand topic.
  dds::ParticipantOptions po;
  po.domain_id = domain;
  po.name = "arena.controller.pivot_to_angle";
  po.network.security_dir = lab + "/rogue";
  dds::Participant rogue(po);
  dds::WriterOptions as_victim;
  as_victim.controller = "pivot_to_angle";
  EXPECT_THROW({ dds::Writer<msg::PusherCommand> w(rogue, as_victim); }, dds::SecurityError);
  EXPECT_THROW({ dds::Writer<msg::PusherCommand> w(rogue); }, dds::SecurityError);
  // What it may do: publish on its own name's topic, commands naming the
  // victim controller, answering every live sample of c1.
  dds::WriterOptions own;
  own.controller = "rogue";
  dds::Writer<msg::PusherCommand> rogue_commands(rogue, own);
  dds::Reader<msg::LiveState> rogue_live(rogue, dds::ReaderOptions{false});
  std::atomic<bool> stop{false};
  std::atomic<int> injected{0};
  std::thread attacker([&] {
    while (!stop) {
      auto m = rogue_live.Take(20ms);
      if (!m || !m->closed_loop()) continue;
      msg::PusherCommand c;
      c.cell_id(m->cell_id());
      c.trial_id(m->trial_id());
      c.attempt(m->attempt());
      c.answers_sample(m->sample());
      c.controller("pivot_to_angle");
      c.velocity() = {0, kRogueSpeed, 0};
      c.angular_velocity() = {0, 0, 0};
      c.state_sent_unix_ns(m->sent_unix_ns());
      if (rogue_commands.Write(c)) ++injected;
    }
  });

  // The rogue hears the cell's live samples before the trial starts.
  ASSERT_TRUE(rogue_live.WaitForMatched(1, 30s));
  const std::string scene = test::PivotScene(1.2, 0.1, 0.5, 2.0);
  ASSERT_TRUE(driver.Send(driver.Command("c1", 1, msg::PHASE_EXECUTE, scene, 11, 1)));
  const auto st = driver.FinalStatus(1, 90s);
  stop = true;
  attacker.join();
  ASSERT_TRUE(st) << test::ReadFile(ProcessLog("sec_cell"));
  ASSERT_EQ(st->state(), msg::STATE_EXECUTED) << st->reason();
  EXPECT_GT(injected.load(), 0) << "the rogue saw no live sample: the attack was not tried";
  const auto detail = test::ClosedLoopDetail(*st);
  ASSERT_TRUE(detail.is_object()) << st->detail_json();
  const auto& commands = detail["commands"];
  ASSERT_EQ(commands.size(), st->samples());
  EXPECT_EQ(detail["held"].get<int>(), 0) << "every sample answered by the bound controller";
  for (std::size_t k = 0; k < commands.size(); ++k) {
    for (std::size_t col = 2; col < 8; ++col) {  // commanded and applied velocities
      ASSERT_NE(std::abs(commands[k][col].get<double>()), kRogueSpeed)
          << "sample " << k << ": the rogue's command was applied";
    }
  }
  EXPECT_EQ(controller->Wait(0ms), std::nullopt) << "the bound controller still runs";
}

TEST(ControllerIdentity, ASecondControllerOfTheSameNameIsRefused) {
  const int domain = test::TestDomain(54);
  auto first = test::StartController(domain, "pivot_to_angle");
  test::Driver driver(domain);
  ASSERT_TRUE(driver.participant.WaitForPeer("arena.controller.pivot_to_angle", 30s));
  auto second =
      test::StartProcess("second", {"controller", "--name", "pivot_to_angle", "--law",
                                    "sliding_to_position", "--domain", std::to_string(domain)});
  EXPECT_EQ(ExitCode(*second), 2);
  const std::string log = test::ReadFile(ProcessLog("second"));
  EXPECT_NE(log.find("--name: controller 'pivot_to_angle' is registered already on domain " +
                     std::to_string(domain)),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("pid " + std::to_string(first->pid())), std::string::npos) << log;
  EXPECT_EQ(first->Wait(0ms), std::nullopt) << "the first controller still runs";
  // Another name on the same domain is welcome.
  auto other = test::StartController(domain, "sliding_to_position");
  EXPECT_TRUE(driver.participant.WaitForPeer("arena.controller.sliding_to_position", 30s));
  EXPECT_EQ(other->Wait(1500ms), std::nullopt) << "a controller of another name was refused";
}

}  // namespace
}  // namespace arena
