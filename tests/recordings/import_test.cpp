// arena import, lab-neutral core and the push-dataset adaptor, on small HDF5
// files in the push dataset's layout that this test writes itself.
//
// The synthetic push (table frame, SI):
//
//        y                    rect 90 x 90 mm, centroid at the origin
//        ^   +--------+
//   (o)->|   |   +    |       the pusher (radius 4.75 mm) starts 1 mm left of the
//        |   +--------+       face x = -45 mm and moves +x at 50 mm/s for 1 s; the
//        +-------------> x    object moves with it once touched (gap 0 at onset)
#include <hdf5.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <set>

#include <gtest/gtest.h>

#include "arena/assessment/scoring.hpp"
#include "arena/db/export.hpp"
#include "arena/executors/backend.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/recordings/import.hpp"
#include "arena/recordings/push_dataset.hpp"

namespace arena::recordings {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kR = 0.00475, kHalf = 0.045;
const char* kGoodName = "motion_surface=abs_shape=rect1_a=0_v=50_i=0.000_s=0.500_t=0.000.h5";

struct Rows {
  std::vector<std::array<double, 4>> tip, object, force;
};

// 249 Hz stamps from t0 (Unix-like time) for 1.4 s: 0.2 s still, 1 s push, 0.2 s still.
Rows Push(double force_on_object = 2.0) {
  Rows r;
  const double t0 = 1.5e9;
  for (int k = 0; k < 349; ++k) {
    const double t = k / 249.0;
    const double travel = 0.05 * std::clamp(t - 0.2, 0.0, 1.0);
    const double px = -kHalf - kR - 0.001 + travel;
    const double ox = std::max(0.0, px + kR + kHalf);  // pushed once touching
    const bool pushing = t > 0.2 && t < 1.2 && ox > 0;
    r.tip.push_back({t0 + t, px, 0.0, 0.0});
    r.object.push_back({t0 + t + 0.0005, ox, 0.0, 0.0});
    // The sensor reads the reaction on the pusher: minus the force on the object.
    // A live sensor's noise (a few mN): no two rows alike.
    const double noise = 0.004 * std::sin(1.7 * k) + 0.003 * std::cos(0.9 * k * k);
    r.force.push_back({t0 + t + 0.001, (pushing ? -force_on_object : 0.0) + noise, -noise, 0.0});
  }
  return r;
}

void WriteDataset(hid_t file, const char* name, const std::vector<std::array<double, 4>>& rows) {
  const hsize_t dims[2] = {rows.size(), 4};
  const hid_t space = H5Screate_simple(2, dims, nullptr);
  const hid_t ds =
      H5Dcreate2(file, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, rows.data());
  H5Dclose(ds);
  H5Sclose(space);
}

void WriteH5(const fs::path& p, const Rows& r, bool with_force = true) {
  const hid_t f = H5Fcreate(p.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  WriteDataset(f, "tip_pose", r.tip);
  WriteDataset(f, "object_pose", r.object);
  if (with_force) WriteDataset(f, "ft_wrench", r.force);
  H5Fclose(f);
}

class ImportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/arena-import-test-XXXXXX";
    root_ = mkdtemp(tmpl);
    data_ = root_ / "abs";
    fs::create_directories(data_);
    shapes_path_ = root_ / "shapes.json";
    std::ofstream(shapes_path_)
        << json({{"thickness", 0.013},
                 {"pusher_radius", kR},
                 {"shapes",
                  {{"rect1",
                    {{"mass", 0.8374},
                     {"moment_of_inertia", 0.001131},
                     {"outline",
                      {{-kHalf, -kHalf}, {kHalf, -kHalf}, {kHalf, kHalf}, {-kHalf, kHalf}}}}}}}})
               .dump();
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(root_);
  }
  ImportReport Import(const std::string& out = "ds") {
    const ShapesTable shapes = ReadShapesTable(shapes_path_.string());
    ImportOptions o;
    o.out_dir = (root_ / out).string();
    o.adaptor = "push-dataset";
    o.source = data_.string();
    return ImportRecordings(ReadPushDataset(data_.string(), shapes), o);
  }
  // Nothing beside the inputs: no dataset, no staging or scratch directory.
  void ExpectNothingWritten() {
    for (const auto& e : fs::directory_iterator(root_)) {
      const std::string n = e.path().filename().string();
      EXPECT_TRUE(n == "abs" || n == "shapes.json") << "left behind: " << n;
    }
  }
  json Manifest(const std::string& out = "ds") {
    return json::parse(std::ifstream(root_ / out / "manifest.json"));
  }
  fs::path root_, data_, shapes_path_;
};

// Serves the dataset's first trial through replay:DATASET as a cell would
// (matched by its scene and seed) with a pusher facing +x; the samples it streams.
std::vector<mechanics::TrajectorySample> Replay(const fs::path& ds) {
  std::ifstream lines(ds / "scenes.jsonl");
  std::string line;
  std::getline(lines, line);
  const json entry = json::parse(line);
  const std::string scene_text = entry["scene"].dump();
  executors::TrialContext trial;
  trial.scene_json = scene_text;
  trial.seed = std::stoull(entry["seed"].get<std::string>());
  mechanics::Scene scene;  // what the cell parsed; replay needs its contacts' names and normals
  scene.pusher.emplace();
  scene.pusher->normal = Eigen::Vector3d::UnitX();
  const auto replay = executors::MakeReplayBackend(ds.string());
  EXPECT_EQ(replay->Prepare(scene, trial), "");
  std::vector<mechanics::TrajectorySample> out;
  const auto outcome = replay->Execute(scene, trial, [&](const mechanics::TrajectorySample& s) {
    out.push_back(s);
    return true;
  });
  EXPECT_TRUE(outcome.ok) << outcome.reason;
  return out;
}

TEST_F(ImportTest, AGoodPushBecomesAVerifiedMeasuredDatasetWithItsCampaign) {
  Rows rows = Push();
  std::swap(rows.object[100], rows.object[101]);  // one out-of-order stamp
  WriteH5(data_ / kGoodName, rows);
  const ImportReport report = Import();
  ASSERT_EQ(report.trials.size(), 1u);
  const auto& t = report.trials[0];
  EXPECT_TRUE(t.checks.pose_usable) << report.text;
  EXPECT_TRUE(t.checks.force_usable) << report.text;
  // The disk touches the face when the object starts to move (within a sample's travel).
  EXPECT_NEAR(t.checks.onset_gap, 0.0, 0.0005) << report.text;
  EXPECT_NEAR(t.checks.start_gap, 0.001, 1e-4);
  EXPECT_NEAR(t.checks.object_travel, 0.049, 0.0005);
  ASSERT_EQ(t.checks.findings.size(), 1u) << report.text;
  EXPECT_EQ(t.checks.findings[0].check, "out_of_order_stamps");
  EXPECT_FALSE(t.checks.findings[0].fails);

  const fs::path ds = root_ / "ds";
  EXPECT_NO_THROW(db::VerifyExport(ds.string()));  // every file listed, sized and checksummed
  const json m = Manifest();
  EXPECT_EQ(m["truth"], "measured");
  EXPECT_EQ(m["export_format"], "hdf5");
  EXPECT_EQ(m["sample_rate_hz"], 250.0);
  std::set<std::string> files;
  for (const auto& f : m["files"]) files.insert(f["path"].get<std::string>());
  for (const char* f : {"campaign.json", "import_report.json", "import_report.txt", "scenes.jsonl",
                        "dataset.h5", "trials.csv"})
    EXPECT_TRUE(files.count(f)) << f;
  // The true stream carries the pusher's measured contact: t, object pose and twist,
  // pusher pose and twist, 6 wrench values and the mode.
  EXPECT_EQ(m["trials"][0]["true_columns"], 1 + 13 + 13 + 7);

  // The campaign commands exactly the dataset's scenes.
  const json campaign = json::parse(std::ifstream(ds / "campaign.json"));
  EXPECT_EQ(campaign["scenes"], "scenes.jsonl");
  std::ifstream lines(ds / "scenes.jsonl");
  std::string line;
  std::getline(lines, line);
  const json entry = json::parse(line);
  EXPECT_EQ(entry["seed"], std::to_string(t.seed));
  const json& scene = entry["scene"];
  // The fields agreed for recorded pushes (docs/real_data.md).
  EXPECT_EQ(scene["object"]["shape"], "prism");
  EXPECT_EQ(scene["object"]["polygon"].size(), 4u);
  EXPECT_DOUBLE_EQ(scene["object"]["height"].get<double>(), 0.013);
  EXPECT_DOUBLE_EQ(scene["object"]["inertia"][2][2].get<double>(), 0.001131);
  EXPECT_DOUBLE_EQ(scene["object"]["pose"]["position"][2].get<double>(), 0.0065);
  EXPECT_TRUE(scene["fingers"].empty());
  EXPECT_EQ(scene["support"]["pressure"], "uniform");
  EXPECT_EQ(scene["gravity"], json({0.0, 0.0, -9.81}));
  const json& pusher = scene["pusher"];
  EXPECT_EQ(pusher["type"], "point");
  EXPECT_DOUBLE_EQ(pusher["radius"].get<double>(), kR);
  EXPECT_NEAR(pusher["normal"][0].get<double>(), 1.0, 1e-9);  // towards the face it pushes
  const json& path = pusher["motion"]["path"];
  ASSERT_EQ(path["t"].size(), path["position"].size());
  EXPECT_EQ(path["t"][0], 0.0);
  for (std::size_t k = 1; k < path["t"].size(); ++k)
    ASSERT_GT(path["t"][k].get<double>(), path["t"][k - 1].get<double>()) << k;
  EXPECT_EQ(path["position"][0], pusher["position"]);
  // The pusher's point facing the object starts 1 mm from the face and ends 49 mm past.
  EXPECT_NEAR(path["position"][0][0].get<double>(), -kHalf - 0.001, 1e-6);
  EXPECT_NEAR(path["position"].back()[0].get<double>(), -kHalf + 0.049, 2e-6);
  EXPECT_NEAR(scene["duration"].get<double>(), path["t"].back().get<double>(), 1e-9);

  // replay:DATASET serves it as measured truth: the pusher's measured force
  // on the object, 2 N along +x while it pushes.
  const auto replay = executors::MakeReplayBackend(ds.string());
  EXPECT_EQ(replay->Capabilities().truth, executors::TruthSource::kMeasured);
  const auto truth = Replay(ds);
  ASSERT_EQ(truth.size(), static_cast<std::size_t>(t.samples));
  ASSERT_EQ(truth[150].contacts.size(), 1u);
  EXPECT_NEAR(truth[150].contacts[0].normal_force, 2.0, 0.01);  // within the sensor's noise
  EXPECT_EQ(truth[150].contacts[0].mode, mechanics::ContactMode::kStick);
  EXPECT_EQ(truth[10].contacts[0].mode, mechanics::ContactMode::kSeparate);  // 1 mm apart
  // Scored against a prediction: forces compared.
  auto predicted = truth;
  for (auto& p : predicted) p.contacts[0].normal_force += 0.5;
  const auto e = assessment::ScorePrediction(predicted, truth);
  EXPECT_GT(e.contact_pairs, 0);
  EXPECT_NEAR(e.force_rms, 0.5, 1e-9);
}

TEST_F(ImportTest, AFrozenForceStreamIsReportedAndLeftOutOfTheTruth) {
  Rows rows = Push();
  for (auto& f : rows.force) f = {f[0], -0.3, 0.2, 0.0};  // a sensor that stopped updating
  WriteH5(data_ / kGoodName, rows);
  const ImportReport report = Import();
  const auto& c = report.trials[0].checks;
  EXPECT_TRUE(c.pose_usable);
  EXPECT_FALSE(c.force_usable);
  ASSERT_FALSE(c.findings.empty());
  EXPECT_EQ(c.findings[0].check, "force_frozen");
  EXPECT_TRUE(c.findings[0].fails);
  EXPECT_NE(report.text.find("FAIL force_frozen"), std::string::npos) << report.text;
  // No contact columns in the truth: forces of this trial are never scored.
  const json m = Manifest();
  EXPECT_EQ(m["trials"][0]["true_columns"], 1 + 13 + 13);
  EXPECT_EQ(m["import"]["trials"][0]["force_usable"], false);
  const json rep = json::parse(std::ifstream(root_ / "ds" / "import_report.json"));
  EXPECT_EQ(rep[0]["force_usable"], false);
  // Replayed, the truth has no contacts: a prediction's poses are scored, its
  // forces never (no pair compared, so no force error is reported).
  const auto truth = Replay(root_ / "ds");
  ASSERT_FALSE(truth.empty());
  for (const auto& s : truth) ASSERT_TRUE(s.contacts.empty());
  // ... and that is the trial's stated truth, not an absence: the cell's check
  // accepts samples without contacts for it, and only for it.
  {
    const fs::path ds = root_ / "ds";
    std::ifstream lines(ds / "scenes.jsonl");
    std::string line;
    std::getline(lines, line);
    const json entry = json::parse(line);
    const std::string scene_text = entry["scene"].dump();
    executors::TrialContext trial;
    trial.scene_json = scene_text;
    trial.seed = std::stoull(entry["seed"].get<std::string>());
    const auto replay = executors::MakeReplayBackend(ds.string());
    EXPECT_TRUE(replay->PreparedTruth().forces_measured);  // nothing prepared yet
    const mechanics::Scene scene = mechanics::ParseScene(scene_text);
    ASSERT_EQ(replay->Prepare(scene, trial), "");
    const executors::TrialTruth stated = replay->PreparedTruth();
    EXPECT_FALSE(stated.forces_measured);
    EXPECT_NE(stated.forces_note.find("force stream failed its import check"), std::string::npos)
        << stated.forces_note;
    EXPECT_EQ(executors::StoredTruth(executors::TruthSource::kMeasured, stated),
              "measured:no-forces");
    EXPECT_EQ(executors::CheckTrueSample(truth[0], {}, scene, stated), "");
    // Without that statement a sample without contacts is refused ...
    EXPECT_NE(executors::CheckTrueSample(truth[0], {}, scene).find("expected 1 contacts"),
              std::string::npos);
    // ... and with it, a sample that has contacts contradicts it.
    mechanics::TrajectorySample with = truth[0];
    with.contacts.emplace_back();
    EXPECT_NE(executors::CheckTrueSample(with, {}, scene, stated).find("measured no contact"),
              std::string::npos);
  }
  auto predicted = truth;
  for (auto& p : predicted) {
    p.contacts.emplace_back();
    p.contacts.back().normal_force = 3.0;
    p.position.x() += 0.001;
  }
  const auto e = assessment::ScorePrediction(predicted, truth);
  EXPECT_EQ(e.contact_pairs, 0);
  EXPECT_NEAR(e.final_position, 0.001, 1e-12);
}

// Each trial starts from its measured start: the scene's object pose is the
// measured pose at the first sample of the common clock (the truth's first
// sample), in the lab's table frame, and a replay cell's workspace holds
// every recorded start and path (the lab frame lies outside the default).
TEST_F(ImportTest, TheSceneStartsAtTheMeasuredStartInTheLabFrame) {
  Rows rows = Push();
  const double dx = 0.42, dy = -0.08;  // where the lab's table frame puts the push
  for (auto* stream : {&rows.tip, &rows.object})
    for (auto& r : *stream) r[1] += dx, r[2] += dy;
  // The object already drifting before the common clock starts (its first
  // stamps are earlier than the force's): the start is where it is at t = 0.
  for (std::size_t k = 0; k < 5; ++k) rows.object[k][1] += 0.00005 * (5.0 - k);
  WriteH5(data_ / kGoodName, rows);
  const ImportReport report = Import();
  ASSERT_TRUE(report.trials[0].checks.pose_usable) << report.text;
  const fs::path ds = root_ / "ds";
  std::ifstream lines(ds / "scenes.jsonl");
  std::string line;
  std::getline(lines, line);
  const json scene = json::parse(line)["scene"];
  const auto& at = scene["object"]["pose"]["position"];
  // The common clock starts at the force's first stamp (1 ms after the
  // tip's); the object's pose there, linear between its stamps.
  const double t_force0 = rows.force[0][0];
  std::size_t k = 0;
  while (rows.object[k + 1][0] < t_force0) ++k;
  const double w = (t_force0 - rows.object[k][0]) / (rows.object[k + 1][0] - rows.object[k][0]);
  const double x0 = rows.object[k][1] + w * (rows.object[k + 1][1] - rows.object[k][1]);
  EXPECT_NEAR(at[0].get<double>(), x0, 2e-7);
  EXPECT_NEAR(at[1].get<double>(), dy, 2e-7);
  EXPECT_NEAR(scene["object"]["pose"]["rpy"][2].get<double>(), 0.0, 1e-9);
  // The truth's first sample is that same pose: the prediction starts where
  // the measurement does.
  const auto truth = Replay(ds);
  ASSERT_FALSE(truth.empty());
  EXPECT_NEAR(truth[0].position.x(), at[0].get<double>(), 2e-7);
  EXPECT_NEAR(truth[0].position.y(), at[1].get<double>(), 2e-7);
  // The replay cell's own workspace: around every start and the path's
  // travel (the campaign's defect profile says the same for `arena submit`).
  const auto caps = executors::MakeReplayBackend(ds.string())->Capabilities();
  ASSERT_TRUE(caps.workspace.has_value());
  const json campaign = json::parse(std::ifstream(ds / "campaign.json"));
  for (int a = 0; a < 3; ++a) {
    EXPECT_LT(caps.workspace->first[a], at[a].get<double>() - 0.04) << a;
    EXPECT_GT(caps.workspace->second[a], at[a].get<double>() + 0.04) << a;
    EXPECT_NEAR(caps.workspace->first[a], campaign["defects"]["workspace"]["min"][a], 1e-6) << a;
    EXPECT_NEAR(caps.workspace->second[a], campaign["defects"]["workspace"]["max"][a], 1e-6) << a;
  }
  EXPECT_GT(caps.workspace->second[0], at[0].get<double>() + 0.049 + 0.04);  // the push's travel
}

TEST_F(ImportTest, AForceThatReadsWhileNothingPushesIsAnOffset) {
  Rows rows = Push();
  for (auto& f : rows.force) f[1] -= 1.2;  // 1.2 N in y throughout
  WriteH5(data_ / kGoodName, rows);
  const ImportReport report = Import();
  const auto& c = report.trials[0].checks;
  EXPECT_FALSE(c.force_usable);
  EXPECT_NEAR(c.force_offset, 1.2, 0.01);
  ASSERT_FALSE(c.findings.empty());
  EXPECT_EQ(c.findings.back().check, "force_offset_drift");
}

TEST_F(ImportTest, APusherStartingDeepInsideTheOutlineFailsThePosesAndReplayRefusesIt) {
  Rows rows = Push();
  for (auto& p : rows.tip) p[2] += 0.003;  // the pusher 3 mm off the push line: still fine
  for (auto& p : rows.tip) p[1] += 0.003;  // and 3 mm further in: it starts 2 mm inside
  WriteH5(data_ / kGoodName, rows);
  const ImportReport report = Import();
  const auto& c = report.trials[0].checks;
  EXPECT_FALSE(c.pose_usable) << report.text;
  EXPECT_NEAR(c.start_gap, -0.002, 1e-4);
  ASSERT_FALSE(c.findings.empty());
  EXPECT_EQ(c.findings[0].check, "pusher_inside_at_start");
  EXPECT_TRUE(c.findings[0].fails);

  // replay:DATASET refuses to serve it (so no model is scored against it).
  const fs::path ds = root_ / "ds";
  std::ifstream lines(ds / "scenes.jsonl");
  std::string line;
  std::getline(lines, line);
  const json entry = json::parse(line);
  const auto replay = executors::MakeReplayBackend(ds.string());
  executors::TrialContext trial;
  const std::string scene_text = entry["scene"].dump();
  trial.scene_json = scene_text;
  trial.seed = std::stoull(entry["seed"].get<std::string>());
  const std::string refused = replay->Prepare(mechanics::Scene{}, trial);
  EXPECT_NE(refused.find("failed its import check of the poses"), std::string::npos) << refused;
}

TEST_F(ImportTest, ASlightlyInsideStartIsReportedAndKept) {
  Rows rows = Push();
  for (auto& p : rows.tip) p[1] += 0.0012;  // starts 0.2 mm inside: a calibration error
  WriteH5(data_ / kGoodName, rows);
  const ImportReport report = Import();
  const auto& c = report.trials[0].checks;
  EXPECT_TRUE(c.pose_usable);
  ASSERT_FALSE(c.findings.empty());
  EXPECT_EQ(c.findings[0].check, "pusher_inside_at_start");
  EXPECT_FALSE(c.findings[0].fails);
}

TEST_F(ImportTest, APushAngleOffTheStatedOneFailsThePoses) {
  // The name says t = 0.349 rad (20 deg from the inward normal); the poses push straight in.
  WriteH5(data_ / "motion_surface=abs_shape=rect1_a=0_v=50_i=0.000_s=0.500_t=0.349.h5", Push());
  const ImportReport report = Import();
  const auto& c = report.trials[0].checks;
  EXPECT_NEAR(c.push_angle, 0.0, 1e-3);
  EXPECT_FALSE(c.pose_usable) << report.text;
  ASSERT_FALSE(c.findings.empty());
  EXPECT_EQ(c.findings[0].check, "push_angle_mismatch");
  EXPECT_NE(c.findings[0].detail.find("states 20.0 deg"), std::string::npos)
      << c.findings[0].detail;
}

// Bad input: an ImportError naming the file and the reason, nothing written.
struct BadCase {
  const char* what;
  std::function<void(const fs::path& dir)> write;
  const char* file;    // the file the message must name
  const char* reason;  // a part of the reason
};

TEST_F(ImportTest, BadInputNamesTheFileAndTheReasonAndWritesNothing) {
  const std::vector<BadCase> cases = {
      {"truncated file",
       [](const fs::path& d) {
         WriteH5(d / kGoodName, Push());
         fs::resize_file(d / kGoodName, fs::file_size(d / kGoodName) / 2);
       },
       kGoodName, "truncated file"},
      {"missing dataset", [](const fs::path& d) { WriteH5(d / kGoodName, Push(), false); },
       kGoodName, "no dataset 'ft_wrench'"},
      {"NaN",
       [](const fs::path& d) {
         Rows r = Push();
         r.object[7][2] = NAN;
         WriteH5(d / kGoodName, r);
       },
       kGoodName, "NaN"},
      {"time that does not advance",
       [](const fs::path& d) {
         Rows r = Push();
         r.tip[9][0] = r.tip[8][0];  // two different rows at one instant
         WriteH5(d / kGoodName, r);
       },
       kGoodName, "time does not advance"},
      {"unknown shape",
       [](const fs::path& d) {
         WriteH5(d / "motion_surface=abs_shape=blob_a=0_v=50_i=0.000_s=0.500_t=0.000.h5", Push());
       },
       "shape=blob", "unknown shape 'blob'"},
      {"a file name without parameters",
       [](const fs::path& d) { WriteH5(d / "push_0001.h5", Push()); }, "push_0001.h5",
       "no push parameter"},
      {"a parameter that is not a number",
       [](const fs::path& d) {
         WriteH5(d / "motion_surface=abs_shape=rect1_a=0_v=fast_i=0.000_s=0.500_t=0.000.h5",
                 Push());
       },
       "v=fast", "not a number"},
      {"no .h5 file", [](const fs::path&) {}, "abs", "holds no .h5 file"},
  };
  for (const auto& bad : cases) {
    SCOPED_TRACE(bad.what);
    fs::remove_all(data_);
    fs::create_directories(data_);
    WriteH5(data_ / "motion_surface=abs_shape=rect1_a=0_v=50_i=0.000_s=0.400_t=0.000.h5",
            Push());  // a good file beside the bad one: still nothing is written
    if (std::string(bad.what) == "no .h5 file")
      fs::remove_all(data_), fs::create_directories(data_);
    bad.write(data_);
    try {
      Import();
      ADD_FAILURE() << "imported";
    } catch (const ImportError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(bad.file), std::string::npos) << msg;
      EXPECT_NE(msg.find(bad.reason), std::string::npos) << msg;
    }
    ExpectNothingWritten();
  }
}

TEST_F(ImportTest, AnExistingDatasetIsNeverOverwritten) {
  WriteH5(data_ / kGoodName, Push());
  fs::create_directories(root_ / "ds");
  std::ofstream(root_ / "ds" / "keep.txt") << "mine";
  EXPECT_THROW(Import(), ImportError);
  EXPECT_TRUE(fs::exists(root_ / "ds" / "keep.txt"));
}

TEST(PushFileName, ParsesEveryParameter) {
  const auto p =
      ParsePushFileName("/x/motion_surface=abs_shape=ellip3_a=0_v=75_i=0.000_s=0.775_t=-1.047.h5");
  EXPECT_EQ(p.surface, "abs");
  EXPECT_EQ(p.shape, "ellip3");
  EXPECT_EQ(p.v, 75);
  EXPECT_DOUBLE_EQ(p.s, 0.775);
  EXPECT_DOUBLE_EQ(p.t, -1.047);
}

TEST(SignedDistance, OfANonConvexOutline) {
  // An L: the notch's corner (0.5, 0.5) is inside the hull but outside the L.
  const std::vector<std::array<double, 2>> l = {{0, 0},     {1, 0},   {1, 0.5},
                                                {0.5, 0.5}, {0.5, 1}, {0, 1}};
  EXPECT_NEAR(SignedDistance(l, 0.75, 0.75), 0.25, 1e-12);  // to the notch's two edges
  EXPECT_NEAR(SignedDistance(l, 1.2, 1.2), std::hypot(0.2, 0.7), 1e-12);  // to the corner (1, 0.5)
  EXPECT_NEAR(SignedDistance(l, 0.25, 0.25), -0.25, 1e-12);
  EXPECT_NEAR(SignedDistance(l, -0.1, 0.5), 0.1, 1e-12);
}

}  // namespace
}  // namespace arena::recordings
