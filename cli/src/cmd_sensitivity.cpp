// arena sensitivity SCENE.json [--params P,...] [--tolerance T ...] [--defects F] [--json]
// arena sensitivity --db FILE --campaign ID [--ensemble N] [--seed S] [--json]
// Model reliability (docs/sensitivity.md): how the predicted outcome of one
// push depends on its inputs and whether it is unstable; for a campaign, the
// predicted spread under its defect profile beside the replicates' spread.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/assessment/campaign_sensitivity.hpp"
#include "arena/assessment/sensitivity.hpp"
#include "arena/db/sensitivity.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/simulators/simulator.hpp"
#include "commands.hpp"
#include "progress.hpp"
#include "result_file.hpp"
#include "signals.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

using assessment::Quantity;

struct SensitivityCliOptions {
  std::string scene_path;
  std::string db_path;
  std::int64_t campaign = -1;
  std::vector<std::string> params;
  std::vector<std::string> tolerances;
  std::string defects_path;
  double sigmas = 2;
  double linear_multiple = 3;
  double step_scale = 1;
  int ensemble = 32;
  std::uint64_t seed = 1;
  int threads = 0;
  bool no_stability = false;
  bool no_start_pose = false;
  bool no_store = false;
  bool json = false;
  std::string simulator = "arena";
  std::string simulator_settings;
  int facets = 0, points = 0;  // model overrides (0: keep)
  double dt = 0;
};

// The predictor by name (simulators room: "arena", "mujoco"), with its
// settings as JSON ("" = defaults). Simulator::Simulate is const and
// thread-safe, so one instance serves every worker.
assessment::SimulateFn SimulatorByName(const std::string& name, const std::string& settings) {
  std::shared_ptr<const simulators::Simulator> sim;
  try {
    sim = simulators::MakeSimulator(name, settings);
  } catch (const simulators::SimulatorError& e) {
    throw CommandError(kExitBadInput, std::string("--simulator: ") + e.what());
  }
  return [sim](const mechanics::Scene& scene) { return sim->Simulate(scene); };
}

// "5%" or "0.05" (relative, every parameter), or NAME=VALUE (absolute, in
// the parameter's unit).
void ParseTolerance(const std::string& text, assessment::StabilityOptions* s) {
  const auto eq = text.find('=');
  auto number = [&](const std::string& v) {
    std::size_t used = 0;
    double x = 0;
    try {
      x = std::stod(v, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    const bool percent = used > 0 && used + 1 == v.size() && v.back() == '%';
    if (used == 0 || (used != v.size() && !percent) || !std::isfinite(x) || x <= 0) {
      throw CommandError(kExitBadInput, "--tolerance '" + text +
                                            "': must be a number > 0, a percentage (5%) or "
                                            "NAME=VALUE");
    }
    return percent ? x / 100 : x;
  };
  if (eq == std::string::npos) {
    s->relative_tolerance = number(text);
  } else {
    s->tolerances[text.substr(0, eq)] = number(text.substr(eq + 1));
  }
}

std::string ReadFile(const std::string& path, const char* what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CommandError(kExitBadInput, std::string(what) + ": cannot read '" + path + "'");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string Fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

// Human output in mm, degrees and N (JSON: SI, `--json`).
std::string SceneText(const assessment::SensitivityReport& r, const mechanics::Scene& scene) {
  using assessment::HumanUnitOf;
  std::ostringstream out;
  const auto& n = r.nominal;
  const double mm = HumanUnitOf("m").factor, deg = HumanUnitOf("rad").factor;
  out << "nominal outcome: position (" << Fmt("%.4g", n.value(Quantity::kPositionX) * mm) << ", "
      << Fmt("%.4g", n.value(Quantity::kPositionY) * mm) << ", "
      << Fmt("%.4g", n.value(Quantity::kPositionZ) * mm) << ") mm, rotation "
      << Fmt("%.4g", n.value(Quantity::kRotation) * deg) << " deg, displacement "
      << Fmt("%.4g", n.value(Quantity::kDisplacement) * mm) << " mm, pusher force "
      << Fmt("%.4g", n.value(Quantity::kPusherForce)) << " N; grasp "
      << (n.grasp_kept ? "kept" : "lost") << "\n  modes:";
  const auto names = assessment::ContactNames(scene);
  for (size_t c = 0; c < n.modes.size() && c < names.size(); ++c) {
    out << " " << names[c] << " " << assessment::ModeSequenceText(n.modes[c]) << ";";
  }
  out << "\n\nparameters ranked by their largest normalised effect (% of the outcome per 1 % of "
         "the parameter's scale):\n";
  char line[400];
  std::snprintf(line, sizeof line, "%4s  %-28s %11s %6s  %-13s %13s %-11s %10s  %s\n", "rank",
                "parameter", "nominal", "unit", "most moves", "d/dp", "unit", "normalised", "note");
  out << line;
  int rank = 0;
  for (const auto& p : r.parameters) {
    int best = 0;
    for (int q = 1; q < assessment::kQuantityCount; ++q) {
      if (std::abs(p.derivatives[size_t(q)].normalised) >
          std::abs(p.derivatives[size_t(best)].normalised))
        best = q;
    }
    const auto& d = p.derivatives[size_t(best)];
    const auto pu = HumanUnitOf(p.parameter.unit);
    const auto qu = HumanUnitOf(assessment::Unit(Quantity(best)));
    const std::string unit =
        qu.unit + "/" + (pu.unit.find('/') != std::string::npos ? "(" + pu.unit + ")" : pu.unit);
    std::snprintf(line, sizeof line, "%4d  %-28s %11.4g %6s  %-13s %13.4g %-11s %10.3g  %s\n",
                  ++rank, p.parameter.name.c_str(), p.parameter.nominal * pu.factor,
                  pu.unit.c_str(), assessment::Name(Quantity(best)),
                  d.value * qu.factor / pu.factor, unit.c_str(), d.normalised,
                  p.differentiable ? "" : ("not differentiable here: " + p.note).c_str());
    out << line;
  }
  const auto& s = r.stability;
  if (s.checked) {
    out << "\nstability: " << (s.unstable ? "UNSTABLE" : "stable") << "\n";
    for (const auto& reason : s.reasons) out << "  - " << reason << "\n";
    if (s.nearest) {
      std::string unit;
      for (const auto& p : r.parameters)
        if (p.parameter.name == s.nearest->parameter) unit = p.parameter.unit;
      const auto hu = HumanUnitOf(unit);
      out << "  nearest boundary: " << s.nearest->parameter << " at "
          << Fmt("%+.4g", s.nearest->offset * hu.factor)
          << (hu.unit.empty() || hu.unit == "1" ? "" : " " + hu.unit) << " ("
          << Fmt("%.3g", s.nearest->tolerances) << " tolerances): " << s.nearest->change << "\n";
    } else {
      out << "  no boundary found within the searched range\n";
    }
  }
  out << "\n"
      << r.model_runs << " model runs on " << r.threads << " threads, " << Fmt("%.3g", r.wall_s)
      << " s\n";
  return out.str();
}

int RunSceneSensitivity(const SensitivityCliOptions& o, assessment::SensitivityOptions so) {
  mechanics::Scene scene;
  try {
    scene = mechanics::LoadSceneFile(o.scene_path);
    if (o.facets > 0) scene.model.facets = o.facets;
    if (o.points > 0) scene.model.points = o.points;
    if (o.dt > 0) scene.model.dt = o.dt;
    mechanics::ValidateScene(scene);  // the overrides too
  } catch (const mechanics::SceneError& e) {
    throw CommandError(kExitBadInput, std::string("sensitivity: ") + e.what());
  }
  if (!o.defects_path.empty()) {
    try {
      so.stability.noise = assessment::ParseActuationNoise(ReadFile(o.defects_path, "--defects"));
    } catch (const assessment::NoiseError& e) {
      throw CommandError(kExitBadInput, "--defects: " + std::string(e.what()));
    }
  }
  so.check_stability = !o.no_stability;
  // The plan grows once (the stability probes follow the derivatives): a new
  // line for each phase.
  std::unique_ptr<ProgressLine> progress;
  long progress_total = 0;
  so.progress = [&](long done, long total) {
    if (!progress || total != progress_total) {
      if (progress) progress->Finish();
      progress = std::make_unique<ProgressLine>(total, "model runs");
      progress_total = total;
    }
    progress->Update(done, 0);
  };
  assessment::SensitivityReport report;
  try {
    report = assessment::AnalyseScene(scene, so);
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, std::string("sensitivity: ") + e.what());
  }
  if (progress) progress->Finish();
  if (!report.nominal.ok) {
    throw CommandError(kExitFailure,
                       "sensitivity: the model fails on the scene itself: " + report.nominal.error);
  }
  if (o.json) {
    std::printf("%s\n", assessment::ToJson(report, scene).dump(2).c_str());
  } else {
    const std::string text = SceneText(report, scene);
    std::fwrite(text.data(), 1, text.size(), stdout);
  }
  return kExitOk;
}

std::string Opt(const std::optional<double>& v, double scale, const char* f) {
  return v ? Fmt(f, *v * scale) : std::string("-");
}

// A condition in the words of its campaign: its varied parameters as
// name=value in the units a person reads (mm, mm/s, N), not its index alone
// nor the campaign file's SI numbers.
std::string ConditionWords(const std::string& params_json) {
  const auto j = nlohmann::json::parse(params_json, nullptr, false);
  if (!j.is_object() || j.empty()) return params_json.empty() ? "-" : params_json;
  std::string out;
  for (const auto& [name, value] : j.items()) {
    out += (out.empty() ? "" : ", ") + name + "=";
    out += value.is_number() ? orchestrator::HumanVariationValue(name, value.get<double>())
                             : (value.is_string() ? value.get<std::string>() : value.dump());
  }
  return out;
}

std::string CampaignText(const assessment::CampaignSensitivityReport& r, std::int64_t run_id) {
  std::ostringstream out;
  char line[512];
  out << "campaign " << r.campaign_id << ": " << r.conditions.size() << " conditions"
      << (run_id > 0 ? ", stored as sensitivity run " + std::to_string(run_id) : "") << "\n";
  std::snprintf(line, sizeof line, "%5s %4s %5s %21s %21s  %-22s %-8s %-20s %s\n", "cond", "reps",
                "ens", "pos spread mm obs/pred", "rot spread deg o/p", "verdict", "stable",
                "nearest boundary", "condition");
  out << line;
  for (const auto& c : r.conditions) {
    const std::string pos = Opt(c.observed_position_spread, 1e3, "%.3g") + "/" +
                            Opt(c.predicted_position_spread, 1e3, "%.3g");
    const double deg = assessment::HumanUnitOf("rad").factor;
    const std::string rot = Opt(c.observed_rotation_spread, deg, "%.3g") + "/" +
                            Opt(c.predicted_rotation_spread, deg, "%.3g");
    std::string boundary = "-";
    if (!c.boundary_parameter.empty()) {
      boundary = c.boundary_parameter + " at " + Opt(c.boundary_tolerances, 1, "%.2g") + " tol";
    }
    std::snprintf(line, sizeof line, "%5d %4d %5d %21s %21s  %-22s %-8s %-20s %s\n", c.condition,
                  c.replicates, c.ensemble, pos.c_str(), rot.c_str(), c.verdict.c_str(),
                  c.unstable ? "UNSTABLE" : "stable", boundary.c_str(),
                  ConditionWords(c.params_json).c_str());
    out << line;
  }
  out << "verdicts: " << r.matches << " match, " << r.underestimates << " model underestimates, "
      << r.overestimates << " model overestimates, " << r.too_few << " too few replicates, "
      << r.no_prediction << " no prediction\n";
  out << "pooled observed/predicted spread: position " << Opt(r.pooled_position_ratio, 1, "%.3g")
      << " (" << r.pooled_position_verdict << "), rotation "
      << Opt(r.pooled_rotation_ratio, 1, "%.3g") << " (" << r.pooled_rotation_verdict << ")\n";
  // Each unstable condition by its parameters (not only its index) and why.
  out << "unstable conditions: " << r.unstable << "\n";
  for (const auto& c : r.conditions) {
    if (!c.unstable) continue;
    out << "  condition " << c.condition << " (" << ConditionWords(c.params_json)
        << "): " << (c.reason.empty() ? "no reason recorded" : c.reason) << " ("
        << Fmt("%.0f", c.flip_fraction * 100) << " % of the ensemble changed contact modes or "
        << "grasp)\n";
  }
  out << r.model_runs << " model runs on " << r.threads << " threads, " << Fmt("%.3g", r.wall_s)
      << " s\n";
  return out.str();
}

int RunCampaignSensitivity(const SensitivityCliOptions& o,
                           const assessment::SensitivityOptions& so) {
  assessment::CampaignSensitivityOptions co;
  co.ensemble = o.ensemble;
  co.seed = o.seed;
  co.threads = o.threads;
  co.check_stability = !o.no_stability;
  co.draw_start_pose = !o.no_start_pose;
  co.params = o.params;
  co.stability.tolerances = so.stability.tolerances;
  // The campaign view probes the cell's noise; a relative --tolerance adds every parameter.
  const bool relative = std::any_of(o.tolerances.begin(), o.tolerances.end(),
                                    [](const std::string& t) { return t.find('=') == t.npos; });
  co.stability.relative_tolerance = relative ? so.stability.relative_tolerance : 0.0;
  co.stability.noise_sigmas = o.sigmas;
  co.stability.linear_multiple = o.linear_multiple;
  co.simulate = so.simulate;
  co.simulator_name =
      o.simulator + (o.simulator_settings.empty() ? "" : " " + o.simulator_settings);
  co.facets = o.facets;
  co.points = o.points;
  co.dt = o.dt;

  std::atomic<bool> cancel{false};
  SignalWatcher signals([&cancel](int) { cancel.store(true); });
  co.cancel = &cancel;
  std::unique_ptr<ProgressLine> progress;
  co.progress = [&](long done, long total) {
    if (!progress) progress = std::make_unique<ProgressLine>(total, "conditions");
    progress->Update(done, 0);
  };
  assessment::CampaignSensitivityReport report;
  std::int64_t run_id = 0;
  try {
    db::StoreOptions opts;
    opts.scene_facts = orchestrator::SceneFactsOfJson;  // an older store's migration reads scenes
    opts.create = false;
    opts.read_only = o.no_store;
    auto store = db::Store::Open(o.db_path, opts);
    report = assessment::AnalyseCampaign(*store, o.campaign, co);
    if (progress) progress->Finish();
    if (report.cancelled) {
      std::fprintf(stderr, "sensitivity: interrupted; nothing stored\n");
      return kExitInterrupted;
    }
    if (!o.no_store) {
      // Finished: a store locked by another process is waited for, not a
      // reason to throw the run away (Ctrl-C gives up).
      db::RetryWhileBusy(
          [&] {
            run_id =
                db::RecordSensitivityRun(*store, o.campaign, assessment::SettingsJson(co).dump(),
                                         assessment::SummaryJson(report).dump(), report.conditions);
          },
          BusyStoreNotice("sensitivity", "", [&cancel] { return cancel.load(); }));
    }
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  } catch (const assessment::NoiseError& e) {
    throw CommandError(kExitBadInput, std::string("sensitivity: defect profile: ") + e.what());
  } catch (const mechanics::SceneError& e) {
    throw CommandError(kExitBadInput, std::string("sensitivity: stored scene: ") + e.what());
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, std::string("sensitivity: ") + e.what());
  }
  if (o.json) {
    nlohmann::json j = assessment::SummaryJson(report);
    j["sensitivity_run_id"] = run_id;
    nlohmann::json rows = nlohmann::json::array();
    auto opt = [](const std::optional<double>& v) {
      return v ? nlohmann::json(*v) : nlohmann::json(nullptr);
    };
    for (const auto& c : report.conditions) {
      rows.push_back({{"condition", c.condition},
                      {"params", nlohmann::json::parse(c.params_json)},
                      {"replicates", c.replicates},
                      {"ensemble", c.ensemble},
                      {"ensemble_failed", c.ensemble_failed},
                      {"predicted_position_spread", opt(c.predicted_position_spread)},
                      {"observed_position_spread", opt(c.observed_position_spread)},
                      {"predicted_rotation_spread", opt(c.predicted_rotation_spread)},
                      {"observed_rotation_spread", opt(c.observed_rotation_spread)},
                      {"predicted_displacement", opt(c.predicted_displacement)},
                      {"observed_displacement", opt(c.observed_displacement)},
                      {"predicted_rotation", opt(c.predicted_rotation)},
                      {"observed_rotation", opt(c.observed_rotation)},
                      {"verdict", c.verdict},
                      {"flip_fraction", c.flip_fraction},
                      {"unstable", c.unstable},
                      {"boundary_parameter", c.boundary_parameter},
                      {"boundary_offset", opt(c.boundary_offset)},
                      {"boundary_tolerances", opt(c.boundary_tolerances)},
                      {"reason", c.reason}});
    }
    j["condition_rows"] = rows;
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    const std::string text = CampaignText(report, run_id);
    std::fwrite(text.data(), 1, text.size(), stdout);
  }
  return kExitOk;
}

int RunSensitivity(const SensitivityCliOptions& o) {
  const bool campaign_mode = !o.db_path.empty() || o.campaign >= 0;
  if (campaign_mode == !o.scene_path.empty()) {
    throw CommandError(kExitBadInput,
                       "sensitivity: give either SCENE.json or --db FILE --campaign ID");
  }
  if (campaign_mode && (o.db_path.empty() || o.campaign < 0)) {
    throw CommandError(kExitBadInput, "sensitivity: the campaign view needs --db and --campaign");
  }
  if (campaign_mode && !o.defects_path.empty()) {
    throw CommandError(kExitBadInput,
                       "--defects: only for a scene; the campaign view uses the profile each "
                       "trial's cell recorded");
  }
  if (o.threads < 0) throw CommandError(kExitBadInput, "--threads: must be >= 0 (0: one per core)");
  if (!(o.sigmas > 0) || !std::isfinite(o.sigmas)) {
    throw CommandError(kExitBadInput, "--sigmas: must be a finite number > 0");
  }
  assessment::SensitivityOptions so;
  so.params = o.params;
  so.step_scale = o.step_scale;
  so.threads = o.threads;
  so.simulate = SimulatorByName(o.simulator, o.simulator_settings);
  so.stability.noise_sigmas = o.sigmas;
  so.stability.linear_multiple = o.linear_multiple;
  for (const auto& t : o.tolerances) ParseTolerance(t, &so.stability);
  if (campaign_mode) return RunCampaignSensitivity(o, so);
  if (!o.defects_path.empty() && o.tolerances.empty()) {
    // The cell's noise sets the tolerances it covers; nothing else is probed
    // unless --tolerance says so.
    so.stability.relative_tolerance = 0;
  }
  return RunSceneSensitivity(o, so);
}

}  // namespace

void AddSensitivityCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<SensitivityCliOptions>();
  auto* cmd = app.add_subcommand(
      "sensitivity",
      "How sensitive a push's predicted outcome is to its inputs, and whether it is unstable; "
      "for a campaign, predicted vs observed spread per condition");
  cmd->add_option("scene", o->scene_path, "Scene JSON file (docs/scene.md)");
  cmd->add_option("--db", o->db_path, "Store file (campaign view)");
  cmd->add_option("--campaign", o->campaign, "Campaign id (campaign view)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--params", o->params,
                  "Parameters to analyse, comma separated: names (grip_force, left.mu, "
                  "pusher.velocity.z), groups (friction, velocity, angular_velocity, position, "
                  "normal, kinematics, mass) or a contact's name (left); default all")
      ->delimiter(',');
  cmd->add_option("--tolerance", o->tolerances,
                  "Stability tolerance, repeatable: '2%' (or 0.02) of every parameter's scale, or "
                  "NAME=VALUE in the parameter's unit. Scene default: 2%; with --defects or in the "
                  "campaign view: the cell's noise only");
  cmd->add_option("--defects", o->defects_path,
                  "Defect profile whose actuation and friction noise set the tolerances (scene)");
  cmd->add_option("--sigmas", o->sigmas, "Noise tolerances are this many standard deviations")
      ->capture_default_str();
  cmd->add_option("--linear-multiple", o->linear_multiple,
                  "Unstable when a quantity moves more than this multiple of its linearised "
                  "estimate within the tolerance")
      ->capture_default_str();
  cmd->add_option("--step-scale", o->step_scale,
                  "Multiplies every parameter's finite-difference step")
      ->capture_default_str();
  cmd->add_option("--ensemble", o->ensemble, "Campaign view: model runs per condition")
      ->capture_default_str();
  cmd->add_option("--seed", o->seed, "Campaign view: the ensemble's seed")->capture_default_str();
  cmd->add_option("--threads", o->threads, "Worker threads (0: one per core)")
      ->capture_default_str();
  cmd->add_option("--simulator", o->simulator, "Predictor to analyse: arena or mujoco")
      ->capture_default_str();
  cmd->add_option("--simulator-settings", o->simulator_settings,
                  "The simulator's settings as JSON, e.g. '{\"timestep\": 0.001}' for mujoco");
  cmd->add_option("--facets", o->facets,
                  "Model setting for every run (0: the scene's, or the campaign's prediction)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--points", o->points, "Model setting for every run (0: keep)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--dt", o->dt, "Model time step for every run, s (0: keep)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--no-stability", o->no_stability, "Skip the stability probes");
  cmd->add_flag("--no-start-pose", o->no_start_pose,
                "Campaign view: start every ensemble run at the nominal pose (leave out the "
                "reset's placement error, to tell its share of the spread)");
  cmd->add_flag("--no-store", o->no_store, "Campaign view: do not store the run");
  cmd->add_flag("--json", o->json, "Print the report as JSON");
  cmd->footer(
      "Examples:\n"
      "  arena sensitivity examples/scenes/canonical.json\n"
      "  arena sensitivity scene.json --params grip_force,friction --tolerance 5% --json\n"
      "  arena sensitivity scene.json --defects examples/defects/noisy.json\n"
      "  arena sensitivity --db lab.db --campaign 3 --ensemble 64\n"
      "Derivatives are central differences at steps h and h/2; a parameter whose two estimates\n"
      "disagree, or whose probes change a contact mode, is 'not differentiable here'. A push is\n"
      "unstable when a change within the tolerance flips a contact mode sequence or the grasp,\n"
      "or moves an outcome more than --linear-multiple times its linear estimate\n"
      "(docs/sensitivity.md). The campaign view stores its run (tables sensitivity_runs,\n"
      "sensitivity_conditions); map it with arena plot --campaign ID --map X,Y --metric M.\n");
  cmd->callback([o, action] { *action = [o] { return RunSensitivity(*o); }; });
}

}  // namespace arena::cli
