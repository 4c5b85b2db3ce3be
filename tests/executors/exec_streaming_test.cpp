// exec:COMMAND streams live: every sample a driver writes reaches the cell's
// GroundTruth log and its LiveState topic while the driver is still running.
// The driver (a real Python process, written below) sends 30 samples, then
// waits for a file the test creates only after it has seen those 30 samples
// over DDS, then sends 30 more and says done. A driver that crashes after
// streaming half a trial fails the phase (the samples already sent are not a
// trial); the cell restarts it and the next trial runs whole.
#include <filesystem>
#include <fstream>
#include <set>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/executors/backend.hpp"
#include "arena/executors/cell.hpp"
#include "test_support.hpp"

namespace arena::executors {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using nlohmann::json;

// Seed 13 crashes (exit 3) where seed 7 goes on. GO/go-TRIAL lets it continue.
constexpr const char* kDriver = R"PY(
import json, os, sys, time
go = sys.argv[1]
def send(m):
    sys.stdout.write(json.dumps(m) + "\n")
    sys.stdout.flush()
send({"type": "hello", "protocol": 1, "name": "stream-test", "truth": "robot",
      "contact_types": ["point", "line", "patch"]})
prepared = None
for line in sys.stdin:
    m = json.loads(line)
    if m["type"] == "prepare":
        scene = m["scene"]
        contacts = len(scene["fingers"]) + (1 if scene.get("pusher") else 0)
        prepared = (m["trial_id"], m["seed"], contacts)
        send({"type": "ready"})
    elif m["type"] == "execute":
        trial, seed, contacts = prepared
        for k in range(60):
            if k == 30:
                flag = os.path.join(go, "go-%d" % trial)
                until = time.time() + 30
                while not os.path.exists(flag) and time.time() < until:
                    time.sleep(0.01)
                if seed == 13:
                    os._exit(3)
            send({"type": "sample", "t": 0.004 * k, "position": [0, 0, 1e-5 * k],
                  "orientation": [1, 0, 0, 0],
                  "contacts": [{"normal_force": 5.0, "mode": "stick"}] * contacts})
        send({"type": "done", "detail": {"driver": "stream-test"}})
    elif m["type"] == "shutdown":
        break
)PY";

class ExecStreaming : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/arena-exec-streaming-XXXXXX";
    dir_ = mkdtemp(tmpl);
    std::ofstream(dir_ + "/driver.py") << kDriver;
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }
  void Go(std::uint64_t trial) { std::ofstream(dir_ + "/go-" + std::to_string(trial)).close(); }

  // What arrived over DDS for one trial so far.
  struct Seen {
    std::set<std::uint32_t> logged;  // sample indices in GroundTruth batches
    std::set<std::uint32_t> live;    // sample indices on LiveState
    bool last_batch = false;
  };
  void Drain(test::Driver& d, dds::Reader<msg::LiveState>& live, std::uint64_t trial, Seen* seen) {
    for (auto b = d.ground_truth.Take(20ms); b; b = d.ground_truth.Take(0ms)) {
      if (b->trial_id() != trial) continue;
      for (std::uint32_t i = 0; i < b->samples().size(); ++i)
        seen->logged.insert(b->first_sample() + i);
      seen->last_batch = seen->last_batch || b->last();
    }
    for (auto m = live.Take(0ms); m; m = live.Take(0ms))
      if (m->trial_id() == trial) seen->live.insert(m->sample());
  }
  // Waits (bounded) until the first 30 samples arrived in the log and live.
  bool WaitForFirstThirty(test::Driver& d, dds::Reader<msg::LiveState>& live, std::uint64_t trial,
                          Seen* seen) {
    const auto until = std::chrono::steady_clock::now() + 20s;
    while (std::chrono::steady_clock::now() < until) {
      Drain(d, live, trial, seen);
      if (seen->logged.size() >= 30 && seen->live.count(29)) return true;
    }
    return false;
  }

  std::string dir_;
};

TEST_F(ExecStreaming, SamplesReachTheLogAndLiveTopicBeforeTheDriverFinishes) {
  const int domain = test::TestDomain(31);
  CellOptions options;
  options.id = "stream1";
  options.domain_id = domain;
  options.speed = 0;
  ExecBackendOptions exec;
  exec.command = "python3 " + dir_ + "/driver.py " + dir_;
  exec.reply_timeout_s = 40;
  Cell cell(options, MakeExecBackend(exec));
  test::Driver d(domain);
  dds::Reader<msg::LiveState> live(d.participant, dds::ReaderOptions{false});
  ASSERT_TRUE(d.WaitForCells({"stream1"}, 15s));
  ASSERT_TRUE(d.commands.WaitForMatched(1, 10s));
  ASSERT_TRUE(live.WaitForMatched(1, 10s));
  // 60 samples, 4 ms apart: the driver streams the whole scene (a stream
  // shorter than its scene is refused).
  const std::string scene = test::CanonicalScene(0.236);

  // 1: streamed while the driver waits; the rest after it continues.
  ASSERT_TRUE(d.Send(d.Command("stream1", 1, msg::PHASE_EXECUTE, scene, 7)));
  Seen one;
  ASSERT_TRUE(WaitForFirstThirty(d, live, 1, &one))
      << one.logged.size() << " samples in the log, " << one.live.size() << " live";
  EXPECT_EQ(one.logged.size(), 30u);  // 0..29: all that were written, in the log already
  EXPECT_EQ(*one.logged.rbegin(), 29u);
  EXPECT_FALSE(one.last_batch);
  EXPECT_FALSE(d.FinalStatus(1, 300ms).has_value()) << "the driver cannot have finished yet";
  Go(1);
  const auto done = d.FinalStatus(1, 20s);
  ASSERT_TRUE(done.has_value());
  ASSERT_EQ(done->state(), msg::STATE_EXECUTED) << done->reason();
  EXPECT_EQ(done->samples(), 60u);
  const auto until = std::chrono::steady_clock::now() + 10s;
  while ((one.logged.size() < 60 || !one.last_batch) && std::chrono::steady_clock::now() < until)
    Drain(d, live, 1, &one);
  EXPECT_EQ(one.logged.size(), 60u);
  EXPECT_EQ(*one.logged.rbegin(), 59u);
  EXPECT_TRUE(one.last_batch);

  // 2: the driver crashes after streaming half a trial: the phase fails with
  // the reason, saying how much had gone out (the service drops it).
  ASSERT_TRUE(d.Send(d.Command("stream1", 2, msg::PHASE_EXECUTE, scene, 13)));
  Seen two;
  ASSERT_TRUE(WaitForFirstThirty(d, live, 2, &two)) << two.logged.size() << " samples logged";
  Go(2);
  const auto crashed = d.FinalStatus(2, 20s);
  ASSERT_TRUE(crashed.has_value());
  EXPECT_EQ(crashed->state(), msg::STATE_FAILED);
  EXPECT_NE(crashed->reason().find("driver crashed: exited with status 3"), std::string::npos)
      << crashed->reason();
  EXPECT_EQ(json::parse(crashed->detail_json()).value("streamed_samples", -1), 30);
  Drain(d, live, 2, &two);
  EXPECT_FALSE(two.last_batch);  // the log never says this stream is whole

  // 3: the cell survived and restarted the driver; a trial runs whole.
  ASSERT_TRUE(d.Send(d.Command("stream1", 3, msg::PHASE_EXECUTE, scene, 7)));
  Go(3);
  const auto again = d.FinalStatus(3, 30s);
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->state(), msg::STATE_EXECUTED) << again->reason();
  EXPECT_EQ(again->samples(), 60u);
}

}  // namespace
}  // namespace arena::executors
