// The shared DDS set-up in one process: two participants on a test-unique
// domain over the local-only transports.
#include <gtest/gtest.h>

#include <memory>
#include <thread>
#include <vector>

#include "arena/schemas/arena.h"
#include "arena/schemas/dds.hpp"
#include "test_support.hpp"

namespace arena {
namespace {

using namespace std::chrono_literals;

dds::ParticipantOptions Named(const std::string& name, int salt) {
  dds::ParticipantOptions o;
  o.domain_id = test::TestDomain(salt);
  o.name = name;
  return o;
}

TEST(DdsParticipant, PeersAreParsedAndBadOnesNamed) {
  EXPECT_EQ(dds::ParsePeers("10.0.0.2, hostb:7410"),
            (std::vector<std::string>{"10.0.0.2", "hostb:7410"}));
  EXPECT_THROW(dds::ParsePeers(""), dds::DdsError);
  try {
    dds::ParsePeers("a:99999");
    FAIL();
  } catch (const dds::DdsError& e) {
    EXPECT_NE(std::string(e.what()).find("--peers"), std::string::npos) << e.what();
  }
  dds::ParticipantOptions bad = Named("x", 0);
  bad.domain_id = 300;
  EXPECT_THROW(dds::Participant p(bad), dds::DdsError);
  bad.domain_id = 5;
  bad.network.security_dir = "/nonexistent";
  EXPECT_THROW(dds::Participant p(bad), dds::DdsError);
}

TEST(DdsParticipant, GroundTruthArrivesCompleteAndInOrder) {
  dds::Participant a(Named("arena.test.a", 1));
  dds::Participant b(Named("arena.test.b", 1));
  dds::WriterOptions cell;
  dds::Writer<msg::GroundTruth> writer(a, cell);
  dds::Reader<msg::GroundTruth> reader(b);
  ASSERT_TRUE(writer.WaitForMatched(1, 10s));
  ASSERT_TRUE(reader.WaitForMatched(1, 10s));
  ASSERT_TRUE(b.WaitForPeer("arena.test.a", 10s));
  // More batches than the bounded history, spread over more trials
  // (instances) than it holds: the writer must be throttled, never lose.
  const int kBatches = 600;
  for (int i = 0; i < kBatches; ++i) {
    msg::GroundTruth g;
    g.trial_id(1 + i / 30);
    g.batch(static_cast<std::uint32_t>(i));
    g.first_sample(static_cast<std::uint32_t>(25 * i));
    g.samples().resize(25);
    for (int k = 0; k < 25; ++k) {
      g.samples()[k].t((25 * i + k) / 250.0);
      g.samples()[k].object_pose() = {0, 0, 0, 1, 0, 0, 0};
      g.samples()[k].pusher_pose() = {0, 0, 0, 1, 0, 0, 0};
    }
    ASSERT_TRUE(writer.Write(g)) << "batch " << i;
  }
  for (int i = 0; i < kBatches; ++i) {
    auto g = reader.Take(10s);
    ASSERT_TRUE(g) << "batch " << i << " missing";
    EXPECT_EQ(g->batch(), static_cast<std::uint32_t>(i));
    EXPECT_EQ(g->schema_version(), msg::SCHEMA_VERSION);
  }
  EXPECT_FALSE(reader.Take(50ms));
}

TEST(DdsParticipant, LateReaderGetsTheLastAnnouncement) {
  dds::Participant a(Named("arena.test.cell", 2));
  dds::WriterOptions cell;
  dds::Writer<msg::CellAnnounce> writer(a, cell);
  msg::CellAnnounce first;
  first.cell_id("c1");
  first.speed(1);
  ASSERT_TRUE(writer.Write(first));
  msg::CellAnnounce second = first;
  second.speed(2);
  ASSERT_TRUE(writer.Write(second));

  dds::Participant b(Named("arena.test.service", 2));
  dds::Reader<msg::CellAnnounce> reader(b);
  auto got = reader.Take(10s);
  ASSERT_TRUE(got);
  EXPECT_EQ(got->cell_id(), "c1");
  EXPECT_EQ(got->speed(), 2);  // keep-last 1
  EXPECT_FALSE(reader.Take(200ms));
}

// Issue 27: one loop serving several topics waits on all of them through a
// doorbell its readers ring; a wait of 0 is a poll.
TEST(DdsParticipant, ADoorbellWakesOnAnyOfItsReaders) {
  auto bell = std::make_shared<dds::Doorbell>();
  EXPECT_FALSE(bell->Wait(0ms));
  EXPECT_FALSE(bell->Wait(20ms));  // not rung: the wait times out
  bell->Ring();
  EXPECT_TRUE(bell->Rung());
  EXPECT_TRUE(bell->Rung());  // looking does not clear it
  EXPECT_TRUE(bell->Wait(0ms));
  EXPECT_FALSE(bell->Rung());  // a wait does

  dds::Participant a(Named("arena.test.cell", 7));
  dds::Participant b(Named("arena.test.service", 7));
  dds::ReaderOptions rung;
  rung.doorbell = bell;
  dds::Reader<msg::TrialStatus> statuses(b, rung);
  dds::Reader<msg::GroundTruth> truth(b, rung);
  dds::Writer<msg::TrialStatus> status_writer(a);
  dds::Writer<msg::GroundTruth> truth_writer(a);
  ASSERT_TRUE(status_writer.WaitForMatched(1, 10s));
  ASSERT_TRUE(truth_writer.WaitForMatched(1, 10s));
  EXPECT_FALSE(statuses.Take(0ns));  // a poll of an empty queue

  msg::GroundTruth g;
  g.trial_id(7);
  ASSERT_TRUE(truth_writer.Write(g));
  const auto start = std::chrono::steady_clock::now();
  ASSERT_TRUE(bell->Wait(10s));  // woken by the ground truth, not a status
  EXPECT_LT(std::chrono::steady_clock::now() - start, 9s);
  const auto batches = truth.TakeAll();
  ASSERT_EQ(batches.size(), 1u);  // queued before the ring
  EXPECT_EQ(batches[0].trial_id(), 7u);
  EXPECT_FALSE(statuses.Take(0ns));

  msg::TrialStatus st;
  st.trial_id(8);
  ASSERT_TRUE(status_writer.Write(st));
  ASSERT_TRUE(bell->Wait(10s));
  const auto taken = statuses.Take(0ns);
  ASSERT_TRUE(taken);
  EXPECT_EQ(taken->trial_id(), 8u);
}

TEST(DdsParticipant, ParticipantLeavingIsReported) {
  dds::Participant b(Named("arena.test.watch", 3));
  dds::Reader<msg::TrialStatus> reader(b);
  {
    dds::Participant a(Named("arena.test.leaver", 3));
    dds::Writer<msg::TrialStatus> writer(a);
    ASSERT_TRUE(b.WaitForPeer("arena.test.leaver", 10s));
  }
  const auto deadline = std::chrono::steady_clock::now() + 5s;
  bool left = false;
  while (!left && std::chrono::steady_clock::now() < deadline) {
    auto e = b.NextPeerEvent(100ms);
    left = e && e->kind == dds::PeerEvent::Kind::kParticipantLeft &&
           e->participant == "arena.test.leaver";
  }
  EXPECT_TRUE(left);
}

}  // namespace
}  // namespace arena

namespace arena {
namespace {

using namespace std::chrono_literals;

// Every topic is keyed; Fast DDS's default of 10 instances would stall a
// deployment after ten cells or ten trials.
TEST(DdsParticipant, ManyCellsAndTrialsDoNotStall) {
  dds::ParticipantOptions o;
  o.domain_id = test::TestDomain(6);
  o.name = "arena.test.many-cells";
  dds::Participant a(o);
  o.name = "arena.test.many-service";
  dds::Participant b(o);
  dds::Writer<msg::CellAnnounce> announce(a);
  dds::Writer<msg::TrialStatus> status(a);
  dds::Reader<msg::CellAnnounce> announcements(b);
  dds::Reader<msg::TrialStatus> statuses(b);
  ASSERT_TRUE(announce.WaitForMatched(1, 10s));
  ASSERT_TRUE(status.WaitForMatched(1, 10s));
  for (int i = 0; i < 30; ++i) {
    msg::CellAnnounce c;
    std::string id = "c";
    id += std::to_string(i);  // (operator+ on a literal trips GCC 12's -Wrestrict)
    c.cell_id(id);
    ASSERT_TRUE(announce.Write(c)) << i;
    msg::TrialStatus s;
    s.trial_id(static_cast<std::uint64_t>(i));
    s.state(msg::STATE_EXECUTED);
    ASSERT_TRUE(status.Write(s)) << i;
  }
  for (int i = 0; i < 30; ++i) {
    ASSERT_TRUE(announcements.Take(5s)) << "announcement " << i;
    auto s = statuses.Take(5s);
    ASSERT_TRUE(s) << "status " << i;
    EXPECT_EQ(s->trial_id(), static_cast<std::uint64_t>(i));
  }
}

// A cell reads PusherCommand through a content filter on its cell id, and
// the controller's writer evaluates it: a command crosses to its own cell
// only (the others leave sequence gaps at that reader instead of arriving).
// A reader filtering in its listener alone gets every cell's commands.
TEST(DdsParticipant, ACellTakesOnlyItsOwnCommandsAndTheWriterSendsNoOthers) {
  dds::Participant controller(Named("arena.controller.filter", 6));
  dds::Writer<msg::PusherCommand> writer(controller);
  std::vector<std::unique_ptr<dds::Participant>> cells;
  std::vector<std::unique_ptr<dds::Reader<msg::PusherCommand>>> readers;
  for (const char* id : {"c1", "c2", "c3"}) {
    cells.push_back(std::make_unique<dds::Participant>(Named(dds::CellParticipantName(id), 6)));
    dds::ReaderOptions o{false, id};
    o.cell_filter_in_dds = std::string(id) != "c3";  // c3: the listener alone
    readers.push_back(std::make_unique<dds::Reader<msg::PusherCommand>>(*cells.back(), o));
  }
  ASSERT_TRUE(writer.WaitForMatched(3, 10s));
  for (auto& r : readers) ASSERT_TRUE(r->WaitForMatched(1, 10s));
  std::this_thread::sleep_for(200ms);  // the writer learns the readers' filters with them
  std::vector<int> taken(3, 0);
  for (std::uint32_t k = 0; k < 20; ++k) {
    for (const char* id : {"c1", "c2", "c3"}) {
      msg::PusherCommand c;
      c.cell_id(id);
      c.answers_sample(k);
      ASSERT_TRUE(writer.Write(c));
      std::this_thread::sleep_for(1ms);
    }
    for (size_t r = 0; r < readers.size(); ++r) {
      std::string own = "c";
      own += std::to_string(r + 1);  // (operator+ on a literal trips GCC 12's -Wrestrict)
      while (auto c = readers[r]->Take(20ms)) {
        EXPECT_EQ(c->cell_id(), own) << "sample " << k;
        ++taken[r];
      }
    }
  }
  for (size_t r = 0; r < readers.size(); ++r) {
    const auto counters = readers[r]->counters();
    EXPECT_GT(taken[r], 10) << "c" << r + 1 << " (best-effort on loopback: most arrive)";
    if (r < 2) {
      EXPECT_EQ(counters.other_cell, 0u) << "c" << r + 1;
      EXPECT_GE(counters.lost, 20u) << "c" << r + 1 << ": the others' commands never crossed";
    } else {
      EXPECT_GT(counters.other_cell, 10u) << "c3 filters in its listener: the others crossed";
    }
  }
}

}  // namespace
}  // namespace arena
