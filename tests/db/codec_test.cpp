// The ground-truth block codec: exact round trip, and malformed blocks
// (truncated, bit-flipped, random) are refused with kCorrupt, never a crash
// or an out-of-bounds read (run under ASan: build-asan).
#include <random>

#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeSample;

TEST(SampleCodec, RoundTripIsExact) {
  std::vector<Sample> in;
  for (int i = 0; i < 50; ++i) in.push_back(MakeSample(i, i % 5));
  in[7].observed_finger_wrenches.clear();
  in[8].contacts.clear();
  std::string block;
  EncodeSamples(in.data(), in.size(), &block);
  const auto out = DecodeSamples(block.data(), block.size());
  ASSERT_EQ(out.size(), in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    EXPECT_EQ(out[i].t, in[i].t);
    EXPECT_EQ(out[i].object_pose, in[i].object_pose);
    EXPECT_EQ(out[i].object_twist, in[i].object_twist);
    EXPECT_EQ(out[i].pusher_pose, in[i].pusher_pose);
    EXPECT_EQ(out[i].pusher_twist, in[i].pusher_twist);
    EXPECT_EQ(out[i].observed_valid, in[i].observed_valid);
    EXPECT_EQ(out[i].observed_object_pose, in[i].observed_object_pose);
    EXPECT_EQ(out[i].observed_pusher_wrench, in[i].observed_pusher_wrench);
    EXPECT_EQ(out[i].observed_finger_wrenches, in[i].observed_finger_wrenches);
    ASSERT_EQ(out[i].contacts.size(), in[i].contacts.size());
    for (std::size_t c = 0; c < in[i].contacts.size(); ++c) {
      EXPECT_EQ(out[i].contacts[c].force, in[i].contacts[c].force);
      EXPECT_EQ(out[i].contacts[c].torque, in[i].contacts[c].torque);
      EXPECT_EQ(out[i].contacts[c].mode, in[i].contacts[c].mode);
    }
  }
}

// Every prefix of a valid block is refused (seeded mutations below too).
TEST(SampleCodec, TruncatedBlocksAreRefused) {
  std::vector<Sample> in = {MakeSample(1), MakeSample(2, 0), MakeSample(3, 4)};
  std::string block;
  EncodeSamples(in.data(), in.size(), &block);
  for (std::size_t n = 0; n < block.size(); ++n) {
    const std::string prefix = block.substr(0, n);  // own allocation: ASan sees overreads
    EXPECT_THROW(DecodeSamples(prefix.data(), prefix.size()), StoreError) << n;
  }
  std::string longer = block + "x";
  EXPECT_THROW(DecodeSamples(longer.data(), longer.size()), StoreError);
}

TEST(SampleCodec, MutatedAndRandomBlocksNeverCrash) {
  std::mt19937 rng(12345);
  std::vector<Sample> in;
  for (int i = 0; i < 20; ++i) in.push_back(MakeSample(i, i % 4));
  std::string block;
  EncodeSamples(in.data(), in.size(), &block);
  int refused = 0, decoded = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::string m = block;
    const int flips = 1 + static_cast<int>(rng() % 8);
    for (int f = 0; f < flips; ++f) m[rng() % m.size()] = static_cast<char>(rng());
    if (trial % 3 == 0) m.resize(rng() % (m.size() + 1));
    try {
      const auto out = DecodeSamples(m.data(), m.size());
      ++decoded;  // flips inside doubles still decode: that is fine
      EXPECT_LE(out.size(), m.size() / 324 + 1);
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), StoreError::Kind::kCorrupt);
      ++refused;
    }
  }
  for (int trial = 0; trial < 2000; ++trial) {
    std::string r(rng() % 2000, '\0');
    for (auto& ch : r) ch = static_cast<char>(rng());
    if (trial % 2 == 0 && r.size() >= 8) r.replace(0, 4, "AGT1");
    try {
      DecodeSamples(r.data(), r.size());
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), StoreError::Kind::kCorrupt);
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(decoded, 0);
}

TEST(SampleCodec, CheckSampleNamesTheField) {
  Sample s = MakeSample(0);
  EXPECT_EQ(CheckSample(s), "");
  s.pusher_twist[4] = -std::numeric_limits<double>::infinity();
  EXPECT_EQ(CheckSample(s), "pusher_twist[4] is infinite");
  s = MakeSample(0);
  s.contacts[1].torque[0] = std::nan("");
  EXPECT_EQ(CheckSample(s), "contacts[1].torque[0] is NaN");
  s = MakeSample(0);
  s.contacts[0].mode = static_cast<ContactMode>(7);
  EXPECT_NE(CheckSample(s).find("mode"), std::string::npos);
  s = MakeSample(0);
  s.observed_finger_wrenches.resize(300);
  EXPECT_NE(CheckSample(s).find("255"), std::string::npos);
}

}  // namespace
}  // namespace arena::db
