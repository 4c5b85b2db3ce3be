// arena plot TRIAL: a real store with a claimed, executed trial whose ground
// truth is the model's own high-fidelity run (observed = truth + offsets, some
// samples dropped); the chart must parse as SVG and carry every panel and
// series, the predicted series must be the campaign's (coarser) model, and
// the command must refuse what it cannot plot with exit 2.
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <gtest/gtest.h>
#include <tinyxml2.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/truth.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/orchestrator/submit.hpp"
#include "plot_trial.hpp"

namespace arena::cli {
namespace {

class PlotTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/arena-plot-test-XXXXXX";
    dir_ = mkdtemp(tmpl);
    db_ = dir_ + "/plot.db";
    Populate(std::string(ARENA_SOURCE_DIR) + "/tests/orchestrator/data/e2e60.json");
  }
  // Submits the campaign file and stores ground truth for its first trial.
  void Populate(const std::string& campaign_file) {
    auto store = db::Store::Open(db_);
    const auto campaign = orchestrator::LoadCampaignFile(campaign_file);
    campaign_ = orchestrator::SubmitCampaign(*store, campaign);
    store->UpsertCell("c1", {"point", "line"});
    const auto claimed = store->ClaimNextTrial("c1");
    ASSERT_TRUE(claimed);
    trial_ = claimed->trial_id;
    // A second trial stays planned: no ground truth to plot.
    planned_ = store->PeekNextTrial("c1")->trial_id;

    const mechanics::Scene scene = mechanics::ParseScene(claimed->scene_json);
    const auto truth = mechanics::Simulate(scene);
    ASSERT_EQ(truth.status, mechanics::SimulationStatus::kOk) << truth.error;
    samples_ = truth.samples.size();
    const auto normals = assessment::ContactNormals(scene);
    auto ingest =
        store->BeginIngest(trial_, claimed->attempt, orchestrator::SceneFactsOf(scene).contacts);
    for (size_t i = 0; i < truth.samples.size(); ++i) {
      const auto& s = truth.samples[i];
      db::Sample d;
      d.t = s.t;
      const auto& q = s.orientation;
      d.object_pose = {s.position.x(), s.position.y(), s.position.z(), q.w(), q.x(), q.y(), q.z()};
      d.pusher_pose[0] = s.pusher_position.x();
      for (size_t c = 0; c < s.contacts.size(); ++c) {
        const Eigen::Vector3d f =
            s.contacts[c].normal_force * normals[c] + s.contacts[c].tangential_force;
        db::ContactWrench w;
        w.force = {f.x(), f.y(), f.z()};
        d.contacts.push_back(w);
        if (c < scene.fingers.size()) {
          for (int k = 0; k < 3; ++k) d.observed_finger_wrenches.push_back(f[k] + 0.1);
          for (int k = 0; k < 3; ++k) d.observed_finger_wrenches.push_back(0);
        } else {
          for (int k = 0; k < 3; ++k) d.observed_pusher_wrench[k] = f[k] + 0.1;
        }
      }
      d.observed_valid = i % 10 != 5;  // every tenth sample dropped
      d.observed_object_pose = d.object_pose;
      d.observed_object_pose[2] += 1e-4;
      ingest->Add(d);
    }
    ingest->Finish();
  }
  void TearDown() override {
    if (!HasFailure()) std::filesystem::remove_all(dir_);
  }

  std::string dir_, db_;
  std::int64_t campaign_ = 0, trial_ = 0, planned_ = 0;
  size_t samples_ = 0;
};

// data-name of every series, per panel title.
std::map<std::string, std::vector<std::string>> SeriesByPanel(
    const tinyxml2::XMLDocument& doc, std::map<std::string, int>* points = nullptr) {
  std::map<std::string, std::vector<std::string>> out;
  const auto* root = doc.FirstChildElement("svg");
  for (const auto* g = root->FirstChildElement("g"); g; g = g->NextSiblingElement("g")) {
    const std::string title = g->Attribute("data-title");
    for (const auto* s = g->FirstChildElement("g"); s; s = s->NextSiblingElement("g")) {
      out[title].push_back(s->Attribute("data-name"));
      if (points) {
        // A line's points, or a marker series' circles.
        const auto* line = s->FirstChildElement("polyline");
        std::istringstream in(line && line->Attribute("points") ? line->Attribute("points") : "");
        std::string p;
        int n = 0;
        while (in >> p) ++n;
        for (const auto* c = s->FirstChildElement("circle"); c; c = c->NextSiblingElement("circle"))
          ++n;
        (*points)[title + "/" + s->Attribute("data-name")] = n;
      }
    }
  }
  return out;
}

TEST_F(PlotTest, ChartHasPosePanelsAndOneForcePanelPerContact) {
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(db_, ro);
  TrialPlotInfo info;
  const Chart chart = MakeTrialChart(*store, trial_, &info);
  EXPECT_EQ(info.prediction_status, arena::db::PredictionStatus::kOk);
  // The campaign's "prediction", not the scene's model.
  EXPECT_EQ(info.model_key, "g4_k2_dt0.008_auto_cone-aligned_inertia-auto");
  EXPECT_EQ(info.samples, samples_);
  const std::string svg = RenderSvg(chart);
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  std::map<std::string, int> points;
  const auto panels = SeriesByPanel(doc, &points);
  // x, y, z, rotation + two fingers + the pusher.
  ASSERT_EQ(panels.size(), 7u) << svg.substr(0, 2000);
  const std::vector<std::string> pose = {"observed", "true", "predicted"};
  const std::vector<std::string> force = {"normal observed",  "tangential observed",
                                          "normal true",      "tangential true",
                                          "normal predicted", "tangential predicted"};
  int pose_panels = 0, force_panels = 0;
  for (const auto& [title, names] : panels) {
    if (title.rfind("object", 0) == 0) {
      EXPECT_EQ(names, pose) << title;
      ++pose_panels;
    } else {
      EXPECT_EQ(names, force) << title;
      ++force_panels;
    }
  }
  EXPECT_EQ(pose_panels, 4);
  EXPECT_EQ(force_panels, 3);
  EXPECT_TRUE(panels.count("pusher contact force on the object"));
  EXPECT_TRUE(panels.count("object position z (gripper frame)"));
  // Every true sample is drawn; observed lacks the dropped tenth; the
  // prediction (dt 0.008) still reports at 250 Hz over the same duration.
  EXPECT_EQ(points["object position z (gripper frame)/true"], static_cast<int>(samples_));
  EXPECT_EQ(points["object position z (gripper frame)/observed"],
            static_cast<int>(samples_ - (samples_ + 4) / 10));
  EXPECT_GT(points["object position z (gripper frame)/predicted"], static_cast<int>(samples_) / 2);
  EXPECT_GT(points["pusher contact force on the object/normal predicted"], 0);
}

// A campaign predicted by MuJoCo is drawn with MuJoCo's trajectory (the
// plot re-runs the campaign's predictor, not arena's model).
class MujocoPlotTest : public PlotTest {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/arena-plot-test-XXXXXX";
    dir_ = mkdtemp(tmpl);
    db_ = dir_ + "/mujoco.db";
    std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/tests/orchestrator/data/e2e60.json");
    nlohmann::json spec = nlohmann::json::parse(in);
    spec["prediction"] = {{"predictor", "mujoco"}, {"timestep", 0.001}};
    const std::string file = dir_ + "/mujoco_predicted.json";
    std::ofstream(file) << spec.dump(2);
    Populate(file);
  }
};

TEST_F(MujocoPlotTest, AMujocoPredictedCampaignIsDrawnWithMujocosTrajectory) {
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(db_, ro);
  TrialPlotInfo info;
  const Chart chart = MakeTrialChart(*store, trial_, &info);
  EXPECT_EQ(info.prediction_status, arena::db::PredictionStatus::kOk);
  EXPECT_EQ(info.model_key.rfind("mujoco_ts0.001", 0), 0u) << info.model_key;
  tinyxml2::XMLDocument doc;
  const std::string svg = RenderSvg(chart);
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  std::map<std::string, int> points;
  SeriesByPanel(doc, &points);
  EXPECT_GT(points["object position z (gripper frame)/predicted"], 10);
}

int RunArena(const std::string& args, std::string* err = nullptr) {
  const std::string errfile = std::string("/tmp/arena-plot-test-err-") + std::to_string(getpid());
  const int st = std::system((std::string(ARENA_BINARY) + " " + args + " 2>" + errfile).c_str());
  if (err) {
    std::ifstream in(errfile);
    std::ostringstream s;
    s << in.rdbuf();
    *err = s.str();
  }
  std::filesystem::remove(errfile);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

TEST_F(PlotTest, CommandWritesTheSvgAndRefusesWhatItCannotPlot) {
  const std::string out = dir_ + "/t.svg";
  std::string err;
  ASSERT_EQ(RunArena("plot --db " + db_ + " " + std::to_string(trial_) + " --out " + out, &err), 0)
      << err;
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.LoadFile(out.c_str()), tinyxml2::XML_SUCCESS);
  EXPECT_EQ(SeriesByPanel(doc).size(), 7u);
  EXPECT_FALSE(std::filesystem::exists(out + ".tmp"));

  EXPECT_EQ(
      RunArena("plot --db " + db_ + " " + std::to_string(planned_) + " --out " + dir_ + "/p.svg",
               &err),
      2);
  EXPECT_NE(err.find("no ground truth yet"), std::string::npos) << err;
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/p.svg"));
  EXPECT_EQ(RunArena("plot --db " + db_ + " 99999 --out " + dir_ + "/n.svg", &err), 2);
  EXPECT_NE(err.find("no trial 99999"), std::string::npos) << err;
  EXPECT_EQ(RunArena("plot --db " + dir_ + "/missing.db 1 --out " + dir_ + "/m.svg", &err), 3);
  EXPECT_EQ(RunArena("plot --db " + db_ + " " + std::to_string(trial_) + " --out " + dir_ +
                         "/no/such/dir/x.svg",
                     &err),
            1);
  EXPECT_NE(err.find("directory"), std::string::npos) << err;
}

// Issue 26: the top view (--paths) said its black path was "measured" on
// every trial, a simulated cell's too, and a gripper's push along z (the
// object moving out of the view) left an empty picture with no word why.
// Pins: the caption names the truth the cell reported, and a push out of
// the view says how far along z and where to look instead.
TEST_F(PlotTest, PathsViewNamesItsTruthAndAPushOutOfTheView) {
  {
    auto store = db::Store::Open(db_);
    store->RecordExecution(trial_, 1, "model", "self-consistency", "{}");
  }
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(db_, ro);
  const std::string svg = TrialPathsSvg(*store, trial_);
  EXPECT_EQ(svg.find("here: measured"), std::string::npos);
  EXPECT_NE(svg.find("here: simulated, self-consistency"), std::string::npos);
  // e2e60's pushes move the object along the gripper's z.
  const auto note = svg.find("<g id=\"out-of-view\">");
  ASSERT_NE(note, std::string::npos);
  EXPECT_NE(svg.find("along z, out of this view", note), std::string::npos);
  EXPECT_NE(svg.find("plot without --paths", note), std::string::npos);
}

// A replayed dataset that does not say it was measured (truth "recorded":
// recorded elsewhere, perhaps by a simulator) is not called measured either.
TEST_F(PlotTest, PathsViewDoesNotCallARecordedDatasetMeasured) {
  {
    auto store = db::Store::Open(db_);
    store->RecordExecution(trial_, 1, "replay", "recorded", "{}");
  }
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(db_, ro);
  const std::string svg = TrialPathsSvg(*store, trial_);
  EXPECT_EQ(svg.find("here: measured"), std::string::npos);
  EXPECT_NE(svg.find("here: recorded elsewhere, replayed"), std::string::npos);
}

// Issue 28: a failed trial is not "not executed yet" (nothing will come to
// plot or watch), and the store's own log is not an output file.
TEST_F(PlotTest, AFailedTrialSaysWhyAndTheStoresLogIsNoOutput) {
  {
    auto store = db::Store::Open(db_);
    auto t = store->ClaimNextTrial("c1");
    ASSERT_TRUE(t.has_value());
    ASSERT_EQ(t->trial_id, planned_);
    store->FailTrial(t->trial_id, t->attempt, "refused by cell: no such finger",
                     arena::db::TrialEnd::kRefused);
  }
  std::string err;
  EXPECT_EQ(
      RunArena("plot --db " + db_ + " " + std::to_string(planned_) + " --out " + dir_ + "/f.svg",
               &err),
      2);
  EXPECT_NE(err.find("failed without ground truth (refused by cell: no such finger)"),
            std::string::npos)
      << err;
  EXPECT_EQ(err.find("watch it live"), std::string::npos) << err;

  std::ofstream(db_ + ".log") << "the service's log\n";
  for (const std::string& out :
       {db_ + ".log", db_ + ".1.log", db_ + ".sim1.log", dir_ + "/.x.partial-1-abc/p.svg"}) {
    EXPECT_EQ(RunArena("plot --db " + db_ + " " + std::to_string(trial_) + " --out " + out, &err),
              2)
        << out;
    EXPECT_NE(err.find("refusing to overwrite"), std::string::npos) << out << ": " << err;
  }
  EXPECT_EQ(RunArena("export --db " + db_ + " --campaign " + std::to_string(campaign_) + " --out " +
                         db_ + ".log",
                     &err),
            2);
  EXPECT_NE(err.find("kept by the store"), std::string::npos) << err;
  std::ifstream log(db_ + ".log");
  std::string first;
  std::getline(log, first);
  EXPECT_EQ(first, "the service's log");  // untouched, still a file
}

}  // namespace
}  // namespace arena::cli
