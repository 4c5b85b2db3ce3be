// The packed ground-truth block "AGT2": bit-exact round trips over edge
// values (±0, denormals, the largest doubles, sign flips, random bit
// patterns), odd sample counts, fallbacks to AGT1, and corrupt packed blocks
// refused with kCorrupt and a message, never a crash or an overread (run under
// ASan: build-asan). Then the store: packed and raw chunks read the same.
#include <cfloat>
#include <cstring>
#include <limits>
#include <random>

#include <sqlite3.h>

#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeSample;

// Every double of two samples compared as bit patterns (EXPECT_EQ on doubles
// would call +0 and -0 equal).
void ExpectSameBits(const Sample& a, const Sample& b, std::size_t i) {
  std::string ea, eb;
  EncodeSamples(&a, 1, &ea);
  EncodeSamples(&b, 1, &eb);
  EXPECT_EQ(ea, eb) << "sample " << i;
}

const std::vector<double>& EdgeValues() {
  static const std::vector<double> v = {
      0.0,
      -0.0,
      std::numeric_limits<double>::denorm_min(),
      -std::numeric_limits<double>::denorm_min(),
      DBL_MIN,
      -DBL_MIN,
      DBL_MIN - std::numeric_limits<double>::denorm_min(),  // largest denormal
      DBL_MAX,
      -DBL_MAX,
      1e300,
      -1e300,
      1e-300,
      1.0,
      -1.0,
      0.1,
      1.0 / 3,
      2.0,
      4.0,
      1e-3,
      -1e-3,
      std::nextafter(1.0, 2.0),
      std::nextafter(0.0, -1.0)};
  return v;
}

// A block of n samples whose columns mix every kind of signal the packer meets:
// constants, smooth ramps and curves, noise, sign flips, edge values.
std::vector<Sample> MixedSamples(int n, std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0, 1);
  const auto& edge = EdgeValues();
  std::vector<Sample> out;
  for (int i = 0; i < n; ++i) {
    Sample s = MakeSample(i, 3);
    s.t = i / 250.0;
    s.object_pose = {0.01 * std::sin(0.3 * i), -0.0, 0.0, std::cos(0.01 * i), 0, 0,
                     std::sin(0.01 * i)};
    s.object_twist = {edge[static_cast<std::size_t>(i) % edge.size()],
                      edge[static_cast<std::size_t>(i * 7 + 3) % edge.size()],
                      std::numeric_limits<double>::denorm_min() * i,
                      DBL_MAX,
                      -DBL_MAX,
                      (i % 2) ? 1e-3 : -1e-3};
    for (auto& v : s.pusher_pose) v = noise(rng);
    for (auto& v : s.pusher_twist) {
      std::uint64_t b;
      do b = rng();
      while (((b >> 52) & 0x7FF) == 0x7FF);  // any finite bit pattern
      std::memcpy(&v, &b, 8);
    }
    s.observed_valid = (rng() % 5) != 0;
    for (auto& v : s.observed_object_pose) v = 0.001 * noise(rng) + 0.2;
    out.push_back(s);
  }
  return out;
}

std::string Raw(const std::vector<Sample>& s) {
  std::string block;
  EncodeSamples(s.data(), s.size(), &block);
  return block;
}

std::string Packed(const std::string& raw) {
  std::string out;
  EXPECT_TRUE(PackBlock(raw.data(), raw.size(), &out));
  return out;
}

TEST(PackedBlock, RoundTripIsBitExact) {
  {  // One sample: every column is "constant" and costs a kind byte more than raw.
    const std::string raw = Raw(MixedSamples(1, 5));
    std::string out;
    EXPECT_FALSE(PackBlock(raw.data(), raw.size(), &out));
    EXPECT_TRUE(out.empty());
  }
  for (int n : {2, 3, 4, 7, 250, 251}) {
    const auto in = MixedSamples(n, 7u + static_cast<std::uint32_t>(n));
    const std::string raw = Raw(in);
    std::string packed = "prefix";  // PackBlock appends
    ASSERT_TRUE(PackBlock(raw.data(), raw.size(), &packed)) << n;
    ASSERT_EQ(packed.substr(0, 10), "prefixAGT2");
    packed.erase(0, 6);
    EXPECT_EQ(UnpackBlock(packed.data(), packed.size()), raw) << n;  // byte for byte
    const auto out = DecodeSamples(packed.data(), packed.size());
    ASSERT_EQ(out.size(), in.size());
    for (std::size_t i = 0; i < in.size(); ++i) ExpectSameBits(out[i], in[i], i);
  }
}

TEST(PackedBlock, EveryEdgeValueInEveryPosition) {
  // One column walks through the edge values in each order: every pair of
  // neighbours (the predictors' inputs) appears.
  const auto& edge = EdgeValues();
  std::vector<Sample> in;
  for (std::size_t a = 0; a < edge.size(); ++a) {
    for (std::size_t b = 0; b < edge.size(); ++b) {
      Sample s = MakeSample(0, 1);
      s.t = static_cast<double>(in.size());
      s.object_pose[0] = edge[a];
      s.object_pose[1] = edge[b];
      s.contacts[0].force = {edge[b], edge[a], edge[(a + b) % edge.size()]};
      in.push_back(s);
    }
  }
  const std::string raw = Raw(in);
  const std::string packed = Packed(raw);
  EXPECT_EQ(UnpackBlock(packed.data(), packed.size()), raw);
}

TEST(PackedBlock, ShrinksSmoothAndConstantColumns) {
  std::vector<Sample> in;
  for (int i = 0; i < 250; ++i) in.push_back(MakeSample(i, 3));
  const std::string raw = Raw(in);
  const std::string packed = Packed(raw);
  EXPECT_LT(packed.size() * 3, raw.size()) << raw.size() << " -> " << packed.size();
}

TEST(PackedBlock, FallsBackWhenItCannotHelp) {
  std::string out = "untouched";
  // Mixed shapes within one block: AGT1 stays.
  std::vector<Sample> mixed = {MakeSample(0, 3), MakeSample(1, 2)};
  std::string raw = Raw(mixed);
  EXPECT_FALSE(PackBlock(raw.data(), raw.size(), &out));
  mixed = {MakeSample(0, 3), MakeSample(1, 3)};
  mixed[1].observed_finger_wrenches.pop_back();
  raw = Raw(mixed);
  EXPECT_FALSE(PackBlock(raw.data(), raw.size(), &out));
  // Random finite bit patterns everywhere do not get smaller.
  std::mt19937_64 rng(3);
  auto random_double = [&rng] {
    std::uint64_t b;
    do b = rng();
    while (((b >> 52) & 0x7FF) == 0x7FF);
    double d;
    std::memcpy(&d, &b, 8);
    return d;
  };
  std::vector<Sample> noise(50, MakeSample(0, 2));
  for (auto& s : noise) {
    s.t = random_double();
    for (auto* a : {&s.object_pose, &s.pusher_pose, &s.observed_object_pose})
      for (auto& v : *a) v = random_double();
    for (auto* a : {&s.object_twist, &s.pusher_twist, &s.observed_pusher_wrench})
      for (auto& v : *a) v = random_double();
    for (auto& c : s.contacts) {
      for (auto& v : c.force) v = random_double();
      for (auto& v : c.torque) v = random_double();
    }
    for (auto& v : s.observed_finger_wrenches) v = random_double();
  }
  raw = Raw(noise);
  EXPECT_FALSE(PackBlock(raw.data(), raw.size(), &out));
  // Not an AGT1 block at all.
  EXPECT_FALSE(PackBlock("AGT2xxxx", 8, &out));
  EXPECT_EQ(out, "untouched");
}

void ExpectCorrupt(const std::string& block, const std::string& fragment) {
  try {
    DecodeSamples(block.data(), block.size());
    ADD_FAILURE() << "decoded a corrupt block; expected '" << fragment << "'";
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), StoreError::Kind::kCorrupt);
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(PackedBlock, CorruptBlocksAreRefusedWithAReason) {
  const std::string packed = Packed(Raw(MixedSamples(9, 1)));
  for (std::size_t n = 0; n < packed.size(); ++n) {
    const std::string prefix = packed.substr(0, n);  // own allocation: ASan sees overreads
    EXPECT_THROW(DecodeSamples(prefix.data(), prefix.size()), StoreError) << n;
  }
  ExpectCorrupt(packed + "x", "trailing bytes");
  std::string m = packed;
  const std::uint32_t huge = 4000000000u;
  std::memcpy(m.data() + 4, &huge, 4);
  ExpectCorrupt(m, "claims 4000000000 samples");
  m = packed;
  const std::uint32_t zero = 0;
  std::memcpy(m.data() + 4, &zero, 4);
  ExpectCorrupt(m, "claims 0 samples");
  m = packed;
  m[10] = 1;
  ExpectCorrupt(m, "unknown flags");
  m = packed;
  m[12] = 9;  // the observed_valid column's kind
  ExpectCorrupt(m, "unknown byte-column kind 9");
  // The largest shape with the largest count would need > 256 MiB.
  m = packed;
  const std::uint32_t many = kMaxBlockSamples;
  std::memcpy(m.data() + 4, &many, 4);
  m[8] = m[9] = static_cast<char>(255);
  ExpectCorrupt(m, "MiB");
}

TEST(PackedBlock, BadResidualLengthIsRefused) {
  // Two samples, one contact, no finger values: all columns are found in order
  // after the byte columns; make the first non-constant double column's
  // length nibble 15.
  std::vector<Sample> in = {MakeSample(0, 1), MakeSample(1, 1)};
  in[1].t = 0.5;
  const std::string packed = Packed(Raw(in));
  // Byte columns: observed_valid and one mode, each kind + 1 or 2 bytes; then t's column.
  std::size_t p = 12;
  for (int c = 0; c < 2; ++c) p += packed[p] == 0 ? 2 : 3;
  ASSERT_TRUE(packed[p] == 1 || packed[p] == 2) << int(packed[p]);
  std::string m = packed;
  m[p + 1] = static_cast<char>(0xFF);
  ExpectCorrupt(m, "residual of 15 bytes");
  m = packed;
  m[p] = 7;
  ExpectCorrupt(m, "unknown column kind 7");
}

TEST(PackedBlock, MutatedAndRandomBlocksNeverCrash) {
  std::mt19937 rng(54321);
  const std::string packed = Packed(Raw(MixedSamples(40, 2)));
  int refused = 0, decoded = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::string m = packed;
    const int flips = 1 + static_cast<int>(rng() % 8);
    for (int f = 0; f < flips; ++f) m[4 + rng() % (m.size() - 4)] = static_cast<char>(rng());
    if (trial % 3 == 0) m.resize(4 + rng() % (m.size() - 3));
    try {
      DecodeSamples(m.data(), m.size());
      ++decoded;
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), StoreError::Kind::kCorrupt);
      ++refused;
    }
  }
  for (int trial = 0; trial < 2000; ++trial) {
    std::string r(12 + rng() % 2000, '\0');
    for (auto& ch : r) ch = static_cast<char>(rng());
    r.replace(0, 4, "AGT2");
    const std::uint32_t count = 1 + rng() % 300;
    std::memcpy(r.data() + 4, &count, 4);
    try {
      DecodeSamples(r.data(), r.size());
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), StoreError::Kind::kCorrupt);
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(decoded, 0);
}

std::string FirstChunkMagic(const std::string& path) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
  sqlite3_stmt* s = nullptr;
  sqlite3_prepare_v2(db, "SELECT substr(data, 1, 4) FROM gt_chunks ORDER BY id LIMIT 1", -1, &s,
                     nullptr);
  std::string out;
  if (sqlite3_step(s) == SQLITE_ROW) {
    out.assign(static_cast<const char*>(sqlite3_column_blob(s, 0)), 4);
  }
  sqlite3_finalize(s);
  sqlite3_close(db);
  return out;
}

// The store packs by default; raw chunks (what stores written before AGT2
// hold, and pack_chunks = false) read back identically; a chunk whose shape
// changes mid-way stays raw.
TEST(PackedBlock, StoreReadsPackedAndRawChunksAlike) {
  const auto in = MixedSamples(600, 11);
  std::vector<std::vector<Sample>> read;
  for (int variant = 0; variant < 3; ++variant) {
    testing::TempDir dir;
    const std::string path = dir.File("s.db");
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point", "line", "patch"});
    store->CreateCampaign(testing::MakeCampaign(), testing::MakeTrials(1));
    auto t = store->ClaimNextTrial("c");
    ASSERT_TRUE(t);
    IngestOptions o;
    o.pack_chunks = variant != 1;
    auto ingest = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites(), o);
    std::vector<Sample> samples = in;
    if (variant == 2) samples[3].contacts.pop_back();  // first chunk not uniform
    for (const auto& s : samples) ingest->Add(s);
    ingest->Finish();
    EXPECT_EQ(FirstChunkMagic(path), variant == 0 ? "AGT2" : "AGT1") << variant;
    const auto gt = store->ReadGroundTruth(t->trial_id);
    ASSERT_EQ(gt.samples.size(), in.size());
    for (std::size_t i = 0; i < in.size(); ++i) ExpectSameBits(gt.samples[i], samples[i], i);
    EXPECT_TRUE(store->CheckInvariants().empty());
    EXPECT_EQ(store->IntegrityCheck(), "ok");
  }
}

// A version-3 store (before AGT2) with raw chunks: a read-write open migrates
// it to the current version and its ground truth reads the same; new ingest
// into it is packed.
TEST(PackedBlock, VersionThreeStoreMigratesAndReads) {
  testing::TempDir dir;
  const std::string path = dir.File("v3.db");
  const auto in = MixedSamples(300, 4);
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point", "line", "patch"});
    store->CreateCampaign(testing::MakeCampaign(), testing::MakeTrials(2));
    auto t = store->ClaimNextTrial("c");
    IngestOptions raw;
    raw.pack_chunks = false;
    auto ingest = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites(), raw);
    for (const auto& s : in) ingest->Add(s);
    ingest->Finish();
  }
  {
    sqlite3* db = nullptr;
    sqlite3_open(path.c_str(), &db);
    ASSERT_EQ(sqlite3_exec(
                  db,
                  (std::string("BEGIN;") + testing::kUndoMigration10 + testing::kUndoMigration14 +
                   testing::kUndoMigration15 + testing::kUndoMigration7 + testing::kUndoMigration5 +
                   " DELETE FROM schema_migrations WHERE version > 3;"
                   " PRAGMA user_version = 3; COMMIT;")
                      .c_str(),
                  nullptr, nullptr, nullptr),
              SQLITE_OK);
    sqlite3_close(db);
  }
  StoreOptions ro;
  ro.read_only = true;
  EXPECT_THROW(Store::Open(path, ro), StoreError);  // "open it read-write once"
  StoreOptions migrate;  // migration 6 reads the stored scenes' contacts through the opener
  migrate.scene_facts = [](const std::string&) { return testing::SceneFactsFor(); };
  auto store = Store::Open(path, migrate);
  EXPECT_EQ(store->FileSchemaVersion(), Store::SchemaVersion());
  EXPECT_GE(Store::SchemaVersion(), 4);
  const auto gt = store->ReadGroundTruth(1);
  ASSERT_EQ(gt.samples.size(), in.size());
  for (std::size_t i = 0; i < in.size(); ++i) ExpectSameBits(gt.samples[i], in[i], i);
  auto t = store->ClaimNextTrial("c");
  ASSERT_TRUE(t);
  auto ingest = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites());
  for (const auto& s : in) ingest->Add(s);
  ingest->Finish();
  EXPECT_EQ(store->ReadGroundTruth(t->trial_id).samples.size(), in.size());
  EXPECT_TRUE(store->CheckInvariants().empty());
}

}  // namespace
}  // namespace arena::db
