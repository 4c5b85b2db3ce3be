// arena export --db FILE --campaign ID --format hdf5|csv|jsonl --out DIR [--no-predictions]
// A dataset directory (layout in db/include/arena/db/export.hpp), verified
// after writing. The predicted stream of each trial is re-run here (db knows
// nothing of the model) exactly as the service ran it.
#include <cstdio>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/assessment/prediction.hpp"
#include "arena/assessment/truth.hpp"
#include "arena/cli/version.hpp"
#include "arena/db/export.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/orchestrator/trial_data.hpp"
#include "commands.hpp"
#include "output_guard.hpp"
#include "progress.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

struct ExportCliOptions {
  std::string db_path;
  std::int64_t campaign = 0;
  std::string format = "hdf5";
  std::string out;
  bool no_predictions = false;
};

db::ContactMode StoreMode(mechanics::ContactMode m) {
  switch (m) {
    case mechanics::ContactMode::kStick:
      return db::ContactMode::kStick;
    case mechanics::ContactMode::kSlide:
      return db::ContactMode::kSlide;
    case mechanics::ContactMode::kSeparate:
      break;
  }
  return db::ContactMode::kSeparate;
}

// The model's trajectory in the store's sample layout (forces on the object in G).
db::Sample ToSample(const mechanics::TrajectorySample& p,
                    const std::vector<Eigen::Vector3d>& normals, const mechanics::Scene& scene) {
  db::Sample s;
  s.t = p.t;
  const auto& q = p.orientation;
  s.object_pose = {p.position.x(), p.position.y(), p.position.z(), q.w(), q.x(), q.y(), q.z()};
  s.object_twist = {p.velocity.x(),         p.velocity.y(),         p.velocity.z(),
                    p.angular_velocity.x(), p.angular_velocity.y(), p.angular_velocity.z()};
  s.pusher_pose = {p.pusher_position.x(), p.pusher_position.y(), p.pusher_position.z(), 1, 0, 0, 0};
  if (scene.pusher) {  // the model moves the pusher as commanded
    const auto& m = scene.pusher->motion;
    s.pusher_twist = {m.velocity.x(),         m.velocity.y(),         m.velocity.z(),
                      m.angular_velocity.x(), m.angular_velocity.y(), m.angular_velocity.z()};
  }
  for (std::size_t i = 0; i < p.contacts.size(); ++i) {
    const auto& c = p.contacts[i];
    const Eigen::Vector3d n = i < normals.size() ? normals[i] : Eigen::Vector3d::Zero();
    const Eigen::Vector3d f = c.normal_force * n + c.tangential_force;
    db::ContactWrench w;
    w.force = {f.x(), f.y(), f.z()};
    w.torque = {c.torque.x(), c.torque.y(), c.torque.z()};
    w.mode = StoreMode(c.mode);
    s.contacts.push_back(w);
  }
  s.observed_valid = false;  // a prediction observes nothing
  return s;
}

// The campaign's "prediction" settings applied to the trial's scene and run
// on the predictor they name (arena's model or MuJoCo), as the service does;
// a closed-loop trial's prediction replays `commands` (the commands its cell
// applied; issue 19).
db::PredictedStream PredictWith(const std::string& scene_json, const std::string& spec_json,
                                const std::vector<db::ClosedLoopCommand>* commands,
                                const db::Sample* first = nullptr) {
  db::PredictedStream out;
  const mechanics::Scene scene = mechanics::ParseScene(scene_json);
  nlohmann::json model;
  const auto spec = nlohmann::json::parse(spec_json);
  if (spec.is_object() && spec.contains("prediction")) model = spec["prediction"];
  assessment::RecordedCommands recorded;
  if (commands) {
    db::ClosedLoopRun applied;
    applied.commands = *commands;
    recorded = assessment::CommandsOf(applied);
  }
  // From the start the service's prediction took (the cell's measured start).
  const assessment::PredictedRun run =
      assessment::SimulatePrediction(scene, model, &recorded, first);
  out.predictor = run.key;
  out.settings_json = run.settings_json;
  out.status = assessment::StatusOf(run.result.status);
  if (out.status != db::PredictionStatus::kOk) {
    out.error = run.result.error;
    return out;
  }
  const auto normals = assessment::ContactNormals(run.scene);
  for (const auto& p : run.result.samples) out.samples.push_back(ToSample(p, normals, run.scene));
  return out;
}

db::PredictedStream Predict(const std::string& scene_json, const std::string& spec_json) {
  return PredictWith(scene_json, spec_json, nullptr);
}

db::PredictedStream PredictClosedLoop(const std::string& scene_json, const std::string& spec_json,
                                      const std::vector<db::ClosedLoopCommand>& commands) {
  return PredictWith(scene_json, spec_json, &commands);
}

db::PredictedStream PredictFrom(const std::string& scene_json, const std::string& spec_json,
                                const std::vector<db::ClosedLoopCommand>& commands,
                                const db::Sample* first) {
  return PredictWith(scene_json, spec_json, commands.empty() ? nullptr : &commands, first);
}

int RunExport(const ExportCliOptions& o) {
  RefuseToOverwriteStore(o.out, "--out", o.db_path);
  {
    db::StoreOptions so;
    so.read_only = true;
    auto store = db::Store::Open(o.db_path, so);
    db::ExportOptions eo;
    eo.campaign_id = o.campaign;
    eo.format = o.format == "csv"     ? db::ExportFormat::kCsv
                : o.format == "jsonl" ? db::ExportFormat::kJsonl
                                      : db::ExportFormat::kHdf5;
    eo.out_dir = o.out;
    eo.arena_version = arena::Version();
    eo.arena_commit = arena::GitCommit();
    eo.scene_facts = orchestrator::SceneFactsOfJson;
    if (!o.no_predictions) {
      eo.predict = Predict;
      eo.predict_closed_loop = PredictClosedLoop;
      eo.predict_from = PredictFrom;
    }
    std::unique_ptr<ProgressLine> progress;
    eo.progress = [&](std::int64_t done, std::int64_t total) {
      if (!progress) progress = std::make_unique<ProgressLine>(static_cast<long>(total), "trials");
      progress->Update(static_cast<long>(done), 0);
    };
    const auto r = db::ExportCampaign(*store, eo);
    if (progress) progress->Finish();
    std::printf(
        "exported campaign %lld: %lld trials, %lld samples, %zu files + manifest.json -> %s "
        "(verified)\n",
        static_cast<long long>(o.campaign), static_cast<long long>(r.trials),
        static_cast<long long>(r.samples), r.files.size(), r.dir.c_str());
    return kExitOk;
  }
}

}  // namespace

void AddExportCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<ExportCliOptions>();
  auto* cmd = app.add_subcommand("export", "Export a campaign as a dataset directory");
  cmd->add_option("--db", o->db_path, "Store file")->required();
  cmd->add_option("--campaign", o->campaign, "Campaign id (see 'arena list')")
      ->required()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--format", o->format, "Stream format: hdf5, csv or jsonl")
      ->check(CLI::IsMember({"hdf5", "csv", "jsonl"}))
      ->capture_default_str();
  cmd->add_option("--out", o->out, "New or empty directory to write")->required();
  cmd->add_flag("--no-predictions", o->no_predictions,
                "Leave out the predicted stream of each trial (re-running the model costs time; "
                "the predicted streams are as large as the true ones)");
  cmd->footer(
      "Example:\n"
      "  arena export --db lab.db --campaign 1 --format hdf5 --out datasets/c1\n"
      "Writes trials.csv (index: parameters, outcomes, prediction errors, scene), contacts.csv\n"
      "(per-contact outcomes), the true, observed and predicted streams of every trial with\n"
      "ground truth, closed-loop trials' controller outcomes and applied pusher commands\n"
      "(closed_loop.csv, closed_loop_commands.csv; their predictions replay the commands),\n"
      "and manifest.json (units, frames, counts, SHA-256 of every file); verifies\n"
      "it, then moves it into place: DIR appears complete or not at all.\n"
      "Reads one snapshot of the store: safe while 'arena serve' runs.\n");
  cmd->callback([o, action] { *action = [o] { return RunExport(*o); }; });
}

}  // namespace arena::cli
