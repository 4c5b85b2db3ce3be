// Running `arena evaluate`: load the campaign's done trials, build the
// requested predictors, replay every (trial, setting) on a pool of worker
// threads, compute the noise floor and the convergence table, summarise and
// store the run.
#include "arena/assessment/evaluation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>

#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "arena/assessment/convergence.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/assessment/truth.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace arena::assessment {

TruthInfo TruthOf(const db::Store& store, std::int64_t campaign_id) {
  // Per trial, from what its cell reported when it executed (migration 10);
  // a trial executed before cells reported it ran the model.
  std::map<std::string, std::string> backends;  // backend -> truth kind
  for (const auto& c : store.CampaignTruths(campaign_id)) {
    if (c.trials <= 0) continue;
    const std::string backend = c.backend.empty() ? "model" : c.backend;
    const std::string truth = c.truth.empty() ? "self-consistency" : c.truth;
    backends[backend] = truth;
  }
  TruthInfo info;
  info.source.clear();
  bool self = false;
  for (const auto& [backend, truth] : backends) {
    info.source += (info.source.empty() ? "" : ",") + backend;
    self = self || truth == "self-consistency";
  }
  if (info.source.empty()) {
    info.source = "model";
    self = true;
  }
  info.independent = !self;
  if (self) {
    info.statement =
        "the truth is the model at the cell's settings (self-consistency, not accuracy)";
    if (backends.size() > 1) info.statement += "; the trials ran on " + info.source;
  } else {
    std::string kinds;
    for (const auto& [backend, truth] : backends)
      if (kinds.find(truth) == std::string::npos) kinds += (kinds.empty() ? "" : ", ") + truth;
    info.statement = "the truth is " + info.source + " (" + kinds +
                     "), independent of arena's model: errors are accuracy against it";
    if (kinds.find("measured") != std::string::npos)
      info.statement +=
          " (measured: the observed streams are the truth, there is no separate true stream)";
  }
  return info;
}

namespace {

struct LoadedTrial {
  std::int64_t id = -1;
  mechanics::Scene scene;
  std::vector<mechanics::TrajectorySample> truth;
  std::optional<db::Sample> first;  // the stream's first sample: the measured start
  RecordedCommands commands;        // closed loop: replayed (issue 19); empty otherwise
  std::string error;                // non-empty: the trial could not be loaded
};

LoadedTrial LoadTrial(const db::Store& store, const db::Trial& t, const mechanics::Scene* scene) {
  LoadedTrial out;
  out.id = t.id;
  try {
    out.scene = scene ? *scene : mechanics::ParseScene(t.scene_json);
    const db::GroundTruth gt = store.ReadGroundTruth(t.id);
    const auto normals = ContactNormals(out.scene);
    out.truth.reserve(gt.samples.size());
    for (const auto& s : gt.samples)
      out.truth.push_back(
          ToTrajectorySample(s, normals, out.scene.pusher.has_value(), gt.forces_measured()));
    if (!gt.samples.empty()) out.first = gt.samples.front();
    if (out.scene.pusher && out.scene.pusher->controller) {
      if (auto run = store.GetClosedLoop(t.id)) out.commands = CommandsOf(*run);
      if (out.commands.empty()) out.error = "closed-loop trial without recorded pusher commands";
    }
  } catch (const std::exception& e) {
    out.error = e.what();
  }
  return out;
}

struct Built {
  std::vector<std::unique_ptr<Predictor>> predictors;
  std::vector<SettingInfo> infos;
  std::vector<std::pair<std::size_t, std::size_t>> index;  // flat -> (predictor, setting)
  nlohmann::json grids = nlohmann::json::object();
};

Built BuildPredictors(const std::vector<PredictorRequest>& requests,
                      const std::vector<mechanics::Scene>& scenes) {
  if (requests.empty()) throw std::invalid_argument("predictors: name at least one");
  Built b;
  std::set<std::string> seen;
  for (const auto& req : requests) {
    if (!seen.insert(req.name).second) {
      throw std::invalid_argument("predictors: '" + req.name + "' is named twice");
    }
    if (req.name == "arena") {
      const auto models = req.arena_grid ? ExpandGrid(*req.arena_grid) : DefaultArenaGrid(scenes);
      b.predictors.push_back(MakeArenaPredictor(models));
      nlohmann::json keys = nlohmann::json::array();
      for (std::size_t i = 0; i < models.size(); ++i) {
        b.infos.push_back(SettingInfo{"arena", b.predictors.back()->settings()[i], models[i]});
        keys.push_back(b.infos.back().setting.key);
      }
      b.grids["arena"] = {{"default", !req.arena_grid}, {"settings", keys}};
    } else if (req.name == "mujoco") {
      // MuJoCo's soft contacts take any scene the model does; its default
      // grid varies the timestep (the knob the curves follow).
      b.predictors.push_back(MakeMujocoPredictor(req.mujoco_grid.value_or(MujocoGrid{})));
      nlohmann::json keys = nlohmann::json::array();
      for (const auto& s : b.predictors.back()->settings()) {
        b.infos.push_back(SettingInfo{"mujoco", s, std::nullopt});
        keys.push_back(s.key);
      }
      b.grids["mujoco"] = {{"default", !req.mujoco_grid}, {"settings", keys}};
    } else {
      throw std::invalid_argument("predictors: unknown predictor '" + req.name +
                                  "' (one of arena, mujoco)");
    }
    for (std::size_t i = 0; i < b.predictors.back()->settings().size(); ++i) {
      b.index.emplace_back(b.predictors.size() - 1, i);
    }
  }
  return b;
}

// Where one trial's predictions start, and the scene placed there.
struct TrialStart {
  PredictionStart start;
  mechanics::Scene scene;
  std::string key;    // trials with the same key start alike (one run per setting)
  std::string error;  // non-empty: the start leaves the grasp (an invalid scene)
};

TrialStart StartFor(const LoadedTrial& l, StartFrom from) {
  TrialStart out;
  out.start = StartOf(l.scene, l.first ? &*l.first : nullptr, from);
  try {
    out.scene = StartedAt(l.scene, out.start);
  } catch (const std::exception& e) {
    out.error = e.what();
    return out;
  }
  if (out.start.from == StartFrom::kPlanned ||
      (out.start.offset_m == 0 && out.start.offset_rad == 0))
    return out;  // key "": the planned scene
  char key[160];
  std::snprintf(key, sizeof key, "%a %a %a %a %a %a %a", out.start.position.x(),
                out.start.position.y(), out.start.position.z(), out.start.orientation.w(),
                out.start.orientation.x(), out.start.orientation.y(), out.start.orientation.z());
  out.key = key;
  return out;
}

// Up to `n` trials spread evenly over the list.
std::vector<std::size_t> Spread(std::size_t total, int n) {
  std::vector<std::size_t> out;
  if (n <= 0 || total == 0) return out;
  const std::size_t take = std::min<std::size_t>(total, static_cast<std::size_t>(n));
  for (std::size_t i = 0; i < take; ++i) out.push_back(i * total / take);
  return out;
}

}  // namespace

StartReport StartShareOf(const std::vector<SettingInfo>& settings,
                         const std::vector<TrialEvaluation>& results,
                         const std::vector<std::optional<db::Prediction>>& planned,
                         const std::vector<std::optional<PredictionStart>>& starts,
                         StartFrom from) {
  StartReport out;
  out.from = from;
  std::vector<double> dp, da;
  for (const auto& st : starts) {
    if (!st) continue;
    if (st->source != "planned") ++out.measured_trials;
    dp.push_back(st->offset_m);
    da.push_back(st->offset_rad);
  }
  if (!dp.empty()) {
    out.offset_position = Distribution{Percentile(dp, 0.5), Percentile(dp, 0.95),
                                       *std::max_element(dp.begin(), dp.end())};
    out.offset_angle = Distribution{Percentile(da, 0.5), Percentile(da, 0.95),
                                    *std::max_element(da.begin(), da.end())};
  }
  if (planned.empty() || settings.empty()) return out;
  for (std::size_t s = 0; s < settings.size(); ++s) {
    StartShare share;
    share.predictor = settings[s].predictor;
    share.model_key = settings[s].setting.key;
    std::vector<double> pm, pp, am, ap;
    for (std::size_t i = s; i < results.size(); i += settings.size()) {
      const db::Prediction& m = results[i].prediction;
      const auto& p = planned[i];
      // Paired: trials predicted from both starts.
      if (!p || m.status != db::PredictionStatus::kOk || p->status != db::PredictionStatus::kOk ||
          !m.final_position_error || !p->final_position_error || !m.final_angle_error ||
          !p->final_angle_error)
        continue;
      pm.push_back(*m.final_position_error);
      pp.push_back(*p->final_position_error);
      am.push_back(*m.final_angle_error);
      ap.push_back(*p->final_angle_error);
    }
    share.trials = static_cast<int>(pm.size());
    if (!pm.empty()) {
      share.position_measured = Percentile(pm, 0.5);
      share.position_planned = Percentile(pp, 0.5);
      share.angle_measured = Percentile(am, 0.5);
      share.angle_planned = Percentile(ap, 0.5);
    }
    out.settings.push_back(share);
  }
  return out;
}

nlohmann::json ToJson(const StartReport& r) {
  auto dist = [](const std::optional<Distribution>& d) -> nlohmann::json {
    if (!d) return nullptr;
    return {{"median", d->median}, {"p95", d->p95}, {"max", d->max}};
  };
  nlohmann::json settings = nlohmann::json::array();
  for (const auto& s : r.settings) {
    nlohmann::json j = {{"predictor", s.predictor}, {"setting", s.model_key}, {"trials", s.trials}};
    if (s.trials > 0) {
      j["position_median_m"] = {{"measured", s.position_measured},
                                {"planned", s.position_planned},
                                {"explained", s.position_planned - s.position_measured}};
      j["angle_median_rad"] = {{"measured", s.angle_measured},
                               {"planned", s.angle_planned},
                               {"explained", s.angle_planned - s.angle_measured}};
    }
    settings.push_back(std::move(j));
  }
  return {{"from", ToString(r.from)},
          {"measured_trials", r.measured_trials},
          {"offset_m", dist(r.offset_position)},
          {"offset_rad", dist(r.offset_angle)},
          {"explained", std::move(settings)}};
}

namespace {

// The campaign's done trials with a ground-truth stream.
std::vector<db::Trial> DoneTrials(db::Store& store, std::int64_t campaign_id) {
  (void)store.GetCampaign(campaign_id);  // kNotFound for an unknown campaign
  std::vector<db::Trial> trials;
  for (auto& t : store.ListTrials(campaign_id)) {
    if (t.state == db::TrialState::kDone && t.gt_stream_id) trials.push_back(std::move(t));
  }
  if (trials.empty()) {
    // An evaluation of nothing would be stored as if it said something.
    throw std::invalid_argument("campaign " + std::to_string(campaign_id) +
                                " has no done trials to evaluate yet (arena status shows "
                                "its progress)");
  }
  return trials;
}

// Every trial's group before any work: a trial without the parameter is an
// error naming it, and nothing is evaluated.
std::map<std::int64_t, std::string> GroupOfTrial(const std::vector<db::Trial>& trials,
                                                 const EvaluationOptions& options) {
  std::map<std::int64_t, std::string> group_of_trial;
  if (!options.group_of) return group_of_trial;
  if (options.group_by.empty())
    throw std::invalid_argument("group_by: name the trial parameter to group by");
  for (const auto& t : trials) group_of_trial[t.id] = options.group_of(t);
  return group_of_trial;
}

// The trials' scenes, calibration scales applied; a scene that does not
// parse stays empty (its jobs report the error).
struct CampaignScenes {
  std::vector<std::optional<mechanics::Scene>> of_trial;  // one per trial
  std::vector<mechanics::Scene> valid;                    // the ones that parsed
};

CampaignScenes ParseScenes(const std::vector<db::Trial>& trials,
                           const std::map<std::string, double>& scales) {
  CampaignScenes out;
  out.of_trial.resize(trials.size());
  for (std::size_t i = 0; i < trials.size(); ++i) {
    try {
      out.of_trial[i] = mechanics::ParseScene(trials[i].scene_json);
    } catch (const std::exception&) {
      continue;  // reported per job as an error
    }
    if (!scales.empty()) {
      // A scale that cannot apply is the caller's error, never a trial
      // predicted unscaled.
      try {
        out.of_trial[i] = ApplyScales(*out.of_trial[i], scales);
        mechanics::ValidateScene(*out.of_trial[i]);
      } catch (const std::exception& e) {
        throw std::invalid_argument("calibration scales on trial " + std::to_string(trials[i].id) +
                                    ": " + e.what());
      }
    }
    out.valid.push_back(*out.of_trial[i]);
  }
  return out;
}

bool ClosedLoop(const std::optional<mechanics::Scene>& scene) {
  return scene && scene->pusher && scene->pusher->controller;
}

// Trials with the same scene (the replicates of a condition: their truths
// differ, the scene a predictor is given does not) share each prediction:
// a predictor is deterministic, so it runs once per scene and setting and
// is scored against each trial's truth. A group holds at most
// kGroupTrials (their truths are in memory together, and one scene's many
// replicates still spread over the threads).
std::vector<std::vector<std::size_t>> ReplicateGroups(const std::vector<db::Trial>& trials,
                                                      const CampaignScenes& scenes) {
  constexpr std::size_t kGroupTrials = 8;
  std::vector<std::vector<std::size_t>> groups;
  std::map<std::string, std::size_t> open;  // scene -> its group still taking trials
  for (std::size_t i = 0; i < trials.size(); ++i) {
    // A closed-loop trial's prediction replays its own commands: never shared.
    if (ClosedLoop(scenes.of_trial[i])) {
      groups.push_back({i});
      continue;
    }
    auto it = open.find(trials[i].scene_json);
    if (it == open.end() || groups[it->second].size() >= kGroupTrials) {
      groups.emplace_back();
      it = open.insert_or_assign(trials[i].scene_json, groups.size() - 1).first;
    }
    groups[it->second].push_back(i);
  }
  return groups;
}

// What the worker threads share: the campaign's inputs (read only), the
// slots each job writes (one per (trial, setting) or per trial, never
// written by two workers) and the counters the calling thread reports.
struct ReplayWork {
  ReplayWork(const std::string& store_path_, const std::vector<db::Trial>& trials_,
             const CampaignScenes& scenes_, const Built& built_, const EvaluationOptions& options_)
      : store_path(store_path_),
        trials(trials_),
        scenes(scenes_),
        built(built_),
        options(options_),
        groups(ReplicateGroups(trials_, scenes_)),
        settings(built_.infos.size()),
        total(trials_.size() * settings),
        also_planned(options_.start_from == StartFrom::kMeasured),
        results(total),
        planned(also_planned ? total : 0),
        trial_starts(trials_.size()),
        finals(trials_.size()),
        durations(trials_.size(), 0) {}

  const std::string& store_path;
  const std::vector<db::Trial>& trials;
  const CampaignScenes& scenes;
  const Built& built;
  const EvaluationOptions& options;
  const std::vector<std::vector<std::size_t>> groups;
  const std::size_t settings;  // settings of all predictors
  const std::size_t total;     // jobs: trials x settings
  // From the measured start, each setting is also run from the planned one
  // (shared by a scene's replicates): the difference is the start's share.
  const bool also_planned;

  std::vector<TrialEvaluation> results;                      // [trial * settings + setting]
  std::vector<std::optional<db::Prediction>> planned;        // the same, from the planned start
  std::vector<std::optional<PredictionStart>> trial_starts;  // per trial
  std::vector<std::optional<FinalPose>> finals;              // per trial
  std::vector<double> durations;                             // per trial

  std::atomic<std::size_t> next_group{0};
  std::atomic<long> done{0}, failed{0};
  std::mutex error_mutex;
  std::string worker_error;
  std::atomic<bool> worker_failed{false};

  bool Cancelled() const { return options.cancel && options.cancel->load(); }
};

// One setting's predictions for a group, one run per start (key "":
// planned), each scored against every trial that starts there.
class SettingRuns {
 public:
  SettingRuns(const Predictor& predictor, std::size_t setting)
      : predictor_(predictor), setting_(setting) {}

  db::Prediction Score(const mechanics::Scene& scene, const LoadedTrial& l, const std::string& key,
                       const PredictionStart& from) {
    const auto& [result, wall] = RunFrom(scene, l, key);
    db::Prediction p = ScoreSimulation(
        l.commands.empty() ? scene : ReplayScoringScene(scene, l.commands), result, l.truth);
    p.wall_s = wall;
    NoteStart(&p, from);
    return p;
  }

 private:
  const std::pair<mechanics::SimulationResult, double>& RunFrom(const mechanics::Scene& scene,
                                                                const LoadedTrial& l,
                                                                const std::string& key) {
    auto it = runs_.find(key);
    if (it == runs_.end()) {
      const auto start = std::chrono::steady_clock::now();
      auto result = l.commands.empty()
                        ? predictor_.Run(scene, setting_)
                        : predictor_.RunClosedLoop(scene, setting_, ReplayCommands(l.commands));
      const double wall =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      it = runs_.emplace(key, std::make_pair(std::move(result), wall)).first;
    }
    return it->second;
  }

  const Predictor& predictor_;
  std::size_t setting_;
  std::map<std::string, std::pair<mechanics::SimulationResult, double>> runs_;
};

// A group's trials read once: truth, start and the measured final pose.
struct LoadedGroup {
  const std::vector<std::size_t>& members;
  std::vector<LoadedTrial> loaded;
  std::vector<TrialStart> starts;

  // The scene every member was given (the first that loaded); null: none loaded.
  const LoadedTrial* WithScene() const {
    for (const LoadedTrial& l : loaded)
      if (l.error.empty()) return &l;
    return nullptr;
  }
};

LoadedGroup LoadGroup(ReplayWork& w, const db::Store& reader, std::size_t group) {
  LoadedGroup g{w.groups[group], {}, {}};
  g.loaded.reserve(g.members.size());
  for (std::size_t ti : g.members) {
    const auto& t = w.trials[ti];
    const auto& scene = w.scenes.of_trial[ti];
    g.loaded.push_back(LoadTrial(reader, t, scene ? &*scene : nullptr));
    const LoadedTrial& l = g.loaded.back();
    if (l.error.empty() && !l.truth.empty()) {
      w.durations[ti] = l.truth.back().t;
      w.finals[ti] =
          FinalPose{t.id, t.condition, l.truth.back().position, l.truth.back().orientation};
    }
  }
  g.starts.reserve(g.loaded.size());
  for (std::size_t m = 0; m < g.loaded.size(); ++m) {
    g.starts.push_back(StartFor(g.loaded[m], w.options.start_from));
    if (g.loaded[m].error.empty()) w.trial_starts[g.members[m]] = g.starts.back().start;
  }
  return g;
}

// Setting s for every member of the group; `same`: an earlier setting that
// builds the same model for this scene, whose predictions are copied.
void PredictSetting(ReplayWork& w, const LoadedGroup& g, std::size_t s,
                    std::optional<std::size_t> same) {
  const auto [pi, si] = w.built.index[s];
  SettingRuns runs(*w.built.predictors[pi], si);
  for (std::size_t m = 0; m < g.members.size(); ++m) {
    const std::size_t ti = g.members[m];
    const auto& t = w.trials[ti];
    const LoadedTrial& l = g.loaded[m];
    const std::size_t at = ti * w.settings;
    TrialEvaluation& r = w.results[at + s];
    r.trial_id = t.id;
    r.attempt = t.attempt;
    r.setting = s;
    r.truth_duration_s = w.durations[ti];
    const TrialStart& st = g.starts[m];
    if (same) {
      r.prediction = w.results[at + *same].prediction;
      if (w.also_planned) w.planned[at + s] = w.planned[at + *same];
    } else if (!l.error.empty()) {
      r.prediction = PredictionFailure(db::PredictionStatus::kError, l.error);
    } else {
      if (!st.error.empty()) {
        r.prediction = PredictionFailure(db::PredictionStatus::kInvalidScene, st.error);
        NoteStart(&r.prediction, st.start);
      } else {
        r.prediction = runs.Score(st.scene, l, st.key, st.start);
      }
      if (w.also_planned)
        w.planned[at + s] =
            runs.Score(l.scene, l, "", StartOf(l.scene, nullptr, StartFrom::kPlanned));
    }
    r.prediction.model_key = w.built.infos[s].setting.key;
    r.prediction.model_json = w.built.infos[s].setting.knobs_json;
    if (r.prediction.status != db::PredictionStatus::kOk) w.failed.fetch_add(1);
    w.done.fetch_add(1);
  }
}

// Every setting of every predictor for one group; false when cancelled.
bool PredictGroup(ReplayWork& w, const db::Store& reader, std::size_t group) {
  const LoadedGroup g = LoadGroup(w, reader, group);
  const LoadedTrial* with_scene = g.WithScene();
  // Settings that build the same model for this scene run it once.
  std::map<std::pair<std::size_t, std::string>, std::size_t> ran;
  for (std::size_t s = 0; s < w.settings; ++s) {
    if (w.Cancelled()) return false;
    const auto [pi, si] = w.built.index[s];
    std::optional<std::size_t> same;
    if (with_scene) {
      const auto key =
          std::make_pair(pi, w.built.predictors[pi]->EffectiveKey(with_scene->scene, si));
      const auto it = ran.find(key);
      if (it != ran.end())
        same = it->second;
      else
        ran.emplace(key, s);
    }
    PredictSetting(w, g, s, same);
  }
  return true;
}

// A worker takes a whole group of trials with one scene (every setting of
// every predictor), so each trial's ground truth is read and converted
// once, and each setting's prediction is made once for the group.
void ReplayWorker(ReplayWork& w) {
  try {
    db::StoreOptions ro;
    ro.read_only = true;
    auto reader = db::Store::Open(w.store_path, ro);
    for (;;) {
      if (w.Cancelled()) return;
      const std::size_t gi = w.next_group.fetch_add(1);
      if (gi >= w.groups.size()) return;
      if (!PredictGroup(w, *reader, gi)) return;
    }
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(w.error_mutex);
    if (w.worker_error.empty()) w.worker_error = e.what();
    w.worker_failed.store(true);
    w.next_group.store(w.groups.size());  // stop the others too
  }
}

// The pool: `threads` workers, progress from the calling thread.
void ReplayOnThreads(ReplayWork& w, int threads) {
  const auto& options = w.options;
  std::vector<std::thread> pool;
  for (int i = 0; i < threads; ++i) pool.emplace_back(ReplayWorker, std::ref(w));
  while (w.done.load() < static_cast<long>(w.total) && !w.worker_failed.load() && !w.Cancelled()) {
    if (options.progress)
      options.progress(w.done.load(), w.failed.load(), static_cast<long>(w.total));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  for (auto& th : pool) th.join();
  if (options.progress)
    options.progress(w.done.load(), w.failed.load(), static_cast<long>(w.total));
  if (!w.worker_error.empty())
    throw std::runtime_error("evaluate: a worker failed: " + w.worker_error);
}

// The convergence table: a few trials, short pieces from the true state.
void AddConvergence(const db::Store& store, const ReplayWork& w, EvaluationReport* report) {
  if (w.options.convergence_trials <= 0 || w.trials.empty()) return;
  std::vector<ConvergenceTrial> sample;
  for (std::size_t ti : Spread(w.trials.size(), w.options.convergence_trials)) {
    // A closed-loop trial's pieces would need its commands replayed from
    // the restart on; the table is built from open-loop trials only.
    const auto& scene = w.scenes.of_trial[ti];
    if (!scene || ClosedLoop(scene)) continue;
    try {
      sample.push_back(ConvergenceTrial{*scene, ReadTruth(store, w.trials[ti].id, *scene)});
    } catch (const std::exception&) {
    }
  }
  std::size_t flat = 0;
  for (const auto& p : w.built.predictors) {
    const auto table = ConvergenceTable(*p, sample);
    for (std::size_t i = 0; i < table.size(); ++i)
      report->settings[flat + i].convergence = table[i];
    flat += table.size();
  }
}

// The run's settings as stored: the grids, the start, scales and budgets.
nlohmann::json SettingsJson(const EvaluationOptions& options, const Built& built, int threads) {
  nlohmann::json grid = {
      {"predictors", built.grids}, {"start", ToString(options.start_from)},
      {"scales", options.scales},  {"budgets", nlohmann::json::array()},
      {"threads", threads},        {"convergence_trials", options.convergence_trials}};
  for (const auto& req : options.predictors) {
    if (req.name == "arena" && req.arena_grid) {
      const auto& g = *req.arena_grid;
      grid["facets"] = g.facets;
      grid["points"] = g.points;
      grid["dt"] = g.dt;
      grid["reduce"] = nlohmann::json::array();
      for (auto r : g.reduce) grid["reduce"].push_back(mechanics::ToString(r));
    }
  }
  for (const auto& b : options.budgets) grid["budgets"].push_back(FormatBudget(b));
  return grid;
}

// Stores the finished run; a store that refuses it leaves the report with
// the caller (run->not_stored).
void StoreRun(db::Store& store, std::int64_t campaign_id, const EvaluationOptions& options,
              std::vector<TrialEvaluation>* results, EvaluationRun* run) {
  std::vector<db::EvaluationResult> rows;
  rows.reserve(results->size());
  for (auto& r : *results)
    rows.push_back(db::EvaluationResult{r.trial_id, r.attempt, std::move(r.prediction)});
  nlohmann::json report = ToJson(run->report);
  report["start"] = ToJson(run->start);
  const std::string report_json = report.dump();
  try {
    db::RetryWhileBusy(
        [&] {
          run->evaluation_id =
              store.RecordEvaluation(campaign_id, run->settings_json, report_json, rows);
        },
        [&](double waited, const std::string& why) {
          if (options.cancel && options.cancel->load()) return false;
          return !options.on_store_busy || options.on_store_busy(waited, why);
        });
  } catch (const db::StoreError& e) {
    run->not_stored = e.what();  // the finished work is the caller's to keep
    run->not_stored_kind = e.kind();
  }
}

}  // namespace

EvaluationRun EvaluateCampaign(db::Store& store, std::int64_t campaign_id,
                               const EvaluationOptions& options) {
  const std::vector<db::Trial> trials = DoneTrials(store, campaign_id);
  const std::map<std::int64_t, std::string> group_of_trial = GroupOfTrial(trials, options);
  // Scenes first: the default grids keep only settings every scene takes.
  const CampaignScenes scenes = ParseScenes(trials, options.scales);
  const Built built = BuildPredictors(options.predictors, scenes.valid);

  ReplayWork w(store.path(), trials, scenes, built, options);
  int threads =
      options.threads > 0 ? options.threads : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::max(
      1, std::min<int>(threads, static_cast<int>(std::max<std::size_t>(w.groups.size(), 1))));
  ReplayOnThreads(w, threads);

  EvaluationRun run;
  if (w.Cancelled()) {
    run.cancelled = true;
    return run;
  }
  std::vector<FinalPose> final_poses;
  for (const auto& f : w.finals) {
    if (f) final_poses.push_back(*f);
  }
  run.report = Summarise(built.infos, w.results, options.budgets, ComputeNoiseFloor(final_poses));
  run.report.campaign_id = campaign_id;
  run.report.truth = TruthOf(store, campaign_id);
  run.start = StartShareOf(built.infos, w.results, w.planned, w.trial_starts, options.start_from);
  run.report.scales = options.scales;
  if (options.group_of) {
    run.report.group_by = options.group_by;
    run.report.groups = SummariseGroups(built.infos, w.results, group_of_trial);
  }
  AddConvergence(store, w, &run.report);
  run.settings_json = SettingsJson(options, built, threads).dump();
  StoreRun(store, campaign_id, options, &w.results, &run);
  return run;
}

}  // namespace arena::assessment
