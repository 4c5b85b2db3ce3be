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

EvaluationRun EvaluateCampaign(db::Store& store, std::int64_t campaign_id,
                               const EvaluationOptions& options) {
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
  // Every trial's group before any work: a trial without the parameter is
  // an error naming it, and nothing is evaluated.
  std::map<std::int64_t, std::string> group_of_trial;
  if (options.group_of) {
    if (options.group_by.empty())
      throw std::invalid_argument("group_by: name the trial parameter to group by");
    for (const auto& t : trials) group_of_trial[t.id] = options.group_of(t);
  }
  // Scenes first: the default grids keep only settings every scene takes.
  std::vector<std::optional<mechanics::Scene>> scenes(trials.size());
  std::vector<mechanics::Scene> valid_scenes;
  for (std::size_t i = 0; i < trials.size(); ++i) {
    try {
      scenes[i] = mechanics::ParseScene(trials[i].scene_json);
    } catch (const std::exception&) {
      continue;  // reported per job as an error
    }
    if (!options.scales.empty()) {
      // A scale that cannot apply is the caller's error, never a trial
      // predicted unscaled.
      try {
        scenes[i] = ApplyScales(*scenes[i], options.scales);
        mechanics::ValidateScene(*scenes[i]);
      } catch (const std::exception& e) {
        throw std::invalid_argument("calibration scales on trial " + std::to_string(trials[i].id) +
                                    ": " + e.what());
      }
    }
    valid_scenes.push_back(*scenes[i]);
  }
  const Built built = BuildPredictors(options.predictors, valid_scenes);
  const std::size_t settings = built.infos.size();
  const std::size_t total = trials.size() * settings;
  std::vector<TrialEvaluation> results(total);
  // From the measured start, each setting is also run from the planned one
  // (shared by a scene's replicates): the difference is the start's share.
  const bool also_planned = options.start_from == StartFrom::kMeasured;
  std::vector<std::optional<db::Prediction>> planned(also_planned ? total : 0);
  std::vector<std::optional<PredictionStart>> trial_starts(trials.size());
  std::vector<std::optional<FinalPose>> finals(trials.size());
  std::vector<double> durations(trials.size(), 0);
  // Trials with the same scene (the replicates of a condition: their truths
  // differ, the scene a predictor is given does not) share each prediction:
  // a predictor is deterministic, so it runs once per scene and setting and
  // is scored against each trial's truth. A group holds at most
  // kGroupTrials (their truths are in memory together, and one scene's many
  // replicates still spread over the threads).
  constexpr std::size_t kGroupTrials = 8;
  std::vector<std::vector<std::size_t>> groups;
  {
    std::map<std::string, std::size_t> open;  // scene -> its group still taking trials
    for (std::size_t i = 0; i < trials.size(); ++i) {
      // A closed-loop trial's prediction replays its own commands: never shared.
      if (scenes[i] && scenes[i]->pusher && scenes[i]->pusher->controller) {
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
  }
  std::atomic<std::size_t> next_group{0};
  std::atomic<long> done{0}, failed{0};
  std::mutex error_mutex;
  std::string worker_error;
  std::atomic<bool> worker_failed{false};

  int threads =
      options.threads > 0 ? options.threads : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::max(
      1, std::min<int>(threads, static_cast<int>(std::max<std::size_t>(groups.size(), 1))));

  // A worker takes a whole group of trials with one scene (every setting of
  // every predictor), so each trial's ground truth is read and converted
  // once, and each setting's prediction is made once for the group.
  auto worker = [&]() {
    try {
      db::StoreOptions ro;
      ro.read_only = true;
      auto reader = db::Store::Open(store.path(), ro);
      for (;;) {
        if (options.cancel && options.cancel->load()) return;
        const std::size_t gi = next_group.fetch_add(1);
        if (gi >= groups.size()) return;
        const std::vector<std::size_t>& members = groups[gi];
        std::vector<LoadedTrial> loaded;
        loaded.reserve(members.size());
        for (std::size_t ti : members) {
          const auto& t = trials[ti];
          loaded.push_back(LoadTrial(*reader, t, scenes[ti] ? &*scenes[ti] : nullptr));
          const LoadedTrial& l = loaded.back();
          if (l.error.empty() && !l.truth.empty()) {
            durations[ti] = l.truth.back().t;
            finals[ti] =
                FinalPose{t.id, t.condition, l.truth.back().position, l.truth.back().orientation};
          }
        }
        std::vector<TrialStart> starts;
        starts.reserve(loaded.size());
        for (std::size_t m = 0; m < loaded.size(); ++m) {
          starts.push_back(StartFor(loaded[m], options.start_from));
          if (loaded[m].error.empty()) trial_starts[members[m]] = starts.back().start;
        }
        // The scene every member was given (the first that loaded).
        const LoadedTrial* with_scene = nullptr;
        for (const LoadedTrial& l : loaded) {
          if (l.error.empty()) {
            with_scene = &l;
            break;
          }
        }
        // Settings that build the same model for this scene run it once.
        std::map<std::pair<std::size_t, std::string>, std::size_t> ran;
        for (std::size_t s = 0; s < settings; ++s) {
          if (options.cancel && options.cancel->load()) return;
          const auto [pi, si] = built.index[s];
          std::optional<std::size_t> same;
          if (with_scene) {
            const auto key =
                std::make_pair(pi, built.predictors[pi]->EffectiveKey(with_scene->scene, si));
            const auto it = ran.find(key);
            if (it != ran.end())
              same = it->second;
            else
              ran.emplace(key, s);
          }
          // This setting's runs in the group, one per start (key "": planned).
          std::map<std::string, std::pair<mechanics::SimulationResult, double>> runs;
          const auto& predictor = *built.predictors[pi];
          auto run_from = [&](const mechanics::Scene& scene, const LoadedTrial& l,
                              const std::string& key) -> const auto& {
            auto it = runs.find(key);
            if (it == runs.end()) {
              const auto start = std::chrono::steady_clock::now();
              auto result = l.commands.empty()
                                ? predictor.Run(scene, si)
                                : predictor.RunClosedLoop(scene, si, ReplayCommands(l.commands));
              const double wall =
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
              it = runs.emplace(key, std::make_pair(std::move(result), wall)).first;
            }
            return it->second;
          };
          auto score = [&](const mechanics::Scene& scene, const LoadedTrial& l,
                           const std::string& key, const PredictionStart& from) {
            const auto& [result, wall] = run_from(scene, l, key);
            db::Prediction p =
                ScoreSimulation(l.commands.empty() ? scene : ReplayScoringScene(scene, l.commands),
                                result, l.truth);
            p.wall_s = wall;
            NoteStart(&p, from);
            return p;
          };
          for (std::size_t m = 0; m < members.size(); ++m) {
            const std::size_t ti = members[m];
            const auto& t = trials[ti];
            const LoadedTrial& l = loaded[m];
            TrialEvaluation& r = results[ti * settings + s];
            r.trial_id = t.id;
            r.attempt = t.attempt;
            r.setting = s;
            r.truth_duration_s = durations[ti];
            const TrialStart& st = starts[m];
            if (same) {
              r.prediction = results[ti * settings + *same].prediction;
              if (also_planned) planned[ti * settings + s] = planned[ti * settings + *same];
            } else if (!l.error.empty()) {
              r.prediction = PredictionFailure(db::PredictionStatus::kError, l.error);
            } else {
              if (!st.error.empty()) {
                r.prediction = PredictionFailure(db::PredictionStatus::kInvalidScene, st.error);
                NoteStart(&r.prediction, st.start);
              } else {
                r.prediction = score(st.scene, l, st.key, st.start);
              }
              if (also_planned)
                planned[ti * settings + s] =
                    score(l.scene, l, "", StartOf(l.scene, nullptr, StartFrom::kPlanned));
            }
            r.prediction.model_key = built.infos[s].setting.key;
            r.prediction.model_json = built.infos[s].setting.knobs_json;
            if (r.prediction.status != db::PredictionStatus::kOk) failed.fetch_add(1);
            done.fetch_add(1);
          }
        }
      }
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (worker_error.empty()) worker_error = e.what();
      worker_failed.store(true);
      next_group.store(groups.size());  // stop the others too
    }
  };
  std::vector<std::thread> pool;
  for (int i = 0; i < threads; ++i) pool.emplace_back(worker);
  while (done.load() < static_cast<long>(total) && !worker_failed.load() &&
         !(options.cancel && options.cancel->load())) {
    if (options.progress) options.progress(done.load(), failed.load(), static_cast<long>(total));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  for (auto& th : pool) th.join();
  if (options.progress) options.progress(done.load(), failed.load(), static_cast<long>(total));
  if (!worker_error.empty()) throw std::runtime_error("evaluate: a worker failed: " + worker_error);

  EvaluationRun run;
  if (options.cancel && options.cancel->load()) {
    run.cancelled = true;
    return run;
  }
  std::vector<FinalPose> final_poses;
  for (const auto& f : finals) {
    if (f) final_poses.push_back(*f);
  }
  run.report = Summarise(built.infos, results, options.budgets, ComputeNoiseFloor(final_poses));
  run.report.campaign_id = campaign_id;
  run.report.truth = TruthOf(store, campaign_id);
  run.start = StartShareOf(built.infos, results, planned, trial_starts, options.start_from);
  run.report.scales = options.scales;
  if (options.group_of) {
    run.report.group_by = options.group_by;
    run.report.groups = SummariseGroups(built.infos, results, group_of_trial);
  }

  // The convergence table: a few trials, short pieces from the true state.
  if (options.convergence_trials > 0 && !trials.empty()) {
    std::vector<ConvergenceTrial> sample;
    for (std::size_t ti : Spread(trials.size(), options.convergence_trials)) {
      // A closed-loop trial's pieces would need its commands replayed from
      // the restart on; the table is built from open-loop trials only.
      if (!scenes[ti] || (scenes[ti]->pusher && scenes[ti]->pusher->controller)) continue;
      try {
        sample.push_back(
            ConvergenceTrial{*scenes[ti], ReadTruth(store, trials[ti].id, *scenes[ti])});
      } catch (const std::exception&) {
      }
    }
    std::size_t flat = 0;
    for (const auto& p : built.predictors) {
      const auto table = ConvergenceTable(*p, sample);
      for (std::size_t i = 0; i < table.size(); ++i)
        run.report.settings[flat + i].convergence = table[i];
      flat += table.size();
    }
  }

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
  std::vector<db::EvaluationResult> rows;
  rows.reserve(results.size());
  for (auto& r : results)
    rows.push_back(db::EvaluationResult{r.trial_id, r.attempt, std::move(r.prediction)});
  run.settings_json = grid.dump();
  nlohmann::json report = ToJson(run.report);
  report["start"] = ToJson(run.start);
  const std::string report_json = report.dump();
  try {
    db::RetryWhileBusy(
        [&] {
          run.evaluation_id =
              store.RecordEvaluation(campaign_id, run.settings_json, report_json, rows);
        },
        [&](double waited, const std::string& why) {
          if (options.cancel && options.cancel->load()) return false;
          return !options.on_store_busy || options.on_store_busy(waited, why);
        });
  } catch (const db::StoreError& e) {
    run.not_stored = e.what();  // the finished work is the caller's to keep
    run.not_stored_kind = e.kind();
  }
  return run;
}

}  // namespace arena::assessment
