// Cell backends without DDS: model and mujoco behind one interface, the
// defect layer's combination and refusals, replay:DATASET's matching, and
// exec:COMMAND against real driver processes (examples/drivers/replay.py)
// failing in every way the protocol names: malformed output, a crash, a
// hang, NaN, out-of-order timestamps. After each failure the backend starts
// the driver afresh and the next trial runs whole.
#include <hdf5.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/executors/backend.hpp"
#include "arena/executors/defect_layer.hpp"
#include "arena/executors/exec_protocol.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "defects_json.hpp"

namespace arena::executors {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string ShortScene(double grip = 10.0) {
  json s =
      json::parse(std::ifstream(std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json"));
  s["duration"] = 0.1;
  s["grip_force"] = grip;
  return s.dump();
}

// The fixture's dataset as `arena export --format hdf5` lays it out
// (db/export.hpp): manifest, scenes.jsonl, dataset.h5 with /trials/ID/true
// (float64, samples x columns, attribute "columns"). `damage`: "" (whole),
// "missing" (trial 2's stream gone), "integers" (trial 2's stream of ints),
// "truncated" (the file cut in half).
std::string WriteHdf5Dataset(const std::string& from, const std::string& damage) {
  const std::string dir = from + "/h5-" + (damage.empty() ? "whole" : damage);
  fs::create_directories(dir);
  json manifest = json::parse(std::ifstream(from + "/manifest.json"));
  manifest["export_format"] = "hdf5";
  std::ofstream(dir + "/manifest.json") << manifest.dump();
  fs::copy_file(from + "/scenes.jsonl", dir + "/scenes.jsonl");
  const std::string path = dir + "/dataset.h5";
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  H5Gclose(H5Gcreate2(file, "trials", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
  for (int id : {1, 2}) {
    std::vector<std::string> columns;
    std::vector<double> flat;
    hsize_t rows = 0;
    std::ifstream in(from + "/streams/" + std::to_string(id) + "_true.jsonl");
    for (std::string line; std::getline(in, line); ++rows) {
      const json row = json::parse(line);
      if (columns.empty())
        for (auto it = row.begin(); it != row.end(); ++it) columns.push_back(it.key());
      for (const auto& c : columns) flat.push_back(row[c].get<double>());
    }
    const std::string group = "trials/" + std::to_string(id);
    H5Gclose(H5Gcreate2(file, group.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
    if (id == 2 && damage == "missing") continue;
    const hsize_t dims[2] = {rows, columns.size()};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const bool ints = id == 2 && damage == "integers";
    const hid_t ds =
        H5Dcreate2(file, (group + "/true").c_str(), ints ? H5T_STD_I32LE : H5T_IEEE_F64LE, space,
                   H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    std::vector<int> as_ints(flat.begin(), flat.end());
    if (ints)
      H5Dwrite(ds, H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, as_ints.data());
    else
      H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, flat.data());
    size_t width = 1;
    for (const auto& c : columns) width = std::max(width, c.size() + 1);
    std::string names(width * columns.size(), '\0');
    for (size_t k = 0; k < columns.size(); ++k)
      names.replace(k * width, columns[k].size(), columns[k]);
    const hid_t type = H5Tcopy(H5T_C_S1);
    H5Tset_size(type, width);
    const hsize_t n[1] = {columns.size()};
    const hid_t aspace = H5Screate_simple(1, n, nullptr);
    const hid_t attr = H5Acreate2(ds, "columns", type, aspace, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attr, type, names.data());
    H5Aclose(attr);
    H5Sclose(aspace);
    H5Tclose(type);
    H5Dclose(ds);
    H5Sclose(space);
  }
  H5Fclose(file);
  if (damage == "truncated") fs::resize_file(path, fs::file_size(path) / 2);
  return dir;
}

// An export-format dataset (jsonl) of the given scenes, the truth from arena's model.
class Dataset : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/arena-backends-test-XXXXXX";
    dir_ = mkdtemp(tmpl);
    fs::create_directories(dir_ + "/streams");
    std::ofstream scenes(dir_ + "/scenes.jsonl");
    json trials = json::array();
    int id = 1;
    for (double grip : {10.0, 12.0}) {
      const std::string text = ShortScene(grip);
      scenes << json({{"trial_id", id}, {"seed", "7"}, {"scene", json::parse(text)}}).dump()
             << "\n";
      WriteStream(id, mechanics::ParseScene(text));
      trials.push_back({{"trial_id", id}, {"samples", samples_}});
      ++id;
    }
    // The manifest's part replay reads (an export's also lists files and checksums).
    std::ofstream(dir_ + "/manifest.json")
        << json({{"export_format", "jsonl"}, {"trials", trials}}).dump();
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }
  void WriteStream(int id, const mechanics::Scene& scene) {
    const auto r = mechanics::Simulate(scene);
    ASSERT_EQ(r.status, mechanics::SimulationStatus::kOk);
    samples_ = r.samples.size();
    std::ofstream out(dir_ + "/streams/" + std::to_string(id) + "_true.jsonl");
    std::vector<std::string> names = {"left", "right", "pusher"};
    std::vector<Eigen::Vector3d> normals = {{1, 0, 0}, {-1, 0, 0}, {0, 0, 1}};
    for (const auto& s : r.samples) {
      json row = {{"t", s.t},
                  {"x", s.position.x()},
                  {"y", s.position.y()},
                  {"z", s.position.z()},
                  {"qw", s.orientation.w()},
                  {"qx", s.orientation.x()},
                  {"qy", s.orientation.y()},
                  {"qz", s.orientation.z()},
                  {"vx", s.velocity.x()},
                  {"vy", s.velocity.y()},
                  {"vz", s.velocity.z()},
                  {"wx", s.angular_velocity.x()},
                  {"wy", s.angular_velocity.y()},
                  {"wz", s.angular_velocity.z()},
                  {"pusher_x", s.pusher_position.x()},
                  {"pusher_y", s.pusher_position.y()},
                  {"pusher_z", s.pusher_position.z()}};
      for (size_t c = 0; c < 3; ++c) {
        const auto& cs = s.contacts[c];
        const Eigen::Vector3d f = cs.normal_force * normals[c] + cs.tangential_force;
        row[names[c] + "_fx"] = f.x();
        row[names[c] + "_fy"] = f.y();
        row[names[c] + "_fz"] = f.z();
        row[names[c] + "_tx"] = cs.torque.x();
        row[names[c] + "_ty"] = cs.torque.y();
        row[names[c] + "_tz"] = cs.torque.z();
        row[names[c] + "_mode"] = static_cast<int>(cs.mode);
      }
      out << row.dump() << "\n";
    }
  }

  // Runs one trial as the cell does (CheckTrueSample on every sample).
  struct Run {
    std::string refused;
    ExecuteOutcome outcome;
    std::vector<mechanics::TrajectorySample> samples;
    std::string rejected;  // the cell's reason for stopping the stream
  };
  Run RunTrial(Backend& backend, const std::string& text, std::uint64_t seed = 7) {
    Run run;
    const auto scene = mechanics::ParseScene(text);
    TrialContext trial;
    trial.trial_id = ++trial_id_;
    trial.seed = seed;
    trial.scene_json = text;
    trial.deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    run.refused = backend.Prepare(scene, trial);
    if (!run.refused.empty()) return run;
    run.outcome = backend.Execute(scene, trial, [&](const mechanics::TrajectorySample& s) {
      run.rejected = CheckTrueSample(s, run.samples, scene);
      if (!run.rejected.empty()) return false;
      run.samples.push_back(s);
      return true;
    });
    return run;
  }

  std::unique_ptr<Backend> Driver(const std::string& mode) {
    ExecBackendOptions o;
    o.command =
        "python3 " + std::string(ARENA_SOURCE_DIR) + "/examples/drivers/replay.py " + dir_ +
        (mode.empty() ? "" : " --fail-mode " + mode + " --fail-once " + dir_ + "/failed-" + mode);
    o.reply_timeout_s = 2;
    return MakeExecBackend(o);
  }

  // The failure kind fails one trial with `reason`; the restarted driver serves the next whole.
  void ExpectFailsThenRecovers(const std::string& mode, const std::string& reason) {
    auto backend = Driver(mode);
    const Run bad = RunTrial(*backend, ShortScene(10));
    ASSERT_EQ(bad.refused, "");
    EXPECT_FALSE(bad.outcome.ok);
    EXPECT_NE((bad.outcome.reason + " | " + bad.rejected).find(reason), std::string::npos)
        << bad.outcome.reason << " | " << bad.rejected;
    const Run good = RunTrial(*backend, ShortScene(10));
    ASSERT_EQ(good.refused, "");
    EXPECT_TRUE(good.outcome.ok) << good.outcome.reason;
    EXPECT_EQ(good.samples.size(), samples_);
  }

  std::string dir_;
  size_t samples_ = 0;
  std::uint64_t trial_id_ = 0;
};

TEST(SimulatorBackends, ModelAndMujocoRunTheSameScene) {
  const std::string text = ShortScene();
  const auto scene = mechanics::ParseScene(text);
  for (const char* name : {"model", "mujoco"}) {
    auto backend = MakeBackend(name, ModelFidelity{});
    const auto caps = backend->Capabilities();
    EXPECT_EQ(caps.name, name);
    EXPECT_EQ(caps.truth, std::string(name) == "model" ? TruthSource::kSelfConsistency
                                                       : TruthSource::kSimulator);
    TrialContext trial;
    trial.scene_json = text;
    ASSERT_EQ(backend->Prepare(scene, trial), "");
    std::vector<mechanics::TrajectorySample> got;
    const auto out = backend->Execute(scene, trial, [&](const mechanics::TrajectorySample& s) {
      EXPECT_EQ(CheckTrueSample(s, got, scene), "");
      got.push_back(s);
      return true;
    });
    ASSERT_TRUE(out.ok) << out.reason;
    EXPECT_EQ(got.size(), 26u);
    EXPECT_NEAR(got.back().position.z(), 0.001, 1e-4) << name;  // 1 cm/s for 0.1 s, sliding
  }
  EXPECT_THROW(MakeBackend("bullet", ModelFidelity{}), std::invalid_argument);
  EXPECT_THROW(MakeBackend("mujoco", ModelFidelity{}, R"({"timestep": 1})"), std::invalid_argument);
}

TEST(DefectLayerTest, CombinesProfilesAndRefusesWhatItCannotApply) {
  DefectProfile cell, campaign;
  cell.position_std.setConstant(3e-4);
  campaign.position_std.setConstant(4e-4);
  cell.latency_ms = 2;
  campaign.latency_ms = 4;
  cell.drop_probability = 0.1;
  campaign.drop_probability = 0.2;
  campaign.workspace_max.setConstant(1.0);  // a campaign cannot widen the cell's workspace
  const DefectProfile p = CombineProfiles(cell, campaign);
  EXPECT_NEAR(p.position_std.x(), 5e-4, 1e-12);
  EXPECT_DOUBLE_EQ(p.latency_ms, 6);
  EXPECT_NEAR(p.drop_probability, 0.28, 1e-12);
  EXPECT_EQ(p.workspace_max, cell.workspace_max);

  const std::string text = ShortScene();
  const auto scene = mechanics::ParseScene(text);
  TrialContext trial;
  trial.scene_json = text;
  DefectLayer sim(MakeBackend("model", ModelFidelity{}), DefectProfile{});
  EXPECT_EQ(sim.Prepare(scene, R"({"friction_variability": {"mu_scale_std": 0.1}})", trial), "");
  EXPECT_NE(sim.Prepare(scene, R"({"latency": 3})", trial).find("defects_json: "),
            std::string::npos);  // a bad campaign profile names its field
}

// The cell's status carries the applied defects as text spliced from a cache
// of their profiles' part (issue 27): it must be the tree's own dump, for
// each trial's perturbation and after the campaign profile changes.
TEST(DefectLayerTest, TheAppliedDefectsTextIsTheTreesDumpAsTheProfileChanges) {
  DefectProfile cell;
  cell.position_std.setConstant(3e-4);
  DefectLayer layer(MakeBackend("model", ModelFidelity{}), cell);
  const std::string text = ShortScene();
  const auto scene = mechanics::ParseScene(text);
  const char* profiles[] = {R"({"friction_variability": {"mu_scale_std": 0.1}})", "{}",
                            R"({"latency_ms": 4, "friction_variability": {"mu_scale_std": 0.2}})",
                            R"({"friction_variability": {"mu_scale_std": 0.1}})"};
  std::uint64_t seed = 1;
  for (const char* profile : profiles) {
    for (int trial_id = 1; trial_id <= 2; ++trial_id) {
      TrialContext trial;
      trial.scene_json = text;
      trial.seed = seed++;
      trial.trial_id = trial_id;
      ASSERT_EQ(layer.Prepare(scene, profile, trial), "") << profile;
      ASSERT_TRUE(
          layer.Execute(scene, trial, [](const mechanics::TrajectorySample&) { return true; }).ok);
      EXPECT_EQ(internal::AppliedDefectsText(layer), layer.AppliedJson()) << profile;
      EXPECT_EQ(json::parse(internal::AppliedDefectsText(layer)),
                internal::AppliedDefectsTree(layer));
    }
  }
}

TEST_F(Dataset, ReplayServesMatchingScenesAndRefusesOthers) {
  auto replay = MakeReplayBackend(dir_);
  EXPECT_EQ(replay->Capabilities().truth, TruthSource::kRecorded);
  EXPECT_FALSE(replay->Capabilities().emulates_defects);
  Run run = RunTrial(*replay, ShortScene(12));
  ASSERT_EQ(run.refused, "");
  ASSERT_TRUE(run.outcome.ok) << run.outcome.reason;
  EXPECT_EQ(run.samples.size(), samples_);
  EXPECT_NE(run.outcome.detail_json.find("\"recorded_trial\":2"), std::string::npos);
  // The predictor's settings (model) do not matter; the physics does.
  json other_model = json::parse(ShortScene(12));
  other_model["model"]["facets"] = 4;
  EXPECT_EQ(RunTrial(*replay, other_model.dump()).refused, "");
  const Run missing = RunTrial(*replay, ShortScene(11));
  EXPECT_NE(missing.refused.find("holds no trial with this scene"), std::string::npos)
      << missing.refused;
  // Recorded physics cannot be perturbed: such a campaign is refused, not run without it.
  DefectLayer layer(MakeReplayBackend(dir_), DefectProfile{});
  const std::string text = ShortScene(12);
  TrialContext trial;
  trial.scene_json = text;
  EXPECT_NE(layer
                .Prepare(mechanics::ParseScene(text),
                         R"({"friction_variability": {"mu_scale_std": 0.05}})", trial)
                .find("cannot"),
            std::string::npos);
  EXPECT_EQ(layer.Prepare(mechanics::ParseScene(text), R"({"latency_ms": 4})", trial), "");
  EXPECT_THROW(MakeReplayBackend(dir_ + "/nowhere"), std::invalid_argument);
}

TEST_F(Dataset, ReplayServesHdf5ExportsAndNamesWhatIsWrongWithThem) {
  // The same trials through the HDF5 reader: matched as in csv and jsonl,
  // the same samples, the same refusal.
  auto jsonl = MakeReplayBackend(dir_);
  auto hdf5 = MakeReplayBackend(WriteHdf5Dataset(dir_, ""));
  EXPECT_NE(hdf5->Capabilities().engine.find("hdf5"), std::string::npos);
  const Run a = RunTrial(*jsonl, ShortScene(12)), b = RunTrial(*hdf5, ShortScene(12));
  ASSERT_TRUE(b.outcome.ok) << b.outcome.reason << b.rejected;
  ASSERT_EQ(b.samples.size(), samples_);
  ASSERT_EQ(a.samples.size(), b.samples.size());
  for (size_t i = 0; i < a.samples.size(); ++i) {
    EXPECT_EQ(a.samples[i].t, b.samples[i].t);
    EXPECT_EQ(a.samples[i].position, b.samples[i].position);
    EXPECT_EQ(a.samples[i].contacts[2].normal_force, b.samples[i].contacts[2].normal_force);
  }
  EXPECT_NE(b.outcome.detail_json.find("\"recorded_trial\":2"), std::string::npos);
  EXPECT_NE(RunTrial(*hdf5, ShortScene(11)).refused.find("holds no trial with this scene"),
            std::string::npos);

  // A broken file stops the backend at start, naming the file, the object and the reason.
  const auto error = [&](const std::string& damage) {
    try {
      MakeReplayBackend(WriteHdf5Dataset(dir_, damage));
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  const std::string missing = error("missing"), ints = error("integers"), cut = error("truncated");
  EXPECT_NE(missing.find("h5-missing/dataset.h5: /trials/2/true: missing"), std::string::npos)
      << missing;
  EXPECT_NE(ints.find("dataset.h5: /trials/2/true: holds 32-bit integers, expected 64-bit floats"),
            std::string::npos)
      << ints;
  EXPECT_NE(cut.find("h5-truncated/dataset.h5: "), std::string::npos) << cut;
  EXPECT_NE(cut.find("truncated"), std::string::npos) << cut;
}

TEST_F(Dataset, ExecDriverServesTrialsAndRefusesUnknownScenes) {
  auto backend = Driver("");
  const auto caps = backend->Capabilities();
  EXPECT_EQ(caps.truth, TruthSource::kRecorded);
  EXPECT_NE(caps.engine.find("recorded dataset"), std::string::npos);
  for (int k = 0; k < 2; ++k) {
    const Run run = RunTrial(*backend, ShortScene(10));
    ASSERT_EQ(run.refused, "");
    ASSERT_TRUE(run.outcome.ok) << run.outcome.reason;
    ASSERT_EQ(run.samples.size(), samples_);
    EXPECT_NEAR(run.samples.back().position.z(), 0.001, 1e-4);
  }
  EXPECT_NE(RunTrial(*backend, ShortScene(11)).refused.find("driver refused"), std::string::npos);
}

TEST_F(Dataset, ExecDriverResetsWhenItSaysItCan) {
  // Without "resets": the cell's own (simulated) reset runs: nullopt.
  BackendResetRequest request;
  request.target.position = {0.001, 0, 0.002};
  EXPECT_FALSE(Driver("")->Reset(request, TrialContext{}).has_value());
  ExecBackendOptions o;
  o.command = "python3 " + std::string(ARENA_SOURCE_DIR) + "/examples/drivers/replay.py " + dir_ +
              " --resets";
  auto backend = MakeExecBackend(o);
  const auto out = backend->Reset(request, TrialContext{});
  ASSERT_TRUE(out.has_value());
  EXPECT_TRUE(out->ok) << out->reason;
  EXPECT_EQ(out->attempts, 1);
  EXPECT_TRUE(out->achieved.position.isApprox(request.target.position));
}

TEST_F(Dataset, ExecMalformedOutputFailsThePhase) {
  ExpectFailsThenRecovers("malformed", "malformed output");
}
TEST_F(Dataset, ExecCrashFailsThePhase) {
  ExpectFailsThenRecovers("crash", "exited with status 3");
}
TEST_F(Dataset, ExecHangFailsThePhase) { ExpectFailsThenRecovers("hang", "driver hung"); }
TEST_F(Dataset, ExecNaNFailsThePhase) { ExpectFailsThenRecovers("nan", "NaN"); }
TEST_F(Dataset, ExecOutOfOrderTimestampsFailThePhase) {
  ExpectFailsThenRecovers("disorder", "out of order");
}

TEST_F(Dataset, ExecDriverThatNeverSaysHelloIsRefusedAtStart) {
  ExecBackendOptions o;
  o.command = "sleep 30";
  o.hello_timeout_s = 0.5;
  EXPECT_THROW(MakeExecBackend(o), std::invalid_argument);
  o.command = "echo '{\"type\":\"hello\",\"protocol\":99}'";
  try {
    MakeExecBackend(o);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("protocol 99"), std::string::npos) << e.what();
  }
}

// Issue 28: what replay serves is what was recorded. Each tampering is
// refused, at start (the dataset's shape) or when the trial is served (its
// stream), with the reason.
TEST_F(Dataset, ReplayRefusesTamperedDatasets) {
  int refused = 0;
  const auto expect_start_refused = [&](const std::string& why, const std::string& dir) {
    try {
      MakeReplayBackend(dir);
      ADD_FAILURE() << "accepted: " << why;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
      ++refused;
    }
  };
  const auto copy = [&](const std::string& name) {
    const std::string to = dir_ + "/" + name;
    fs::create_directories(to);
    fs::copy(dir_ + "/streams", to + "/streams", fs::copy_options::recursive);
    fs::copy_file(dir_ + "/scenes.jsonl", to + "/scenes.jsonl");
    fs::copy_file(dir_ + "/manifest.json", to + "/manifest.json");
    return to;
  };
  {  // trial 2's line says trial 1: trial 2's scene would be served trial 1's data
    const std::string d = copy("dup");
    std::ifstream in(d + "/scenes.jsonl");
    std::string a, b;
    std::getline(in, a);
    std::getline(in, b);
    in.close();
    json jb = json::parse(b);
    jb["trial_id"] = 1;
    std::ofstream(d + "/scenes.jsonl") << a << "\n" << jb.dump() << "\n";
    expect_start_refused("trial 1 again", d);
  }
  {  // a stream that is a link to a file elsewhere
    const std::string d = copy("link");
    fs::copy_file(d + "/streams/2_true.jsonl", dir_ + "/elsewhere.jsonl");
    fs::remove(d + "/streams/2_true.jsonl");
    fs::create_symlink(dir_ + "/elsewhere.jsonl", d + "/streams/2_true.jsonl");
    expect_start_refused("symbolic link", d);
  }
  {  // the manifest points a stream outside the dataset
    const std::string d = copy("outside");
    json m = json::parse(std::ifstream(d + "/manifest.json"));
    m["trials"][1]["true_file"] = "../elsewhere.jsonl";
    std::ofstream(d + "/manifest.json") << m.dump();
    expect_start_refused("leads outside the dataset", d);
  }
  {  // a trial listed twice in the manifest
    const std::string d = copy("twice");
    json m = json::parse(std::ifstream(d + "/manifest.json"));
    m["trials"][1]["trial_id"] = 1;
    std::ofstream(d + "/manifest.json") << m.dump();
    expect_start_refused("listed twice", d);
  }
  const auto expect_serve_refused = [&](const std::string& why, const std::string& dir,
                                        const std::function<void()>& after_start = nullptr) {
    auto replay = MakeReplayBackend(dir);
    if (after_start) after_start();
    const Run run = RunTrial(*replay, ShortScene(12));
    ASSERT_EQ(run.refused, "");
    EXPECT_FALSE(run.outcome.ok) << why;
    EXPECT_NE(run.outcome.reason.find(why), std::string::npos) << run.outcome.reason;
    refused += !run.outcome.ok;
  };
  const auto rewrite = [](const std::string& path, const std::function<void(json&, int)>& edit,
                          int keep_rows) {
    std::ifstream in(path);
    std::vector<json> rows;
    for (std::string line; std::getline(in, line);) rows.push_back(json::parse(line));
    in.close();
    std::ofstream out(path);
    for (int i = 0; i < static_cast<int>(rows.size()) && i < keep_rows; ++i) {
      edit(rows[static_cast<size_t>(i)], i);
      out << rows[static_cast<size_t>(i)].dump() << "\n";
    }
  };
  {  // a contact mode of 7.5
    const std::string d = copy("mode");
    rewrite(
        d + "/streams/2_true.jsonl",
        [](json& r, int i) {
          if (i == 3) r["left_mode"] = 7.5;
        },
        1 << 20);
    expect_serve_refused("is no contact mode", d);
  }
  {  // the stream cut short (the manifest recorded more rows)
    const std::string d = copy("cut");
    rewrite(
        d + "/streams/2_true.jsonl", [](json&, int) {}, 10);
    expect_serve_refused("rows, not the " + std::to_string(samples_), d);
  }
  {  // the object moved 5 cm after the cell verified the dataset
    const std::string d = copy("moved");
    expect_serve_refused("changed since the cell verified", d, [&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // a new mtime
      rewrite(
          d + "/streams/2_true.jsonl", [](json& r, int) { r["x"] = r["x"].get<double>() + 0.05; },
          1 << 20);
    });
  }
  std::printf("replay: %d of 7 tampered datasets refused\n", refused);
  // The untouched dataset still serves (without the copies made inside it).
  for (const char* copied : {"dup", "link", "outside", "twice", "mode", "cut", "moved"})
    fs::remove_all(dir_ + "/" + copied);
  auto replay = MakeReplayBackend(dir_);
  EXPECT_TRUE(RunTrial(*replay, ShortScene(12)).outcome.ok);
}

// A stream longer than its scene (a 0.1 s push reported as 100 s) is not a
// recording of that push: the cell's check stops it at the first sample past
// the scene's end; one that ends early is refused when it ends.
TEST(StreamLength, StreamsThatDoNotMatchTheSceneAreRefused) {
  const auto scene = mechanics::ParseScene(ShortScene());
  auto sample = [](double t) {
    mechanics::TrajectorySample s;
    s.t = t;
    s.contacts.resize(3);
    return s;
  };
  std::vector<mechanics::TrajectorySample> before;
  for (int k = 0; k <= 25; ++k) {
    ASSERT_EQ(CheckTrueSample(sample(0.004 * k), before, scene), "") << k;
    before.push_back(sample(0.004 * k));
  }
  EXPECT_NE(CheckTrueSample(sample(0.2), before, scene).find("past the scene's duration"),
            std::string::npos);
  EXPECT_NE(CheckTrueSample(sample(100.0), before, scene).find("past the scene's duration"),
            std::string::npos);
}

// Exec drivers: 1e999 is named for what it is; a driver that keeps streaming
// past the deadline is not "hung"; its stderr reaches the log capped.
TEST_F(Dataset, ExecDriverOutputsAreNamedAndItsStderrIsCapped) {
  const std::string script = dir_ + "/driver.py";
  std::ofstream(script) << R"PY(
import json, os, sys
def send(m):
    sys.stdout.write(json.dumps(m) + "\n"); sys.stdout.flush()
send({"type": "hello", "protocol": 1, "name": "t", "truth": "robot",
      "contact_types": ["point", "line", "patch"]})
marker = sys.argv[1]
for line in sys.stdin:
    m = json.loads(line)
    if m["type"] == "prepare":
        send({"type": "ready"})
    elif m["type"] == "execute":
        sys.stderr.write(("x" * 999 + "\n") * 4000)   # 4 MB of stderr
        sys.stderr.flush()
        if not os.path.exists(marker):   # the first trial (the driver restarts after it)
            open(marker, "w").close()
            sys.stdout.write('{"type": "sample", "t": 1e999}\n'); sys.stdout.flush()
        else:
            k = 0
            while True:   # streams, never says done
                send({"type": "log", "text": "sample %d" % k}); k += 1
    elif m["type"] == "shutdown":
        break
)PY";
  ExecBackendOptions o;
  o.command = "python3 " + script + " " + dir_ + "/first-done";
  o.log_path = dir_ + "/driver.log";
  o.reply_timeout_s = 30;
  auto backend = MakeExecBackend(o);
  const auto scene = mechanics::ParseScene(ShortScene());
  TrialContext trial;
  trial.scene_json = ShortScene();
  trial.deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  ASSERT_EQ(backend->Prepare(scene, trial), "");
  auto out =
      backend->Execute(scene, trial, [](const mechanics::TrajectorySample&) { return true; });
  EXPECT_FALSE(out.ok);
  EXPECT_NE(out.reason.find("out of range"), std::string::npos) << out.reason;
  EXPECT_EQ(out.reason.find("not JSON"), std::string::npos) << out.reason;

  trial.deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  ASSERT_EQ(backend->Prepare(scene, trial), "");
  // Long enough for a loaded machine to start the restarted driver and let it
  // stream: at the deadline it is still sending.
  trial.deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  out = backend->Execute(scene, trial, [](const mechanics::TrajectorySample&) { return true; });
  EXPECT_FALSE(out.ok);
  EXPECT_NE(out.reason.find("overran the phase's deadline: still sending"), std::string::npos)
      << out.reason;
  EXPECT_EQ(out.reason.find("hung"), std::string::npos) << out.reason;
  backend.reset();
  // 8 MB written on stderr over two trials; the log holds at most 64 KiB a phase.
  const auto bytes = fs::file_size(dir_ + "/driver.log");
  EXPECT_LT(bytes, 3u * (64u << 10)) << bytes;
  EXPECT_GT(bytes, 32u << 10) << bytes;
  std::ifstream log(dir_ + "/driver.log");
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("the rest of it is dropped"), std::string::npos);
}

TEST(ExecProtocol, SamplesRoundTrip) {
  mechanics::TrajectorySample s;
  s.t = 0.004;
  s.position = {1, 2, 3};
  s.contacts.resize(2);
  s.contacts[1].mode = mechanics::ContactMode::kSlide;
  mechanics::TrajectorySample back;
  ASSERT_EQ(exec::ParseSample(exec::SampleToJson(s), &back), "");
  EXPECT_EQ(back.position, s.position);
  EXPECT_EQ(back.contacts[1].mode, mechanics::ContactMode::kSlide);
  json bad = exec::SampleToJson(s);
  bad.erase("orientation");
  EXPECT_NE(exec::ParseSample(bad, &back).find("orientation"), std::string::npos);
}

}  // namespace
}  // namespace arena::executors
