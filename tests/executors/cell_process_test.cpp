// Real `arena cell` processes on a test-unique domain, driven by a test
// participant that plays the service: commands, statuses, ground truth,
// liveliness, defect statistics. Every wait is bounded; children are killed
// in teardown whatever happens (and by the kernel if this test dies).
#include <cmath>
#include <cstdlib>
#include <map>
#include <memory>

#include <gtest/gtest.h>

#include "arena/schemas/ground_truth.hpp"
#include "test_support.hpp"

namespace arena {
namespace {

using namespace std::chrono_literals;
using test::Child;
using test::Driver;

class ShmCleaner : public ::testing::Environment {
 public:
  // SIGKILLed cells leave fastrtps_* segments in /dev/shm; this removes only
  // segments no live process uses.
  void TearDown() override {
    [[maybe_unused]] int rc = std::system("fastdds shm clean > /dev/null 2>&1");
  }
};
[[maybe_unused]] auto* const kShmCleaner = ::testing::AddGlobalTestEnvironment(new ShmCleaner);

std::unique_ptr<Child> StartCell(const std::string& id, int domain, double speed,
                                 const std::string& defects = "") {
  std::vector<std::string> argv = {
      ARENA_BINARY,         "cell", "--id", id, "--domain", std::to_string(domain), "--speed",
      std::to_string(speed)};
  if (!defects.empty()) {
    const std::string path =
        ::testing::TempDir() + "defects_" + id + "_" + std::to_string(getpid()) + ".json";
    std::ofstream(path) << defects;
    argv.push_back("--defects");
    argv.push_back(path);
  }
  const std::string log =
      ::testing::TempDir() + "cell_" + id + "_" + std::to_string(getpid()) + ".log";
  return std::make_unique<Child>(argv, log);
}

// Every GroundTruth batch of one trial (and attempt) until the last one.
struct Stream {
  std::vector<msg::GroundTruth> batches;
  std::vector<msg::GroundTruthSample> samples;
  std::string error;  // first malformed or out-of-order batch
  bool complete = false;
};

Stream Collect(Driver& d, std::uint64_t trial, std::uint32_t attempt,
               std::chrono::milliseconds timeout,
               std::map<std::uint64_t, std::vector<msg::GroundTruth>>* others = nullptr) {
  Stream s;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!s.complete) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left <= 0ms) break;
    auto b = d.ground_truth.Take(left);
    if (!b) break;
    if (b->trial_id() != trial || b->attempt() != attempt) {
      if (others) (*others)[b->trial_id()].push_back(*b);
      continue;
    }
    if (s.error.empty()) {
      if (b->batch() != s.batches.size())
        s.error = "batch " + std::to_string(b->batch()) + " out of order";
      else
        s.error = dds::CheckBatch(*b, static_cast<std::uint32_t>(s.samples.size()));
    }
    for (const auto& x : b->samples()) s.samples.push_back(x);
    s.complete = b->last();
    s.batches.push_back(std::move(*b));
  }
  return s;
}

TEST(CellProcess, TwoCellsAndADriverExchangeCommands) {
  const int domain = test::TestDomain(1);
  auto c1 = StartCell("c1", domain, 0);
  auto c2 = StartCell("c2", domain, 0,
                      R"({"workspace": {"min": -0.05, "max": 0.05}, "contact_types": ["point"]})");
  Driver d(domain);
  ASSERT_TRUE(d.WaitForCells({"c1", "c2"}, 15s)) << "cells did not announce themselves";
  EXPECT_EQ(d.seen["c2"].contact_types().size(), 1u);
  EXPECT_DOUBLE_EQ(d.seen["c2"].workspace_max()[0], 0.05);
  ASSERT_TRUE(d.commands.WaitForMatched(2, 10s));

  // c1 executes; c2 refuses (its fingers are points only, the scene has a line).
  auto e1 = d.Command("c1", 101, msg::PHASE_EXECUTE, test::CanonicalScene(1.0));
  auto e2 = d.Command("c2", 201, msg::PHASE_EXECUTE, test::CanonicalScene(1.0));
  ASSERT_TRUE(d.commands.Write(e1));
  ASSERT_TRUE(d.commands.Write(e2));
  std::map<std::uint64_t, std::vector<msg::GroundTruth>> others;
  Stream s1 = Collect(d, 101, 1, 20s, &others);
  EXPECT_TRUE(s1.complete);
  EXPECT_EQ(s1.error, "");
  auto st1 = d.FinalStatus(101, 20s);
  ASSERT_TRUE(st1);
  EXPECT_EQ(st1->state(), msg::STATE_EXECUTED) << st1->reason();
  EXPECT_EQ(st1->cell_id(), "c1");
  EXPECT_EQ(st1->samples(), s1.samples.size());
  EXPECT_GE(s1.samples.size(), 250u);
  auto st2 = d.FinalStatus(201, 20s);
  ASSERT_TRUE(st2);
  EXPECT_EQ(st2->state(), msg::STATE_REFUSED);
  EXPECT_NE(st2->reason().find("fingers[1].type"), std::string::npos) << st2->reason();
  EXPECT_TRUE(others[201].empty()) << "a refused trial streamed ground truth";

  // Reset c1 to the next trial's start.
  ASSERT_TRUE(d.Send((d.Command("c1", 101, msg::PHASE_RESET, test::CanonicalScene(1.0)))));
  auto r1 = d.FinalStatus(101, 20s);
  ASSERT_TRUE(r1);
  EXPECT_EQ(r1->phase(), msg::PHASE_RESET);
  EXPECT_EQ(r1->state(), msg::STATE_RESET_DONE) << r1->reason();
  EXPECT_LE(r1->reset_position_error(), 0.002);
  EXPECT_GE(r1->reset_attempts(), 1u);

  // Idempotency: the same EXECUTE again gets the final status again and no new stream.
  ASSERT_TRUE(d.commands.Write(e1));
  auto again = d.FinalStatus(101, 20s);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->state(), msg::STATE_EXECUTED);
  EXPECT_EQ(again->samples(), st1->samples());
  EXPECT_FALSE(d.ground_truth.Take(500ms)) << "a finished trial ran again";

  // ... but a new service session (a new store restarts trial ids at 1) is not a
  // repeat: the same trial id and attempt run again and stream again.
  // (The first session releases the cell; a cell serves one session at a time.)
  ASSERT_TRUE(d.Send(d.Claim("c1", 0)));
  auto e1_new_session = e1;
  e1_new_session.service_session(e1.service_session() + 1);
  ASSERT_TRUE(d.commands.Write(e1_new_session));
  Stream rerun = Collect(d, 101, 1, 20s);
  EXPECT_TRUE(rerun.complete) << "a new session's command was taken for a repeat";
  auto st_rerun = d.FinalStatus(101, 20s);
  ASSERT_TRUE(st_rerun);
  EXPECT_EQ(st_rerun->state(), msg::STATE_EXECUTED) << st_rerun->reason();

  // A scene outside c2's workspace is refused with the reason.
  ASSERT_TRUE(
      d.Send((d.Command("c2", 202, msg::PHASE_EXECUTE,
                        R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2,
         "pose": {"position": [0.2, 0, 0], "rpy": [0, 0, 0]}},
         "duration": 0.1, "grip_force": 10,
         "fingers": [{"name": "l", "type": "point", "position": [0.175, 0, 0], "normal": [1, 0, 0], "mu": 0.5},
                     {"name": "r", "type": "point", "position": [0.225, 0, 0], "normal": [-1, 0, 0], "mu": 0.5}]})"))));
  auto ws = d.FinalStatus(202, 20s);
  ASSERT_TRUE(ws);
  EXPECT_EQ(ws->state(), msg::STATE_REFUSED);
  EXPECT_NE(ws->reason().find("workspace"), std::string::npos) << ws->reason();

  // Clean shutdown on SIGTERM.
  c1->Signal(SIGTERM);
  auto rc = c1->Wait(10s);
  ASSERT_TRUE(rc) << "cell did not stop on SIGTERM";
  EXPECT_TRUE(WIFEXITED(*rc) && WEXITSTATUS(*rc) == 0);
}

// Issue 27: an EXECUTE sent while the cell still resets (after_reset_*)
// waits in the cell's queue behind that RESET and runs only if it ended
// done. Both commands go out back to back, as the service sends them.
TEST(CellProcess, AnExecuteQueuedBehindAResetRunsOnlyIfThatResetEndedDone) {
  const int domain = test::TestDomain(9);
  auto cell = StartCell("c1", domain, 0, R"({"workspace": {"min": -0.05, "max": 0.05}})");
  Driver d(domain);
  ASSERT_TRUE(d.WaitForCells({"c1"}, 15s)) << "the cell did not announce itself";
  ASSERT_TRUE(d.commands.WaitForMatched(1, 10s));
  const std::string outside =
      R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2,
         "pose": {"position": [0.2, 0, 0], "rpy": [0, 0, 0]}},
         "duration": 0.1, "grip_force": 10,
         "fingers": [{"name": "l", "type": "point", "position": [0.175, 0, 0], "normal": [1, 0, 0], "mu": 0.5},
                     {"name": "r", "type": "point", "position": [0.225, 0, 0], "normal": [-1, 0, 0], "mu": 0.5}]})";
  auto queued = [&](std::uint64_t trial, std::uint64_t after) {
    auto e = d.Command("c1", trial, msg::PHASE_EXECUTE, test::CanonicalScene(0.2));
    e.after_reset_trial_id(after);
    e.after_reset_attempt(1);
    return e;
  };
  // A reset aimed outside the workspace is refused: the trial behind it too.
  ASSERT_TRUE(d.Send(d.Command("c1", 100, msg::PHASE_RESET, outside)));
  ASSERT_TRUE(d.Send(queued(101, 100)));
  auto r = d.FinalStatus(100, 20s);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->state(), msg::STATE_REFUSED) << r->reason();
  auto refused = d.FinalStatus(101, 20s);
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->state(), msg::STATE_REFUSED);
  EXPECT_NE(refused->reason().find("did not end done"), std::string::npos) << refused->reason();
  EXPECT_FALSE(d.ground_truth.Take(300ms)) << "a trial ran from a failed reset";
  // A reset that ends done: the trial behind it runs and streams.
  ASSERT_TRUE(d.Send(d.Command("c1", 102, msg::PHASE_RESET, test::CanonicalScene(0.2))));
  ASSERT_TRUE(d.Send(queued(103, 102)));
  auto done = d.FinalStatus(102, 20s);
  ASSERT_TRUE(done);
  EXPECT_EQ(done->state(), msg::STATE_RESET_DONE) << done->reason();
  Stream s = Collect(d, 103, 1, 20s);
  EXPECT_TRUE(s.complete);
  auto ran = d.FinalStatus(103, 20s);
  ASSERT_TRUE(ran);
  EXPECT_EQ(ran->state(), msg::STATE_EXECUTED) << ran->reason();
  // Sent ahead of another reset than the one it names: refused.
  ASSERT_TRUE(d.Send(d.Command("c1", 104, msg::PHASE_RESET, test::CanonicalScene(0.2))));
  ASSERT_TRUE(d.Send(queued(105, 102)));
  auto other = d.FinalStatus(105, 20s);
  ASSERT_TRUE(other);
  EXPECT_EQ(other->state(), msg::STATE_REFUSED);
  EXPECT_NE(other->reason().find("not what this cell ran last"), std::string::npos)
      << other->reason();
}

TEST(CellProcess, TenSecondStreamArrivesCompleteAndInOrder) {
  const int domain = test::TestDomain(2);
  auto c1 = StartCell("long", domain, 0);
  Driver d(domain);
  ASSERT_TRUE(d.WaitForCells({"long"}, 15s));
  ASSERT_TRUE(d.commands.WaitForMatched(1, 10s));
  auto cmd = d.Command("long", 7, msg::PHASE_EXECUTE, test::CanonicalScene(10.0));
  ASSERT_TRUE(d.commands.Write(cmd));
  Stream s = Collect(d, 7, 1, 40s);
  ASSERT_TRUE(s.complete) << s.samples.size() << " samples before the timeout";
  EXPECT_EQ(s.error, "");
  EXPECT_GE(s.samples.size(), 2500u);  // 10 s at 250 Hz (plus t = 0)
  for (size_t i = 0; i < s.samples.size(); ++i) {
    ASSERT_NEAR(s.samples[i].t(), i / 250.0, 1e-9) << "sample " << i;
  }
  EXPECT_EQ(s.batches.size(), (s.samples.size() + 24) / 25);
  auto st = d.FinalStatus(7, 20s);
  ASSERT_TRUE(st);
  EXPECT_EQ(st->state(), msg::STATE_EXECUTED) << st->reason();
  EXPECT_EQ(st->samples(), s.samples.size());
}

TEST(CellProcess, WallClockSpeedPacesTheStream) {
  const int domain = test::TestDomain(3);
  auto c1 = StartCell("rt", domain, 1);
  Driver d(domain);
  ASSERT_TRUE(d.WaitForCells({"rt"}, 15s));
  ASSERT_TRUE(d.commands.WaitForMatched(1, 10s));
  auto cmd = d.Command("rt", 8, msg::PHASE_EXECUTE, test::CanonicalScene(1.0));
  const auto sent = std::chrono::steady_clock::now();
  ASSERT_TRUE(d.commands.Write(cmd));
  Stream s = Collect(d, 8, 1, 20s);
  const double took =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
  ASSERT_TRUE(s.complete);
  EXPECT_EQ(s.error, "");
  EXPECT_EQ(s.samples.size(), 251u);
  EXPECT_GE(took, 0.95);  // the last sample is at t = 1 s
  EXPECT_LT(took, 5.0);
}

// The cell's intake thread reads commands as they come, so a release sent
// during a 10 s wall-clock trial is taken at once (the cell announces it is
// free and the trial stops, interrupted), not after the trial; then the
// worker takes commands again: a new session's command runs.
TEST(CellProcess, AReleaseDuringALongTrialIsTakenAtOnce) {
  const int domain = test::TestDomain(8);
  auto c1 = StartCell("busy", domain, 1);
  Driver d(domain);
  ASSERT_TRUE(d.WaitForCells({"busy"}, 15s));
  ASSERT_TRUE(d.commands.WaitForMatched(1, 10s));
  ASSERT_TRUE(d.Send(d.Command("busy", 9, msg::PHASE_EXECUTE, test::CanonicalScene(10.0))));
  auto first = d.ground_truth.Take(10s);  // the trial runs
  ASSERT_TRUE(first) << "the trial did not start";
  ASSERT_EQ(first->trial_id(), 9u);
  while (d.announcements.Take(0ms)) {
  }

  ASSERT_TRUE(d.Send(d.Claim("busy", 0)));
  const auto sent = std::chrono::steady_clock::now();
  double freed_after = -1;
  while (freed_after < 0 && std::chrono::steady_clock::now() < sent + 8s) {
    auto a = d.announcements.Take(100ms);
    if (a && a->cell_id() == "busy" && a->serving_session() == 0)
      freed_after = std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
  }
  ASSERT_GE(freed_after, 0) << "the release was not taken during the trial";
  EXPECT_LT(freed_after, 2.0) << "the release waited behind the trial";
  auto st = d.FinalStatus(9, 8s);
  ASSERT_TRUE(st) << "the released trial did not stop";
  EXPECT_EQ(st->state(), msg::STATE_FAILED);
  EXPECT_EQ(st->failure(), msg::FAILURE_INTERRUPTED) << st->reason();
  EXPECT_LT(std::chrono::steady_clock::now() - sent, 5s);
  std::printf("release taken %.3f s after it was sent, mid-trial\n", freed_after);

  d.session += 1;  // a new service: its command claims the free cell and runs
  ASSERT_TRUE(d.Send(d.Command("busy", 10, msg::PHASE_EXECUTE, test::CanonicalScene(0.2))));
  auto next = d.FinalStatus(10, 10s);
  ASSERT_TRUE(next) << "the worker did not read again after the trial";
  EXPECT_EQ(next->state(), msg::STATE_EXECUTED) << next->reason();
}

// The leases, not DDS's defaults (tens of seconds), decide how soon a killed
// cell is seen gone. The slack (3 s past each lease) is for a loaded CI
// machine whose event thread runs late; the defaults would miss it by far.
TEST(CellProcess, KilledCellIsSeenGoneSoonAfterItsLeases) {
  const int domain = test::TestDomain(4);
  auto c1 = StartCell("victim", domain, 0);
  Driver d(domain);
  ASSERT_TRUE(d.WaitForCells({"victim"}, 15s));
  ASSERT_TRUE(d.participant.WaitForPeer("arena.cell.victim", 10s));
  ASSERT_TRUE(d.statuses.WaitForMatched(1, 10s));
  while (d.participant.NextPeerEvent(0ms)) {
  }
  c1->Signal(SIGKILL);
  const auto killed = std::chrono::steady_clock::now();
  ASSERT_TRUE(c1->Wait(5s));
  double writer_lost = -1, participant_left = -1;
  const auto deadline = killed + 15s;
  while ((writer_lost < 0 || participant_left < 0) && std::chrono::steady_clock::now() < deadline) {
    auto e = d.participant.NextPeerEvent(100ms);
    if (e)
      std::printf("event %s %s %s\n", dds::ToString(e->kind), e->participant.c_str(),
                  e->topic.c_str());
    if (!e || e->participant != "arena.cell.victim") continue;
    const double at = std::chrono::duration<double>(e->when - killed).count();
    if (e->kind == dds::PeerEvent::Kind::kWriterLost && writer_lost < 0) writer_lost = at;
    if (e->kind == dds::PeerEvent::Kind::kParticipantLeft && participant_left < 0)
      participant_left = at;
  }
  ASSERT_GE(writer_lost, 0) << "liveliness loss never reported";
  EXPECT_LE(writer_lost, dds::kCellLivelinessLease_s + 3.0);
  ASSERT_GE(participant_left, 0) << "participant removal never reported";
  EXPECT_LE(participant_left, 2.5 + 3.0);  // participant lease + slack
  std::printf(
      "killed cell: writer liveliness lost after %.2f s, participant dropped after %.2f s\n",
      writer_lost, participant_left);
}

TEST(CellProcess, DefectNoiseStatisticsMatchTheProfileAndRepeatBitForBit) {
  const int domain = test::TestDomain(5);
  const double kStd[3] = {0.001, 0.002, 0.0005};
  const double kForceStd = 0.1;
  auto c1 = StartCell("noisy", domain, 0,
                      R"({"pose_noise": {"position_std": [0.001, 0.002, 0.0005]},
                          "ft_noise": {"force_std": 0.1}, "drop_probability": 0.05})");
  Driver d(domain);
  ASSERT_TRUE(d.WaitForCells({"noisy"}, 15s));
  ASSERT_TRUE(d.commands.WaitForMatched(1, 10s));
  ASSERT_TRUE(
      d.Send((d.Command("noisy", 9, msg::PHASE_EXECUTE, test::CanonicalScene(10.0), 1234, 1))));
  Stream a = Collect(d, 9, 1, 40s);
  ASSERT_TRUE(a.complete);
  ASSERT_TRUE(d.FinalStatus(9, 20s));
  // The same trial and seed as attempt 2: the cell runs it again and must
  // see exactly what it saw the first time.
  ASSERT_TRUE(
      d.Send((d.Command("noisy", 9, msg::PHASE_EXECUTE, test::CanonicalScene(10.0), 1234, 2))));
  Stream b = Collect(d, 9, 2, 40s);
  ASSERT_TRUE(b.complete);
  ASSERT_EQ(a.samples.size(), b.samples.size());

  double sum[3] = {}, sum2[3] = {}, fsum = 0, fsum2 = 0;
  int n = 0, dropped = 0;
  for (size_t i = 0; i < a.samples.size(); ++i) {
    const auto& x = a.samples[i];
    const auto& y = b.samples[i];
    ASSERT_EQ(x.observed_valid(), y.observed_valid());
    ASSERT_EQ(x.observed_object_pose(), y.observed_object_pose()) << "sample " << i;
    ASSERT_EQ(x.observed_pusher_wrench(), y.observed_pusher_wrench()) << "sample " << i;
    if (!x.observed_valid()) {
      ++dropped;
      continue;
    }
    ++n;
    for (int k = 0; k < 3; ++k) {
      const double e = x.observed_object_pose()[k] - x.object_pose()[k];
      sum[k] += e;
      sum2[k] += e * e;
    }
    const double fe = x.observed_pusher_wrench()[2] - x.pusher_force()[2];
    fsum += fe;
    fsum2 += fe * fe;
  }
  ASSERT_GT(n, 2000);
  // ~2400 samples: the sample std is within 1/sqrt(2n) = 1.4 % (1 sigma) of
  // the true one; 6 % is > 4 sigma.
  for (int k = 0; k < 3; ++k) {
    const double s = std::sqrt(sum2[k] / n - std::pow(sum[k] / n, 2));
    EXPECT_NEAR(s / kStd[k], 1.0, 0.06) << "position axis " << k;
  }
  EXPECT_NEAR(std::sqrt(fsum2 / n - std::pow(fsum / n, 2)) / kForceStd, 1.0, 0.06);
  EXPECT_NEAR(dropped / static_cast<double>(a.samples.size()), 0.05, 0.015);
}

}  // namespace
}  // namespace arena
