// Export round trips: HDF5 read back through the HDF5 library, CSV and JSONL
// through parsers, each compared value for value with the store.
#include <hdf5.h>
#include <sqlite3.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>

#include "arena/db/export.hpp"
#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeTrials;
using testing::RunTrialToDone;
using testing::TempDir;
namespace fs = std::filesystem;

// The caller's facts of the stores' scenes (all SceneJson: fingers left and
// right, the pusher), as the CLI's orchestrator::SceneFactsOfJson gives them.
SceneFacts FactsOfScene(const std::string&) { return testing::SceneFactsFor(); }

// The columns the dataset promises, rebuilt here independently of export.cpp.
std::vector<double> TrueRow(const Sample& s) {
  std::vector<double> r{s.t};
  for (double v : s.object_pose) r.push_back(v);
  for (double v : s.object_twist) r.push_back(v);
  for (double v : s.pusher_pose) r.push_back(v);
  for (double v : s.pusher_twist) r.push_back(v);
  for (const auto& c : s.contacts) {
    for (double v : c.force) r.push_back(v);
    for (double v : c.torque) r.push_back(v);
    r.push_back(static_cast<double>(c.mode));
  }
  return r;
}

// A dropped observation (valid = 0) has every value missing (NaN).
std::vector<double> ObservedRow(const Sample& s) {
  std::vector<double> r{s.t, s.observed_valid ? 1.0 : 0.0};
  if (!s.observed_valid) {
    r.insert(r.end(), 7 + 6 + s.observed_finger_wrenches.size(),
             std::numeric_limits<double>::quiet_NaN());
    return r;
  }
  for (double v : s.observed_object_pose) r.push_back(v);
  for (double v : s.observed_pusher_wrench) r.push_back(v);
  for (double v : s.observed_finger_wrenches) r.push_back(v);
  return r;
}

// Equal, or both missing.
bool Same(double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; }
// A CSV field as a number: empty is missing.
double CsvNumber(const std::string& f) {
  return f.empty() ? std::numeric_limits<double>::quiet_NaN() : std::strtod(f.c_str(), nullptr);
}

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Minimal RFC 4180 reader (quotes, doubled quotes, commas inside quotes).
std::vector<std::vector<std::string>> ParseCsv(const std::string& text) {
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> row;
  std::string field;
  bool quoted = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (quoted) {
      if (c == '"' && i + 1 < text.size() && text[i + 1] == '"') {
        field += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        field += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      row.push_back(field);
      field.clear();
    } else if (c == '\n') {
      row.push_back(field);
      field.clear();
      rows.push_back(row);
      row.clear();
    } else {
      field += c;
    }
  }
  return rows;
}

class ExportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = dir_.File("e.db");
    auto store = Store::Open(path_);
    store->UpsertCell("c", {"point"});
    campaign_ = store->CreateCampaign(MakeCampaign("export"), MakeTrials(4));
    const int counts[] = {250, 17, 400};
    for (int n : counts) {
      auto t = store->ClaimNextTrial("c");
      RunTrialToDone(*store, *t, n);
    }
    // The 4th trial stays planned: it has no ground truth and is not exported.
    StoreOptions ro;
    ro.read_only = true;
    store_ = Store::Open(path_, ro);
  }

  ExportReport Export(ExportFormat f, const std::string& name) {
    ExportOptions o;
    o.scene_facts = FactsOfScene;
    o.campaign_id = campaign_;
    o.format = f;
    o.out_dir = dir_.File(name);
    o.arena_version = "0.1.0";
    o.arena_commit = "abc123";
    return ExportCampaign(*store_, o);
  }

  nlohmann::json Manifest(const std::string& name) {
    return nlohmann::json::parse(ReadAll(dir_.path() / name / "manifest.json"));
  }

  TempDir dir_;
  std::string path_;
  std::int64_t campaign_ = 0;
  std::unique_ptr<Store> store_;
};

TEST(Sha256, KnownVectors) {
  EXPECT_EQ(Sha256Hex("", 0), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256Hex("abc", 3),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  const std::string two = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
  EXPECT_EQ(Sha256Hex(two.data(), two.size()),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  const std::string million(1000000, 'a');
  EXPECT_EQ(Sha256Hex(million.data(), million.size()),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST_F(ExportTest, Hdf5RoundTripThroughTheLibrary) {
  const auto r = Export(ExportFormat::kHdf5, "h5");
  EXPECT_EQ(r.trials, 3);
  EXPECT_EQ(r.samples, 250 + 17 + 400);
  const auto m = Manifest("h5");
  EXPECT_EQ(m["format_version"], kDatasetFormatVersion);
  EXPECT_EQ(m["arena_commit"], "abc123");
  EXPECT_EQ(m["campaign"]["spec"]["name"], "export");
  EXPECT_NEAR(m["sample_rate_hz"].get<double>(), 250.0, 1e-6);
  const hid_t file =
      H5Fopen((dir_.path() / "h5" / "dataset.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  for (const auto& trial : store_->ListTrials(campaign_)) {
    if (!trial.gt_stream_id) continue;
    const auto gt = store_->ReadGroundTruth(trial.id);
    const std::string group = "/trials/" + std::to_string(trial.id);
    for (const bool observed : {false, true}) {
      const std::string name = group + (observed ? "/observed" : "/true");
      const hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
      ASSERT_GE(ds, 0) << name;
      const hid_t space = H5Dget_space(ds);
      hsize_t dims[2];
      H5Sget_simple_extent_dims(space, dims, nullptr);
      ASSERT_EQ(dims[0], gt.samples.size());
      std::vector<double> data(dims[0] * dims[1]);
      ASSERT_GE(H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), 0);
      for (std::size_t i = 0; i < gt.samples.size(); ++i) {
        const auto expected = observed ? ObservedRow(gt.samples[i]) : TrueRow(gt.samples[i]);
        ASSERT_EQ(expected.size(), dims[1]);
        for (std::size_t k = 0; k < expected.size(); ++k) {
          ASSERT_TRUE(Same(data[i * dims[1] + k], expected[k]))
              << name << " row " << i << " col " << k;
        }
      }
      H5Sclose(space);
      H5Dclose(ds);
    }
    // The index row travels as attributes of the trial's group.
    const hid_t g = H5Gopen2(file, group.c_str(), H5P_DEFAULT);
    double grip = 0;
    const hid_t a = H5Aopen(g, "grip_force", H5P_DEFAULT);
    ASSERT_GE(a, 0);
    H5Aread(a, H5T_NATIVE_DOUBLE, &grip);
    EXPECT_EQ(grip, 5.0 + trial.index);
    H5Aclose(a);
    H5Gclose(g);
  }
  H5Fclose(file);
}

TEST_F(ExportTest, CsvRoundTripThroughAParser) {
  Export(ExportFormat::kCsv, "csv");
  const auto m = Manifest("csv");
  const auto index = ParseCsv(ReadAll(dir_.path() / "csv" / "trials.csv"));
  ASSERT_EQ(index.size(), 4u);  // header + 3 trials
  const auto& header = index[0];
  const auto col = [&](const std::string& name) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  for (std::size_t r = 1; r < index.size(); ++r) {
    const auto trial_id = std::stoll(index[r][col("trial_id")]);
    const auto gt = store_->ReadGroundTruth(trial_id);
    EXPECT_EQ(std::stoull(index[r][col("seed")]), store_->GetTrial(trial_id).seed);
    EXPECT_EQ(std::stoll(index[r][col("samples")]), static_cast<long long>(gt.samples.size()));
    EXPECT_EQ(index[r][col("final_position_error")], "0.001");
    for (const bool observed : {false, true}) {
      const auto file = index[r][col(observed ? "observed_file" : "true_file")];
      const auto rows = ParseCsv(ReadAll(dir_.path() / "csv" / file));
      ASSERT_EQ(rows.size(), gt.samples.size() + 1);
      EXPECT_EQ(rows[0][0], "t");
      if (!observed) {
        EXPECT_EQ(rows[0].back(), "pusher_mode");  // the scene names the contacts
      }
      for (std::size_t i = 0; i < gt.samples.size(); ++i) {
        const auto expected = observed ? ObservedRow(gt.samples[i]) : TrueRow(gt.samples[i]);
        ASSERT_EQ(rows[i + 1].size(), expected.size());
        for (std::size_t k = 0; k < expected.size(); ++k) {
          ASSERT_TRUE(Same(CsvNumber(rows[i + 1][k]), expected[k])) << file << " " << i;
        }
      }
    }
  }
  EXPECT_EQ(m["counts"]["files"],
            3 + 2 * 3);  // trials.csv, contacts.csv, scenes.jsonl, 2 streams per trial
}

TEST_F(ExportTest, JsonlRoundTripThroughAParser) {
  Export(ExportFormat::kJsonl, "jsonl");
  const auto m = Manifest("jsonl");
  std::istringstream index(ReadAll(dir_.path() / "jsonl" / "trials.jsonl"));
  std::string line;
  int trials = 0;
  while (std::getline(index, line)) {
    const auto t = nlohmann::json::parse(line);
    ++trials;
    const auto gt = store_->ReadGroundTruth(t["trial_id"].get<std::int64_t>());
    const auto cols = m["columns"]["true"];
    std::istringstream stream(ReadAll(dir_.path() / "jsonl" / t["true_file"].get<std::string>()));
    std::size_t i = 0;
    while (std::getline(stream, line)) {
      const auto s = nlohmann::json::parse(line);
      const auto expected = TrueRow(gt.samples.at(i));
      ASSERT_EQ(s.size(), expected.size());
      for (std::size_t k = 0; k < expected.size(); ++k) {
        ASSERT_EQ(s[cols[k]["name"].get<std::string>()].get<double>(), expected[k]);
      }
      ++i;
    }
    EXPECT_EQ(i, gt.samples.size());
  }
  EXPECT_EQ(trials, 3);
}

TEST_F(ExportTest, ManifestListsUnitsAndChecksumsAndVerifyCatchesTampering) {
  Export(ExportFormat::kCsv, "v");
  const auto m = Manifest("v");
  for (const auto& c : m["columns"]["true"]) {
    EXPECT_TRUE(c.contains("unit")) << c;
    EXPECT_FALSE(c["meaning"].get<std::string>().empty()) << c;
  }
  for (const auto& f : m["files"]) {
    EXPECT_EQ(f["sha256"], Sha256File((dir_.path() / "v" / f["path"].get<std::string>()).string()));
  }
  EXPECT_EQ(VerifyExport(dir_.File("v")).samples, 667);
  // Flip one byte of a stream: verification names it.
  const auto victim = dir_.path() / "v" / m["files"][0]["path"].get<std::string>();
  std::string bytes = ReadAll(victim);
  bytes[bytes.size() / 2] ^= 1;
  std::ofstream(victim, std::ios::binary | std::ios::trunc) << bytes;
  try {
    VerifyExport(dir_.File("v"));
    ADD_FAILURE();
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), StoreError::Kind::kCorrupt);
    EXPECT_NE(std::string(e.what()).find("checksum"), std::string::npos) << e.what();
  }
  fs::remove(dir_.path() / "v" / "manifest.json");
  EXPECT_THROW(VerifyExport(dir_.File("v")), StoreError);
}

TEST_F(ExportTest, RefusesNonEmptyDirectoryAndUnknownCampaign) {
  fs::create_directories(dir_.path() / "full");
  std::ofstream(dir_.path() / "full" / "x") << "x";
  EXPECT_THROW(Export(ExportFormat::kCsv, "full"), StoreError);
  ExportOptions o;
  o.scene_facts = FactsOfScene;
  o.campaign_id = 99;
  o.out_dir = dir_.File("none");
  EXPECT_THROW(ExportCampaign(*store_, o), StoreError);
  EXPECT_FALSE(fs::exists(dir_.path() / "none"));
  // db reads no scene: an export without the caller's reader is refused.
  o.campaign_id = campaign_;
  o.scene_facts = nullptr;
  try {
    ExportCampaign(*store_, o);
    ADD_FAILURE();
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), StoreError::Kind::kBadInput);
    EXPECT_NE(std::string(e.what()).find("scene_facts"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_.path() / "none"));
}

// What a cell with drops really sends: a dropped observation carries no
// finger wrenches at all (0 values where a valid one has 12), and one sample
// lacks a contact. Every format exports it; dropped rows are flagged and missing.
TEST(ExportRealData, DroppedObservationsAndShortSamplesExportInEveryFormat) {
  TempDir dir;
  const auto path = dir.File("drops.db");
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    store->CreateCampaign(MakeCampaign("drops"), MakeTrials(1));
    auto t = store->ClaimNextTrial("c");
    auto ingest = store->BeginIngest(t->trial_id, t->attempt, testing::SceneSites());
    for (int i = 0; i < 60; ++i) {
      Sample s = testing::MakeSample(i);
      if (s.observed_valid == false) s.observed_finger_wrenches.clear();  // as the DDS decoder
      if (i == 30) s.contacts.pop_back();                                 // a short sample
      ingest->Add(s);
    }
    ingest->Finish();
  }
  StoreOptions ro;
  ro.read_only = true;
  auto store = Store::Open(path, ro);
  for (const auto f : {ExportFormat::kHdf5, ExportFormat::kCsv, ExportFormat::kJsonl}) {
    ExportOptions o;
    o.scene_facts = FactsOfScene;
    o.campaign_id = 1;
    o.format = f;
    o.out_dir = dir.File(std::string("out_") + ToString(f));
    const auto r = ExportCampaign(*store, o);
    EXPECT_EQ(r.samples, 60) << ToString(f);
  }
  const auto rows = ParseCsv(ReadAll(dir.path() / "out_csv" / "streams" / "1_observed.csv"));
  ASSERT_EQ(rows.size(), 61u);
  EXPECT_EQ(rows[0].size(), 2u + 7 + 6 + 12);  // the valid samples' width
  EXPECT_EQ(rows[4][1], "0");                  // sample 3 was dropped
  EXPECT_EQ(rows[4][2], "");                   // and has no values
  EXPECT_EQ(rows[1][1], "1");
  const auto truth = ParseCsv(ReadAll(dir.path() / "out_csv" / "streams" / "1_true.csv"));
  EXPECT_EQ(truth[31].back(), "");  // sample 30's missing pusher contact
  std::ifstream jl(dir.path() / "out_jsonl" / "streams" / "1_observed.jsonl");
  std::string line;
  for (int i = 0; i <= 3; ++i) std::getline(jl, line);
  const auto dropped = nlohmann::json::parse(line);
  EXPECT_EQ(dropped["valid"], 0);
  EXPECT_TRUE(dropped["x"].is_null());
}

// A failed export leaves nothing behind, names the trial, and a retry works.
TEST_F(ExportTest, FailedExportLeavesNothingNamesTheTrialAndCanBeRetried) {
  // Damage the second trial's ground truth (a chunk that is not a block).
  std::int64_t victim = 0;
  std::string saved;
  {
    auto rw = Store::Open(path_);
    victim = rw->ListTrials(campaign_)[1].id;
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path_.c_str(), &db), SQLITE_OK);
    const std::string sql =
        "UPDATE gt_chunks SET data = x'00010203' WHERE stream_id = (SELECT gt_stream_id FROM "
        "trials WHERE id = " +
        std::to_string(victim) + ")";
    ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(db);
  }
  for (const auto f : {ExportFormat::kHdf5, ExportFormat::kCsv}) {
    try {
      Export(f, "retry");
      ADD_FAILURE() << "export of a damaged stream succeeded";
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), StoreError::Kind::kCorrupt);
      EXPECT_NE(std::string(e.what()).find("trial " + std::to_string(victim)), std::string::npos)
          << e.what();
    }
    EXPECT_FALSE(fs::exists(dir_.path() / "retry"));
    for (const auto& e : fs::directory_iterator(dir_.path()))
      EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();
  }
  // An empty directory the user made stays usable too.
  fs::create_directories(dir_.path() / "made");
  EXPECT_THROW(Export(ExportFormat::kJsonl, "made"), StoreError);
  EXPECT_TRUE(fs::is_empty(dir_.path() / "made"));
  // Repair the store (re-ingest the trial), then the same command works.
  {
    auto rw = Store::Open(path_);
    const auto t = rw->GetTrial(victim);
    auto ingest = rw->BeginIngest(victim, t.attempt, testing::SceneSites());
    for (int i = 0; i < 17; ++i) ingest->Add(testing::MakeSample(i));
    ingest->Finish();
  }
  EXPECT_EQ(Export(ExportFormat::kHdf5, "retry").trials, 3);
  EXPECT_EQ(Export(ExportFormat::kCsv, "made").trials, 3);
  EXPECT_EQ(VerifyExport(dir_.File("made")).trials, 3);
}

// An output that cannot be written is kOutput (the command failed; exit 1), not a store error.
TEST_F(ExportTest, UnwritableOutputIsAnOutputError) {
  std::ofstream(dir_.path() / "plainfile") << "x";
  try {
    Export(ExportFormat::kCsv, "plainfile/sub");
    ADD_FAILURE();
  } catch (const StoreError& e) {
    EXPECT_EQ(e.kind(), StoreError::Kind::kOutput) << e.what();
  }
}

// Parameters, the scene, contact outcomes and a predicted stream travel with each trial.
TEST(ExportContents, ParametersSceneContactsAndPredictions) {
  TempDir dir;
  const auto path = dir.File("p.db");
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    auto trials = MakeTrials(2);
    trials[0].params_json =
        R"({"pivot_offset": 0, "push_distance": 0.004, "finger_type": "point"})";
    trials[1].params_json =
        R"({"pivot_offset": 0.01, "push_distance": 0.004, "finger_type": "point"})";
    store->CreateCampaign(MakeCampaign("p"), trials);
    for (int i = 0; i < 2; ++i) RunTrialToDone(*store, *store->ClaimNextTrial("c"), 20);
  }
  StoreOptions ro;
  ro.read_only = true;
  auto store = Store::Open(path, ro);
  ExportOptions o;
  o.scene_facts = FactsOfScene;
  o.campaign_id = 1;
  o.format = ExportFormat::kCsv;
  o.out_dir = dir.File("d");
  int calls = 0;
  o.predict = [&](const std::string& scene, const std::string& spec) {
    EXPECT_NE(scene.find("fingers"), std::string::npos);
    EXPECT_NE(spec.find("\"p\""), std::string::npos);
    PredictedStream p;
    p.predictor = "g4_k3_dt0.008_auto";
    p.settings_json = R"({"facets":4})";
    if (++calls == 2) {
      p.status = PredictionStatus::kSolverFailure;
      p.error = "no pivot";
      return p;
    }
    for (int i = 0; i < 5; ++i) p.samples.push_back(testing::MakeSample(i));
    return p;
  };
  ExportCampaign(*store, o);
  const auto index = ParseCsv(ReadAll(dir.path() / "d" / "trials.csv"));
  ASSERT_EQ(index.size(), 3u);
  const auto& h = index[0];
  auto col = [&](const std::string& n) {
    const auto it = std::find(h.begin(), h.end(), n);
    EXPECT_NE(it, h.end()) << n;
    return static_cast<std::size_t>(it - h.begin());
  };
  EXPECT_EQ(index[1][col("pivot_offset")], "0");
  EXPECT_EQ(index[2][col("pivot_offset")], "0.01");
  EXPECT_EQ(index[1][col("push_distance")], "0.004");
  EXPECT_EQ(std::count(h.begin(), h.end(), "finger_type"), 1);  // already a column
  EXPECT_EQ(nlohmann::json::parse(index[1][col("scene_json")])["fingers"].size(), 2u);
  EXPECT_EQ(index[1][col("predicted_by")], "g4_k3_dt0.008_auto");
  EXPECT_EQ(index[1][col("predicted_samples")], "5");
  EXPECT_EQ(index[2][col("predicted_status")], "solver_failure");
  EXPECT_EQ(index[2][col("predicted_error")], "no pivot");
  EXPECT_EQ(ParseCsv(ReadAll(dir.path() / "d" / index[1][col("predicted_file")])).size(), 6u);
  EXPECT_EQ(ParseCsv(ReadAll(dir.path() / "d" / index[2][col("predicted_file")])).size(), 1u);
  EXPECT_NE(index[1][col("grasp_kept")], "");
  const auto contacts = ParseCsv(ReadAll(dir.path() / "d" / "contacts.csv"));
  ASSERT_EQ(contacts.size(), 1u + 2 * 3);
  EXPECT_EQ(contacts[1][2], "left");
  EXPECT_EQ(contacts[3][2], "pusher");
  const auto m = nlohmann::json::parse(ReadAll(dir.path() / "d" / "manifest.json"));
  EXPECT_EQ(m["parameters"].size(), 2u);  // pivot_offset, push_distance
  EXPECT_EQ(m["columns"]["predicted"].size(), m["columns"]["true"].size());
}

// Closed loop (issue 19): the controller's run and every applied command
// travel with the dataset in each format, and the prediction of a
// closed-loop trial is given the commands to replay.
TEST(ExportContents, ClosedLoopRunsAndAppliedCommandsInEveryFormat) {
  TempDir dir;
  const auto path = dir.File("cl.db");
  std::int64_t closed_trial = 0;
  {
    auto store = Store::Open(path);
    store->UpsertCell("c", {"point"});
    store->CreateCampaign(MakeCampaign("cl"), MakeTrials(2));
    for (int i = 0; i < 2; ++i) {
      const auto t = store->ClaimNextTrial("c");
      RunTrialToDone(*store, *t, 20);
      if (i != 0) continue;
      closed_trial = t->trial_id;
      ClosedLoopRun run;
      run.trial_id = t->trial_id;
      run.attempt = t->attempt;
      run.controller = "pivot";
      run.lockstep = true;
      run.target = 0.2;
      run.gain = 0.05;
      run.tolerance = 0.02;
      run.hold_s = 0.05;
      run.reached = true;
      run.final_error = 0.01;
      run.settle_time_s = 0.3;
      run.held = 1;
      run.loop_p50_ms = 0.4;
      run.loop_p99_ms = 1.5;
      for (int k = 0; k < 3; ++k) {
        ClosedLoopCommand c;
        c.sample = k;
        c.t = 0.004 * k;
        c.commanded = {0.01 * (k + 1), 0, 0};
        c.applied = {0.01 * (k + 1) + 1e-4, 0, 0};
        if (k != 1) c.loop_ms = 0.5 + k;  // sample 1: no fresh answer, held
        run.commands.push_back(c);
      }
      store->RecordClosedLoop(run);
    }
  }
  StoreOptions ro;
  ro.read_only = true;
  auto store = Store::Open(path, ro);
  auto export_as = [&](ExportFormat f, const std::string& name, int* replays) {
    ExportOptions o;
    o.scene_facts = FactsOfScene;
    o.campaign_id = 1;
    o.format = f;
    o.out_dir = dir.File(name);
    o.predict = [](const std::string&, const std::string&) { return PredictedStream{}; };
    o.predict_closed_loop = [replays](const std::string&, const std::string&,
                                      const std::vector<ClosedLoopCommand>& commands) {
      ++*replays;
      EXPECT_EQ(commands.size(), 3u);
      if (commands.size() == 3) {
        EXPECT_EQ(commands[2].sample, 2);
        EXPECT_DOUBLE_EQ(commands[2].commanded[0], 0.03);
        EXPECT_FALSE(commands[1].loop_ms.has_value());
      }
      return PredictedStream{};
    };
    ExportCampaign(*store, o);
    return dir.path() / name;
  };
  int replays = 0;
  const auto csv = export_as(ExportFormat::kCsv, "csv", &replays);
  EXPECT_EQ(replays, 1);  // the open-loop trial went to `predict`
  const auto runs = ParseCsv(ReadAll(csv / "closed_loop.csv"));
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[1][0], std::to_string(closed_trial));
  EXPECT_EQ(runs[1][2], "pivot");
  const auto commands = ParseCsv(ReadAll(csv / "closed_loop_commands.csv"));
  ASSERT_EQ(commands.size(), 4u);
  EXPECT_EQ(commands[0][2], "sample");
  EXPECT_DOUBLE_EQ(CsvNumber(commands[3][4]), 0.03);
  EXPECT_DOUBLE_EQ(CsvNumber(commands[3][7]), 0.0301);
  EXPECT_EQ(commands[2][10], "");  // held: no loop latency
  const auto m = nlohmann::json::parse(ReadAll(csv / "manifest.json"));
  EXPECT_EQ(m["columns"]["closed_loop_commands"].size(), 11u);
  int listed = 0;
  for (const auto& t : m["trials"]) listed += t.value("commands", 0);
  EXPECT_EQ(listed, 3);

  const auto jsonl = export_as(ExportFormat::kJsonl, "jsonl", &replays);
  std::istringstream lines(ReadAll(jsonl / "closed_loop_commands.jsonl"));
  std::string line;
  int n = 0;
  while (std::getline(lines, line)) {
    const auto j = nlohmann::json::parse(line);
    EXPECT_EQ(j["sample"], n);
    EXPECT_EQ(j["loop_ms"].is_null(), n == 1);
    ++n;
  }
  EXPECT_EQ(n, 3);

  const auto h5 = export_as(ExportFormat::kHdf5, "h5", &replays);
  const hid_t file = H5Fopen((h5 / "dataset.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const std::string name = "/trials/" + std::to_string(closed_trial) + "/commands";
  const hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  ASSERT_GE(ds, 0);
  const hid_t space = H5Dget_space(ds);
  hsize_t dims[2];
  H5Sget_simple_extent_dims(space, dims, nullptr);
  ASSERT_EQ(dims[0], 3u);
  ASSERT_EQ(dims[1], 9u);
  std::vector<double> data(dims[0] * dims[1]);
  ASSERT_GE(H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), 0);
  EXPECT_DOUBLE_EQ(data[2 * 9 + 2], 0.03);   // sample 2, vx
  EXPECT_TRUE(std::isnan(data[1 * 9 + 8]));  // sample 1 held
  EXPECT_DOUBLE_EQ(data[2 * 9 + 8], 2.5);
  H5Sclose(space);
  H5Dclose(ds);
  H5Fclose(file);
}

}  // namespace
}  // namespace arena::db
