// The ground-truth codec (schemas/ground_truth.hpp) shared by cell and service.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include <fastdds/rtps/common/SerializedPayload.h>

#include "arena/schemas/arena.h"
#include "arena/schemas/arenaPubSubTypes.h"
#include "arena/schemas/ground_truth.hpp"

namespace arena::dds {
namespace {

mechanics::TrajectorySample Truth() {
  mechanics::TrajectorySample s;
  s.t = 0.124;
  s.position = {0.01, -0.02, 0.03};
  s.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  s.velocity = {0.1, 0.2, 0.3};
  s.angular_velocity = {-1, 0.5, 2};
  s.pusher_position = {0, 0, -0.05};
  s.pusher_force = {0.5, 0, 11.9};
  s.contacts.resize(3);
  s.contacts[1].normal_force = 10;
  s.contacts[1].tangential_force = {0, 0.1, -5};
  s.contacts[1].torque = {0.001, 0, 0};
  s.contacts[1].mode = mechanics::ContactMode::kSlide;
  s.contacts[2].mode = mechanics::ContactMode::kStick;
  return s;
}

TEST(GroundTruthCodec, RoundTripsTruthPusherAndObservation) {
  PusherState pusher;
  pusher.position = {0, 0, -0.05};
  pusher.velocity = {0, 0, 0.01};
  Observation seen;
  seen.valid = true;
  seen.t = 0.1;
  seen.position = {0.011, -0.02, 0.03};
  seen.pusher_wrench << 1, 2, 3, 4, 5, 6;
  seen.finger_wrenches = {Wrench::Constant(1.5), Wrench::Constant(-2)};
  msg::GroundTruthSample m;
  EncodeSample(Truth(), pusher, seen, &m);
  EXPECT_EQ(CheckSample(m), "");
  PusherState p2;
  Observation o2;
  const mechanics::TrajectorySample back = DecodeSample(m, &p2, &o2);
  const mechanics::TrajectorySample truth = Truth();
  EXPECT_EQ(back.t, truth.t);
  EXPECT_EQ(back.position, truth.position);
  EXPECT_EQ(back.orientation.coeffs(), truth.orientation.coeffs());
  EXPECT_EQ(back.angular_velocity, truth.angular_velocity);
  EXPECT_EQ(back.pusher_force, truth.pusher_force);
  ASSERT_EQ(back.contacts.size(), 3u);
  EXPECT_EQ(back.contacts[1].tangential_force, truth.contacts[1].tangential_force);
  EXPECT_EQ(back.contacts[1].mode, mechanics::ContactMode::kSlide);
  EXPECT_EQ(p2.velocity, pusher.velocity);
  EXPECT_TRUE(o2.valid);
  EXPECT_EQ(o2.t, 0.1);
  EXPECT_EQ(o2.pusher_wrench, seen.pusher_wrench);
  ASSERT_EQ(o2.finger_wrenches.size(), 2u);
  EXPECT_EQ(o2.finger_wrenches[1], seen.finger_wrenches[1]);
}

TEST(GroundTruthCodec, MalformedSamplesAreNamed) {
  msg::GroundTruthSample m;
  EncodeSample(Truth(), PusherState{}, Observation{}, &m);
  EXPECT_EQ(CheckSample(m), "");
  EXPECT_FALSE(m.observed_valid());
  msg::GroundTruthSample nan = m;
  nan.object_pose()[1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(CheckSample(nan), "samples[].object_pose[1]: not finite");
  msg::GroundTruthSample q = m;
  q.object_pose()[3] = 2;
  EXPECT_NE(CheckSample(q).find("quaternion"), std::string::npos);
  msg::GroundTruthSample fingers = m;
  fingers.observed_valid(true);
  fingers.observed_finger_wrenches().resize(5);
  EXPECT_NE(CheckSample(fingers).find("multiple of 6"), std::string::npos);

  msg::GroundTruth batch;
  batch.first_sample(25);
  batch.samples().push_back(m);
  EXPECT_NE(CheckBatch(batch, 0).find("first_sample"), std::string::npos);
  EXPECT_EQ(CheckBatch(batch, 25), "");
  batch.samples().push_back(m);  // same t twice
  EXPECT_NE(CheckBatch(batch, 25).find("not increasing"), std::string::npos);
}

// Found by tests/fuzz/ground_truth_fuzz.cpp: CheckSample does not look at the
// observed fields of a dropped observation, so DecodeSample must not pass
// whatever a sender left there on as values.
TEST(GroundTruthCodec, DroppedObservationDecodesToZeroWhateverTheFieldsHold) {
  msg::GroundTruthSample m;
  EncodeSample(Truth(), PusherState{}, Observation{}, &m);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  m.observed_valid(false);
  m.observed_t(nan);
  m.observed_object_pose() = {nan, 1e308, -0.0, 2, 0, 0, 0};
  m.observed_pusher_wrench() = {nan, nan, std::numeric_limits<double>::infinity(), 0, 0, 0};
  m.observed_finger_wrenches().assign(12, nan);
  ASSERT_EQ(CheckSample(m), "");
  Observation seen;
  seen.valid = true;
  seen.finger_wrenches = {Wrench::Ones()};
  DecodeSample(m, nullptr, &seen);
  EXPECT_FALSE(seen.valid);
  EXPECT_EQ(seen.t, 0.0);
  EXPECT_TRUE(seen.position.isZero());
  EXPECT_TRUE(seen.pusher_wrench.isZero());
  EXPECT_TRUE(seen.finger_wrenches.empty());
}

// Replays what the fuzzer found (tests/fuzz/crashers/ground_truth_fuzz/) along
// the service's path: CDR bytes -> type support -> CheckBatch -> DecodeSample.
TEST(GroundTruthCodec, FuzzCrashersAreHandled) {
  const std::filesystem::path dir =
      std::filesystem::path(ARENA_SOURCE_DIR) / "tests/fuzz/crashers/ground_truth_fuzz";
  ASSERT_TRUE(std::filesystem::exists(dir));
  int replayed = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
    eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<uint32_t>(bytes.size() + 4));
    payload.data[1] = 0x01;  // CDR, little endian
    std::memcpy(payload.data + 4, bytes.data(), bytes.size());
    payload.length = static_cast<uint32_t>(bytes.size() + 4);
    msg::GroundTruthPubSubType type;
    msg::GroundTruth batch;
    bool decoded = false;
    try {
      decoded = type.deserialize(&payload, &batch);
    } catch (const std::exception&) {
    }
    ++replayed;
    if (!decoded || !CheckBatch(batch, batch.first_sample()).empty()) continue;
    for (const auto& m : batch.samples()) {
      PusherState pusher;
      Observation seen;
      const auto s = DecodeSample(m, &pusher, &seen);
      EXPECT_TRUE(std::isfinite(s.t) && s.position.allFinite() && s.velocity.allFinite())
          << entry.path();
      EXPECT_TRUE(std::isfinite(seen.t) && seen.position.allFinite() &&
                  seen.pusher_wrench.allFinite())
          << entry.path();
      for (const auto& w : seen.finger_wrenches) EXPECT_TRUE(w.allFinite()) << entry.path();
    }
  }
  EXPECT_GT(replayed, 0);
}

}  // namespace
}  // namespace arena::dds
