// Issue 15 end to end: the real `arena` binary on stores made by real cells
// with drops, latency and noise. Each test runs the smoke campaign (36
// trials, ~2 s) with two simulated cells, then uses the store as a lab would.
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "arena_command_test.hpp"

namespace arena::test {
namespace {

namespace fs = std::filesystem;

std::string Source(const std::string& rel) { return std::string(ARENA_SOURCE_DIR) + "/" + rel; }

// Debian's python3 (where python3-h5py lives), else whichever is on PATH.
std::string Python() { return fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3"; }

class DatasetE2E : public ArenaCommandTest {
 protected:
  // The smoke campaign on two cells with this defect profile, into dir_/lab.db.
  void RunSmoke(const std::string& defects_file) {
    db_ = dir_ + "/lab.db";
    const auto r = Arena("run " + Source("examples/campaigns/smoke.json") + " --db " + db_ +
                         " --cells 2 --cell-defects " + defects_file);
    ASSERT_EQ(r.rc, 0) << r.err;
  }
  // read_dataset.py's exit status (0 ok, 77 reader missing) and its message.
  int ReadBack(const std::string& dir, std::string* message) {
    const std::string err = dir_ + "/read.err";
    const int st = std::system(
        (Python() + " " + Source("tests/cli/read_dataset.py") + " " + dir + " >/dev/null 2>" + err)
            .c_str());
    *message = Slurp(err);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  }
  // Exports in all three formats and reads each back; returns why HDF5 was
  // not read ("" if it was).
  std::string ExportAllFormatsAndReadBack() {
    std::string hdf5_skipped;
    for (const char* format : {"csv", "jsonl", "hdf5"}) {
      const std::string out = dir_ + "/d_" + format;
      const auto r =
          Arena("export --db " + db_ + " --campaign 1 --format " + format + " --out " + out);
      EXPECT_EQ(r.rc, 0) << format << ": " << r.err;
      EXPECT_NE(r.out.find("36 trials"), std::string::npos) << r.out;
      std::string message;
      const int rc = ReadBack(out, &message);
      if (rc == 77) {
        hdf5_skipped = message;
        continue;
      }
      EXPECT_EQ(rc, 0) << format << ": " << message;
    }
    return hdf5_skipped;
  }
  std::string db_;
};

TEST_F(DatasetE2E, NoisyCellStoreExportsInEveryFormatAndReadsBack) {
  RunSmoke(Source("examples/defects/noisy.json"));
  const auto dropped = Arena("query --db " + db_ +
                             " \"SELECT sum(samples - observed_samples) FROM trial_results\""
                             " --format csv");
  ASSERT_EQ(dropped.rc, 0);
  EXPECT_NE(dropped.out, "sum(samples - observed_samples)\n0\n") << "no drop to export";
  const std::string skipped = ExportAllFormatsAndReadBack();
  if (!skipped.empty()) GTEST_SKIP() << "HDF5 not read back: " << skipped;
}

TEST_F(DatasetE2E, DropsOnlyCellExportsAndAFailedExportLeavesNothingBehind) {
  std::ofstream(dir_ + "/drops.json") << R"({"drop_probability": 0.01})";
  RunSmoke(dir_ + "/drops.json");
  // An output that cannot be written: exit 1, the reason, nothing left over.
  std::ofstream(dir_ + "/plainfile") << "x";
  const auto bad =
      Arena("export --db " + db_ + " --campaign 1 --format hdf5 --out " + dir_ + "/plainfile/d");
  EXPECT_EQ(bad.rc, 1) << bad.err;
  EXPECT_NE(bad.err.find("plainfile"), std::string::npos) << bad.err;
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();
  const std::string skipped = ExportAllFormatsAndReadBack();
  // The same export again into its finished directory is refused, not half-done.
  const auto again =
      Arena("export --db " + db_ + " --campaign 1 --format csv --out " + dir_ + "/d_csv");
  EXPECT_EQ(again.rc, 2);
  if (!skipped.empty()) GTEST_SKIP() << "HDF5 not read back: " << skipped;
}

TEST_F(DatasetE2E, VariedParametersAreQueryableColumns) {
  RunSmoke(Source("examples/defects/noisy.json"));
  const auto pushed = Arena("query --db " + db_ + " --where 'pivot_offset > 0' --format json");
  ASSERT_EQ(pushed.rc, 0) << pushed.err;
  const auto rows = nlohmann::json::parse(pushed.out);
  EXPECT_EQ(rows.size(), 18u);  // half the grid pushes 10 mm off the centre
  for (const auto& r : rows) {
    EXPECT_DOUBLE_EQ(r["pivot_offset"].get<double>(), 0.01);
    EXPECT_DOUBLE_EQ(r["push_distance"].get<double>(), 0.004);
    EXPECT_TRUE(r.contains("finger_length") && r.contains("finger_radius")) << r;
  }
  const auto grouped = Arena(
      "query --db " + db_ +
      " \"SELECT finger_type, pivot_offset, count(*) AS n FROM trial_results"
      " GROUP BY finger_type, pivot_offset ORDER BY finger_type, pivot_offset\" --format csv");
  ASSERT_EQ(grouped.rc, 0) << grouped.err;
  EXPECT_EQ(grouped.out,
            "finger_type,pivot_offset,n\nline,0,6\nline,0.01,6\npatch,0,6\npatch,0.01,6\n"
            "point,0,6\npoint,0.01,6\n");
  const auto out = dir_ + "/d";
  ASSERT_EQ(Arena("export --db " + db_ + " --campaign 1 --format csv --out " + out).rc, 0);
  const auto index = Slurp(out + "/trials.csv");
  const auto header = index.substr(0, index.find('\n'));
  for (const char* c : {"pivot_offset", "push_distance", "push_speed", "scene_json"})
    EXPECT_NE(header.find(c), std::string::npos) << c;
}

TEST_F(DatasetE2E, PredictionsAreExportedBesideTheTruth) {
  RunSmoke(Source("examples/defects/noisy.json"));
  const auto out = dir_ + "/d";
  ASSERT_EQ(Arena("export --db " + db_ + " --campaign 1 --format jsonl --out " + out).rc, 0);
  std::ifstream index(out + "/trials.jsonl");
  std::string line;
  int trials = 0;
  while (std::getline(index, line)) {
    const auto t = nlohmann::json::parse(line);
    ++trials;
    // The re-run prediction is the one the service stored: same setting.
    EXPECT_EQ(t["predicted_by"], t["model_key"]);
    EXPECT_EQ(nlohmann::json::parse(t["predicted_settings"].get<std::string>())["facets"], 4);
    ASSERT_EQ(t["predicted_status"], "ok");
    std::ifstream p(out + "/" + t["predicted_file"].get<std::string>());
    std::string first;
    ASSERT_TRUE(std::getline(p, first));
    const auto s = nlohmann::json::parse(first);
    EXPECT_TRUE(s.contains("left_fx") && s.contains("pusher_mode") && s.contains("qw")) << s;
    EXPECT_GT(t["predicted_samples"].get<int>(), 10);
  }
  EXPECT_EQ(trials, 36);
  const auto m = nlohmann::json::parse(Slurp(out + "/manifest.json"));
  EXPECT_EQ(m["columns"]["predicted"].size(), m["columns"]["true"].size());
  // Without predictions: no predicted stream, no predicted columns.
  ASSERT_EQ(
      Arena("export --db " + db_ + " --campaign 1 --format csv --no-predictions --out " + out + "2")
          .rc,
      0);
  EXPECT_EQ(Slurp(out + "2/trials.csv").find("predicted_by"), std::string::npos);
}

// A campaign predicted by MuJoCo exports MuJoCo's trajectory under the key
// the service stored (before, the export re-ran arena's model for it).
TEST_F(DatasetE2E, AMujocoPredictedCampaignExportsMujocosPrediction) {
  std::ifstream in(Source("examples/campaigns/smoke.json"));
  nlohmann::json spec = nlohmann::json::parse(in);
  spec["prediction"] = {{"predictor", "mujoco"}, {"timestep", 0.001}};
  const std::string file = dir_ + "/smoke_mujoco.json";
  std::ofstream(file) << spec.dump(2);
  db_ = dir_ + "/lab.db";
  ASSERT_EQ(Arena("run " + file + " --db " + db_ + " --cells 2").rc, 0);
  const auto out = dir_ + "/d";
  ASSERT_EQ(Arena("export --db " + db_ + " --campaign 1 --format jsonl --out " + out).rc, 0);
  std::ifstream index(out + "/trials.jsonl");
  std::string line;
  int trials = 0;
  while (std::getline(index, line)) {
    const auto t = nlohmann::json::parse(line);
    ++trials;
    EXPECT_EQ(t["predicted_by"], t["model_key"]);
    EXPECT_EQ(t["predicted_by"].get<std::string>().rfind("mujoco_ts0.001", 0), 0u) << t;
    EXPECT_EQ(nlohmann::json::parse(t["predicted_settings"].get<std::string>())["predictor"],
              "mujoco");
    if (t["predicted_status"] == "ok") {
      EXPECT_GT(t["predicted_samples"].get<int>(), 10);
    }
  }
  EXPECT_EQ(trials, 36);
}

TEST_F(DatasetE2E, PerContactOutcomesAreQueryableAndExported) {
  RunSmoke(Source("examples/defects/noisy.json"));
  const auto q = Arena("query --db " + db_ +
                       " \"SELECT grip_force, contact_name, avg(stick_fraction) AS stick,"
                       " avg(slide_fraction) AS slide, avg(separate_fraction) AS separate,"
                       " max(slip_distance_m) AS slip FROM contact_results WHERE role = 'finger'"
                       " GROUP BY grip_force, contact_name\" --format json");
  ASSERT_EQ(q.rc, 0) << q.err;
  const auto rows = nlohmann::json::parse(q.out);
  ASSERT_EQ(rows.size(), 4u);  // 2 grip forces x the fingers left, right
  for (const auto& r : rows) {
    EXPECT_NEAR(r["stick"].get<double>() + r["slide"].get<double>() + r["separate"].get<double>(),
                1.0, 1e-9);
    EXPECT_GE(r["slip"].get<double>(), 0.0);
  }
  const auto object = Arena("query --db " + db_ +
                            " \"SELECT count(*) FROM trial_results WHERE grasp_kept IS NULL"
                            " OR net_dz IS NULL OR net_rx IS NULL\" --format csv");
  EXPECT_EQ(object.out, "count(*)\n0\n");
  const auto out = dir_ + "/d";
  ASSERT_EQ(Arena("export --db " + db_ + " --campaign 1 --format csv --out " + out).rc, 0);
  const auto contacts = Slurp(out + "/contacts.csv");
  EXPECT_EQ(std::count(contacts.begin(), contacts.end(), '\n'), 1 + 36 * 3);
  EXPECT_NE(Slurp(out + "/trials.csv").find("grasp_kept"), std::string::npos);
}

// A store in a directory the user cannot write: a read-only bind mount in a
// private mount namespace (tests run as root here, and root ignores file
// permissions, so chmod would prove nothing).
TEST_F(DatasetE2E, ReadOnlyCommandsWorkInAWriteProtectedDirectory) {
  RunSmoke(Source("examples/defects/noisy.json"));
  const std::string ro = dir_ + "/ro";
  fs::create_directories(ro);
  fs::copy_file(db_, ro + "/lab.db");
  const std::string probe = "unshare -m sh -c 'mount --bind -o ro " + ro + " " + ro +
                            " && ! touch " + ro + "/.w 2>/dev/null' 2>/dev/null";
  if (std::system(probe.c_str()) != 0)
    GTEST_SKIP() << "cannot make a read-only directory (needs unshare -m and mount --bind)";
  const std::string a = ARENA_BINARY, db = ro + "/lab.db";
  const std::string script = "set -e; mount --bind -o ro " + ro + " " + ro + "; " + a +
                             " status --db " + db + "; " + a + " status --db " + db + " --json; " +
                             a + " list --db " + db + "; " + a + " query --db " + db +
                             " --where \"pivot_offset > 0\" --format csv > " + dir_ + "/q.csv; " +
                             a + " export --db " + db + " --campaign 1 --format csv --out " + dir_ +
                             "/exp; " + a + " plot --db " + db + " 3 --out " + dir_ + "/t3.svg";
  std::ofstream(dir_ + "/ro.sh") << script << "\n";
  const auto r = std::system(
      ("unshare -m sh " + dir_ + "/ro.sh >" + dir_ + "/ro.out 2>" + dir_ + "/ro.err").c_str());
  EXPECT_EQ(WEXITSTATUS(r), 0) << Slurp(dir_ + "/ro.err");
  EXPECT_EQ(Slurp(dir_ + "/ro.err").find("read-write command"), std::string::npos);
  const auto q = Slurp(dir_ + "/q.csv");
  EXPECT_EQ(std::count(q.begin(), q.end(), '\n'), 1 + 18);
  EXPECT_TRUE(fs::exists(dir_ + "/exp/manifest.json"));
  EXPECT_TRUE(fs::exists(dir_ + "/t3.svg"));
  EXPECT_FALSE(fs::exists(ro + "/lab.db-wal"));  // nothing was written next to the store
}

TEST_F(DatasetE2E, ExitCodesAndMessagesFollowTheReadme) {
  RunSmoke(Source("examples/defects/noisy.json"));
  const auto none = Arena("");
  EXPECT_EQ(none.rc, 2);
  EXPECT_NE(none.err.find("Usage"), std::string::npos) << none.err;
  const auto q99 = Arena("query --db " + db_ + " --campaign 99");
  EXPECT_EQ(q99.rc, 2);
  EXPECT_NE(q99.err.find("no campaign 99"), std::string::npos) << q99.err;
  for (const char* c : {"status", "list", "query", "export --campaign 1 --out x"}) {
    const std::string cmd = c;
    const auto dir = Arena(cmd + " --db " + dir_);
    EXPECT_EQ(dir.rc, 3) << cmd;
    EXPECT_NE(dir.err.find("is a directory"), std::string::npos) << cmd << ": " << dir.err;
    EXPECT_EQ(dir.err.find("disk I/O"), std::string::npos) << dir.err;
  }
  EXPECT_EQ(Arena("submit " + Source("examples/campaigns/smoke.json") + " --db " + dir_).rc, 3);
  // No error names an internal function ("GetCampaign:", "Store::Open:").
  for (const std::string& cmd : {"pause 99 --db " + db_, "status 99 --db " + db_,
                                 "export --db " + db_ + " --campaign 99 --out " + dir_ + "/x",
                                 "plot --db " + db_ + " 9999 --out x.svg",
                                 "query --db " + dir_ + "/missing.db", "cancel 42 --db " + db_}) {
    const auto r = Arena(cmd);
    EXPECT_EQ(r.rc, cmd.find("missing") != std::string::npos ? 3 : 2) << cmd << ": " << r.err;
    for (const char* internal : {"GetCampaign", "Store::Open", "GetTrial", "Campaign:", "'SELECT"})
      EXPECT_EQ(r.err.find(internal), std::string::npos) << cmd << ": " << r.err;
  }
  const auto help = Arena("export --help");
  EXPECT_NE(help.out.find("=hdf5"), std::string::npos) << help.out;
  const auto sim = Arena("simulate " + Source("examples/scenes/canonical.json") +
                         " --trajectory /nonexistent/x.csv");
  EXPECT_EQ(sim.rc, 1) << sim.err;
}

}  // namespace
}  // namespace arena::test
