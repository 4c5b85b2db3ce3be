// Per-contact and object outcomes: the pure function on hand-made motions
// whose answers are known, what the ingest stores, the parameter columns of
// the result views, and reading a store whose directory cannot be written.
#include <sqlite3.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <nlohmann/json.hpp>

#include "arena/db/outcomes.hpp"
#include "arena/db/query.hpp"
#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeTrials;
using testing::RunTrialToDone;
using testing::SceneJson;
using testing::TempDir;

// The object slides along +z between two fixed fingers at 1 cm/s for 1 s
// (250 Hz), turning about z at 0.1 rad/s; the pusher pushes it from below.
std::vector<Sample> SlidingUp(ContactMode finger_mode, bool release_at_end) {
  std::vector<Sample> out;
  for (int i = 0; i <= 250; ++i) {
    Sample s;
    s.t = i / 250.0;
    const double angle = 0.1 * s.t;
    s.object_pose = {0, 0, 0.01 * s.t, std::cos(angle / 2), 0, 0, std::sin(angle / 2)};
    s.object_twist = {0, 0, 0.01, 0, 0, 0.1};
    s.pusher_pose = {0, 0, -0.05 + 0.01 * s.t, 1, 0, 0, 0};
    s.pusher_twist = {0, 0, 0.01, 0, 0, 0};
    for (int f = 0; f < 2; ++f) {
      ContactWrench w;
      w.force = {f == 0 ? 10.0 : -10.0, 0, -1};
      w.mode = finger_mode;
      if (release_at_end && i == 250 && f == 1) w.mode = ContactMode::kSeparate;
      s.contacts.push_back(w);
    }
    ContactWrench p;
    p.force = {0, 0, 2};
    p.mode = ContactMode::kStick;
    s.contacts.push_back(p);
    out.push_back(s);
  }
  return out;
}

TEST(Outcomes, SlipDistanceRotationTranslationAndGraspFromTheSamples) {
  const auto sites = testing::SceneSites();  // the caller's facts of SceneJson()
  ASSERT_EQ(sites.size(), 3u);
  EXPECT_EQ(sites[0].name, "left");
  EXPECT_TRUE(sites[2].pusher);
  const auto o = ComputeOutcome(SlidingUp(ContactMode::kSlide, false), sites);
  ASSERT_EQ(o.contacts.size(), 3u);
  // Finger at x = -0.025: the object's point there moves (0, -0.0025, 0.01) m/s
  // relative to it (v + w x r), all tangential to the x normal: 1 s of it.
  const double expected = std::hypot(0.01, 0.1 * 0.025);
  EXPECT_NEAR(*o.contacts[0].slip_distance, expected, 1e-9);
  EXPECT_NEAR(*o.contacts[1].slip_distance, expected, 1e-9);
  EXPECT_DOUBLE_EQ(o.contacts[0].slide_fraction, 1.0);
  EXPECT_NEAR(o.contacts[0].max_normal_force, 10.0, 1e-12);
  // The pusher moves with the object along z: no slip at its contact point
  // (on the rotation axis).
  EXPECT_NEAR(*o.contacts[2].slip_distance, 0.0, 1e-12);
  EXPECT_DOUBLE_EQ(o.contacts[2].stick_fraction, 1.0);
  EXPECT_NEAR((*o.net_translation)[2], 0.01, 1e-12);
  EXPECT_NEAR((*o.net_rotation)[2], 0.1, 1e-9);
  EXPECT_NEAR((*o.net_rotation)[0], 0.0, 1e-12);
  EXPECT_EQ(o.grasp_kept, true);

  const auto released = ComputeOutcome(SlidingUp(ContactMode::kStick, true), sites);
  EXPECT_EQ(released.grasp_kept, false);
  EXPECT_NEAR(released.contacts[1].separate_fraction, 1.0 / 251, 1e-12);
  // Accumulating sample by sample gives the same answer as the whole.
  OutcomeAccumulator acc(sites);
  for (const auto& s : SlidingUp(ContactMode::kSlide, false)) acc.Add(s);
  EXPECT_EQ(*acc.Result().contacts[0].slip_distance, *o.contacts[0].slip_distance);
}

TEST(Outcomes, UnknownGeometryKeepsFractionsWithoutSlip) {
  const auto o = ComputeOutcome(SlidingUp(ContactMode::kSlide, false), {});
  ASSERT_EQ(o.contacts.size(), 3u);
  EXPECT_EQ(o.contacts[0].name, "contact0");
  EXPECT_FALSE(o.contacts[0].slip_distance.has_value());
  EXPECT_DOUBLE_EQ(o.contacts[0].slide_fraction, 1.0);
  EXPECT_FALSE(o.grasp_kept.has_value());
  EXPECT_TRUE(ComputeOutcome({}, {}).contacts.empty());
}

QueryResult Query(const std::string& path, const std::string& sql, const QueryFilter& f = {}) {
  StoreOptions ro;
  ro.read_only = true;
  return RunQuery(*Store::Open(path, ro), sql, f);
}

TEST(ResultViews, ParametersAreColumnsAndOutcomesAreStoredPerContact) {
  TempDir dir;
  const auto path = dir.File("v.db");
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    auto trials = MakeTrials(4);
    for (int i = 0; i < 4; ++i) {
      trials[i].params_json = nlohmann::json({{"pivot_offset", i % 2 ? 0.01 : 0.0},
                                              {"push_direction", {0, 0, 1}},
                                              {"grip_force", 5.0 + i}})
                                  .dump();
    }
    store->CreateCampaign(MakeCampaign("a"), trials);
    // A second campaign brings another name; the first campaign's rows get NULL there.
    auto more = MakeTrials(1);
    more[0].params_json = R"({"object_mass": 0.3, "finger_length": 0.02})";
    store->CreateCampaign(MakeCampaign("b"), more);
    for (int i = 0; i < 4; ++i) {
      auto t = store->ClaimNextTrial("c");
      auto ingest = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites());
      ingest->Add(SlidingUp(ContactMode::kSlide, i == 3));
      ingest->Finish();
    }
    EXPECT_TRUE(store->CheckInvariants().empty());
  }
  QueryFilter f;
  f.where = "pivot_offset > 0";
  const auto rows = Query(path, "", f);
  EXPECT_EQ(rows.rows.size(), 2u);
  const auto cols = Query(path, "SELECT * FROM trial_results LIMIT 1").columns;
  for (const char* c : {"pivot_offset", "push_direction", "finger_length", "net_rz", "grasp_kept"})
    EXPECT_NE(std::find(cols.begin(), cols.end(), c), cols.end()) << c;
  EXPECT_EQ(std::count(cols.begin(), cols.end(), "grip_force"), 1);
  const auto kept = Query(path,
                          "SELECT grasp_kept, count(*) FROM trial_results WHERE campaign_id = 1"
                          " AND samples IS NOT NULL GROUP BY grasp_kept ORDER BY grasp_kept");
  ASSERT_EQ(kept.rows.size(), 2u);
  EXPECT_EQ(std::get<std::int64_t>(kept.rows[0][1]), 1);  // the released one
  // "Which grip force made the fingers slip?"
  const auto slip = Query(path,
                          "SELECT grip_force, sum(slip_distance_m) AS slip FROM contact_results"
                          " WHERE role = 'finger' GROUP BY grip_force ORDER BY grip_force");
  ASSERT_EQ(slip.rows.size(), 4u);
  EXPECT_NEAR(std::get<double>(slip.rows[0][1]), 2 * std::hypot(0.01, 0.0025), 1e-9);
  const auto pusher = Query(path,
                            "SELECT count(*) FROM contact_results WHERE contact_name = 'pusher'"
                            " AND pivot_offset > 0");
  EXPECT_EQ(std::get<std::int64_t>(pusher.rows[0][0]), 2);
}

// A store written before schema version 6 gets the outcomes of its stored
// streams and its parameter columns on the first read-write open.
TEST(ResultViews, MigrationSixComputesOutcomesOfStoredStreams) {
  TempDir dir;
  const auto path = dir.File("v5.db");
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    auto trials = MakeTrials(2);
    trials[1].params_json = R"({"pivot_offset": 0.01})";
    store->CreateCampaign(MakeCampaign("old"), trials);
    auto t = store->ClaimNextTrial("c");
    auto ingest = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites());
    ingest->Add(SlidingUp(ContactMode::kSlide, false));
    ingest->Finish();
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  // Later migrations (7 adaptive, 10 backends) add columns, which cannot be
  // re-added: undo them too, so the store really is at version 5.
  const std::string back_to_5 =
      std::string("BEGIN;") + testing::kUndoMigration7 + testing::kUndoMigration10 +
      testing::kUndoMigration14 + testing::kUndoMigration15 +
      " DROP VIEW contact_results; DROP VIEW trial_results;"
      " DROP TABLE contact_outcomes; DROP TABLE campaign_parameters;"
      " ALTER TABLE gt_summary DROP COLUMN net_dx; ALTER TABLE gt_summary DROP COLUMN net_dy;"
      " ALTER TABLE gt_summary DROP COLUMN net_dz; ALTER TABLE gt_summary DROP COLUMN net_rx;"
      " ALTER TABLE gt_summary DROP COLUMN net_ry; ALTER TABLE gt_summary DROP COLUMN net_rz;"
      " ALTER TABLE gt_summary DROP COLUMN grasp_kept;"
      " CREATE VIEW trial_results AS SELECT t.id AS trial_id, t.campaign_id FROM trials t;"
      " DELETE FROM schema_migrations WHERE version > 5; PRAGMA user_version = 5; COMMIT;";
  ASSERT_EQ(sqlite3_exec(db, back_to_5.c_str(), nullptr, nullptr, nullptr), SQLITE_OK)
      << sqlite3_errmsg(db);
  sqlite3_close(db);
  // The migration reads each stored scene's contacts through its opener
  // (db reads no scene): without that reader the open is refused, unchanged.
  try {
    Store::Open(path);
    ADD_FAILURE() << "opened without StoreOptions::scene_facts";
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), StoreError::Kind::kIo);
    EXPECT_NE(std::string(e.what()).find("scene_facts"), std::string::npos) << e.what();
  }
  {
    sqlite3* raw = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &raw), SQLITE_OK);
    sqlite3_stmt* st = nullptr;
    sqlite3_prepare_v2(raw, "PRAGMA user_version", -1, &st, nullptr);
    ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
    EXPECT_EQ(sqlite3_column_int(st, 0), 5);
    sqlite3_finalize(st);
    sqlite3_close(raw);
  }
  StoreOptions migrate;
  std::vector<std::string> read;
  migrate.scene_facts = [&read](const std::string& scene_json) {
    read.push_back(scene_json);
    return testing::SceneFactsFor();
  };
  Store::Open(path, migrate).reset();  // migrates
  EXPECT_EQ(read.size(), 1u);          // the one published stream's scene
  const auto slip = Query(path,
                          "SELECT contact_name, slip_distance_m, pivot_offset FROM"
                          " contact_results ORDER BY contact");
  ASSERT_EQ(slip.rows.size(), 3u);
  EXPECT_EQ(std::get<std::string>(slip.rows[0][0]), "left");
  EXPECT_NEAR(std::get<double>(slip.rows[0][1]), std::hypot(0.01, 0.0025), 1e-9);
  const auto kept = Query(path, "SELECT grasp_kept, net_dz FROM trial_results WHERE samples > 0");
  ASSERT_EQ(kept.rows.size(), 1u);
  EXPECT_EQ(std::get<std::int64_t>(kept.rows[0][0]), 1);
}

// A store in a directory this user cannot write (a read-only bind mount in a
// private mount namespace: root ignores permissions, so chmod proves nothing).
// Returns the exit status of `command` run with `dir` read-only, or -1.
int WithReadOnlyDirectory(const std::string& dir, const std::string& command) {
  const std::string sh = "unshare -m sh -c 'mount --bind -o ro " + dir + " " + dir + " && touch " +
                         dir + "/.w 2>/dev/null && exit 99; " + command + "'";
  const int st = std::system(sh.c_str());
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

bool CanMakeReadOnlyDirectories(const std::string& dir) {
  return WithReadOnlyDirectory(dir, "exit 0") == 0;
}

TEST(ReadOnlyDirectory, ReadsWithAndWithoutAnUnmergedWal) {
  TempDir dir;
  if (!CanMakeReadOnlyDirectories(dir.path().string()))
    GTEST_SKIP() << "cannot make a read-only directory here (needs unshare -m and mount --bind)";
  const auto path = dir.File("ro.db");
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    store->CreateCampaign(MakeCampaign("ro"), MakeTrials(3));
    RunTrialToDone(*store, *store->ClaimNextTrial("c"), 30);
  }  // closed: checkpointed, no -wal left
  ASSERT_FALSE(std::filesystem::exists(path + "-wal"));
  // The reader is this test binary itself, re-run inside the namespace.
  char self[4096];
  const auto n = ::readlink("/proc/self/exe", self, sizeof self - 1);
  ASSERT_GT(n, 0);
  self[n] = 0;
  const std::string reader = std::string(self) +
                             " --gtest_filter=ReadOnlyDirectory.ReaderChild"
                             " >/dev/null 2>&1";
  ::setenv("ARENA_RO_STORE", path.c_str(), 1);
  ::setenv("ARENA_RO_EXPECT", "3", 1);
  EXPECT_EQ(WithReadOnlyDirectory(dir.path().string(), reader), 0) << "no -wal";
  // Now with a WAL a writer left behind (its transactions only there).
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_exec(db, "PRAGMA journal_mode=WAL; PRAGMA wal_autocheckpoint=0;", nullptr, nullptr,
               nullptr);
  ASSERT_EQ(sqlite3_exec(db,
                         "INSERT INTO campaigns(name, spec_json, seed, created_at, updated_at)"
                         " VALUES('late', '{}', 1, 0, 0)",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  // Leave the WAL as a killed writer would: copy the files while it is open.
  std::filesystem::create_directories(dir.path() / "copy");
  for (const char* suffix : {"", "-wal"})
    std::filesystem::copy_file(path + suffix,
                               (dir.path() / "copy" / ("ro.db" + std::string(suffix))));
  sqlite3_close(db);
  ::setenv("ARENA_RO_STORE", (dir.path() / "copy" / "ro.db").c_str(), 1);
  ::setenv("ARENA_RO_EXPECT", "3", 1);
  ::setenv("ARENA_RO_CAMPAIGNS", "2", 1);
  EXPECT_EQ(WithReadOnlyDirectory((dir.path() / "copy").string(), reader), 0) << "with -wal";
  for (const char* v : {"ARENA_RO_STORE", "ARENA_RO_EXPECT", "ARENA_RO_CAMPAIGNS"}) ::unsetenv(v);
}

// Run by the test above inside the read-only namespace (skipped otherwise).
TEST(ReadOnlyDirectory, ReaderChild) {
  const char* path = std::getenv("ARENA_RO_STORE");
  if (!path) GTEST_SKIP() << "only run by ReadsWithAndWithoutAnUnmergedWal";
  StoreOptions ro;
  ro.read_only = true;
  auto store = Store::Open(path, ro);
  EXPECT_EQ(store->ListTrials(1).size(), std::stoul(std::getenv("ARENA_RO_EXPECT")));
  if (const char* c = std::getenv("ARENA_RO_CAMPAIGNS")) {
    EXPECT_EQ(store->ListCampaigns().size(), std::stoul(c));
  }
  EXPECT_EQ(RunQuery(*store, "SELECT count(*) FROM trial_results").rows.size(), 1u);
  if (::testing::Test::HasFailure()) std::_Exit(1);
}

}  // namespace
}  // namespace arena::db
