// arena run CAMPAIGN.json [--db FILE] [--cells N]: the embedded default. Starts
// N simulated cells as child processes on a private DDS domain, runs the
// service in this process until the campaign is finished, shows progress and
// prints a summary.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/executors/backend.hpp"
#include "arena/executors/controller.hpp"
#include "arena/executors/defect_layer.hpp"
#include "arena/executors/defects.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/logging.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/orchestrator/service.hpp"
#include "arena/orchestrator/submit.hpp"
#include "arena/schemas/security.hpp"
#include "campaign_input.hpp"
#include "child_process.hpp"
#include "commands.hpp"
#include "deadline_report.hpp"
#include "failure_reasons.hpp"
#include "progress.hpp"
#include "signals.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

struct RunOptions {
  std::string campaign_path;
  std::string db_path = "arena.db";
  int cells = 2;
  int domain = -1;                // -1: derived from the process id
  double speed = 0;               // cells' pacing: 0 = as fast as possible
  std::string defects_path;       // the cells' own profile (workspace, reset); optional
  std::string backend = "model";  // the cells' backend (arena cell --backend)
  std::string backend_settings;
  std::string log_level = "info";
  bool quiet = false;
  std::string
      security_lab;  // DDS-Security: LAB/service and LAB/sim1.. (arena certs); "": open domain
  dds::NetworkOptions network_for_probe;  // this host only, like the run's participants
};

std::string RunTag() {
  std::random_device rd;
  char buf[8];
  std::snprintf(buf, sizeof buf, "%06x", static_cast<unsigned>(rd() ^ (getpid() << 8)) & 0xffffff);
  return buf;
}

// A domain on which no participant is heard for a moment and that no other
// arena process on this host has claimed (dds::HostDomainClaim: one that
// chose its domain a moment ago may have no participant yet): two `arena
// run`s on one host, a run beside the test suite, or a lab's own domain do
// not share a domain by chance. The claim is held in `claim` for the run.
int QuietDomain(const dds::NetworkOptions& network, std::optional<dds::HostDomainClaim>& claim) {
  std::mt19937 pick(std::random_device{}());
  std::uniform_int_distribution<int> domain(100, dds::kMaxDomainId);
  for (int tries = 0; tries < 8; ++tries) {
    const int candidate = domain(pick);
    claim = dds::HostDomainClaim::TryClaim(candidate);
    if (!claim) {
      spdlog::info("domain {} is claimed by another arena process; trying another", candidate);
      continue;
    }
    dds::Participant probe(dds::ParticipantOptions{candidate, "arena.run-probe", network, 2.5});
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    if (probe.Peers().empty()) return candidate;
    spdlog::info("domain {} is in use ({} participants); trying another", candidate,
                 probe.Peers().size());
    claim.reset();
  }
  throw dds::DdsError("--domain: no quiet DDS domain found in 8 tries; pass --domain");
}

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

// The run flags (mechanics::RunFlagsJson) of a campaign's ok predictions.
struct PredictionFlags {
  std::int64_t steered = 0;               // a friction cone steered a slide
  std::int64_t steered_aligned = 0;       // ... though it was the aligned cone
  std::int64_t oscillating = 0;           // ended in a swing nothing damps
  std::int64_t oscillating_balanced = 0;  // ... though its steps were quasi-static
  std::int64_t oscillating_turned = 0;    // ... "auto" that ran carried (push needed momentum)
  std::int64_t oscillating_steered = 0;   // ... and steered as well
};

void CountFlags(const db::Prediction& p, PredictionFlags& f) {
  const bool steered = mechanics::HasRunFlag(p.detail_json, "steered_slip");
  const bool oscillating = mechanics::HasRunFlag(p.detail_json, "oscillation");
  if (!steered && !oscillating) return;
  const auto model = nlohmann::json::parse(p.model_json, nullptr, false);
  const auto detail = nlohmann::json::parse(p.detail_json, nullptr, false);
  if (steered) {
    ++f.steered;
    // (assessment::ModelSettingsJson has written `cone` since the aligned cone
    // became the default; settings stored before without it are polyhedral.)
    if (model.is_object() && model.value("cone", "") == "aligned") ++f.steered_aligned;
  }
  if (oscillating) {
    ++f.oscillating;
    if (detail.is_object() && detail.value("inertia", "") == "quasi_static")
      ++f.oscillating_balanced;
    // "auto" that tried balanced steps and ran the scene carried, where its
    // push needed the object's momentum (model.cpp, CarryOnPush): "auto" is
    // no hint there.
    else if (detail.is_object() && detail.contains("solver") && detail["solver"].is_object() &&
             detail["solver"].value("quasi_static_solves", 0L) > 0)
      ++f.oscillating_turned;
    if (steered) ++f.oscillating_steered;
  }
}

// Issue 31: where the friction cone steered the predictions' slides, their
// answers move with facets; where they ended swinging, their final pose is
// a phase of the swing. The run's summary says so, with the hint that
// applies.
void PrintFlags(const PredictionFlags& f, std::size_t predictions) {
  if (f.steered > 0) {
    std::printf(
        "  steered     %lld of %zu predictions slid where the friction cone steered them, so "
        "their answers\n"
        "              move with facets (%s)\n",
        static_cast<long long>(f.steered), predictions,
        f.steered_aligned == f.steered
            ? "the aligned cone's re-solves did not settle there; a finer\n"
              "              dt settles more: arena evaluate --dt weighs it"
            : "arena evaluate --cone polyhedral,aligned weighs the aligned cone");
  }
  if (f.oscillating > 0) {
    const char* hint =
        f.oscillating_balanced == f.oscillating
            ? "their quasi-static steps found no balance there and carried\n"
              "              the momentum; a finer dt balances more: arena evaluate --dt weighs it"
        : f.oscillating_balanced + f.oscillating_turned == f.oscillating
            ? "\"inertia\": \"auto\" ran them carried where the push needed the\n"
              "              object's momentum, so the swing is the carried model's answer there"
        : f.oscillating_steered > 0
            ? "\"inertia\": \"auto\" with \"cone\": \"aligned\" follows the\n"
              "              balanced path unsteered: arena evaluate --cone polyhedral,aligned\n"
              "              --inertia carried,auto weighs it"
            : "\"inertia\": \"auto\" follows the balanced path: arena evaluate\n"
              "              --inertia carried,auto weighs it";
    std::printf(
        "  oscillating %lld of %zu predictions ended in a swing nothing damps, so their final pose "
        "is\n"
        "              a phase of it (%s)\n",
        static_cast<long long>(f.oscillating), predictions, hint);
  }
}

// overhead_s: arena's own time per clean trial on its cell (TrialTiming).
// @returns the number of failed trials (the exit code says whether there were any).
std::int64_t PrintSummary(const std::string& db_path, std::int64_t campaign_id, double wall_s,
                          const std::vector<double>& overhead_s) {
  db::StoreOptions ro;
  ro.read_only = true;
  auto store = db::Store::Open(db_path, ro);
  const db::Campaign campaign = store->GetCampaign(campaign_id);
  std::vector<double> pos_err, ang_err, force_err, force_rel, mode, pred_time;
  std::int64_t done = 0, failed = 0, other = 0, prediction_failures = 0;
  PredictionFlags flags;
  for (const auto& t : store->ListTrials(campaign_id)) {
    if (t.state == db::TrialState::kDone)
      ++done;
    else if (t.state == db::TrialState::kFailed)
      ++failed;
    else
      ++other;
    for (const auto& p : store->ListPredictions(t.id)) {
      if (p.status != db::PredictionStatus::kOk) {
        ++prediction_failures;
        continue;
      }
      if (p.final_position_error) pos_err.push_back(*p.final_position_error);
      if (p.final_angle_error) ang_err.push_back(*p.final_angle_error);
      if (p.force_error) force_err.push_back(*p.force_error);
      if (p.mode_agreement) mode.push_back(*p.mode_agreement);
      pred_time.push_back(p.wall_s);
      CountFlags(p, flags);
    }
  }
  const std::int64_t total = done + failed + other;
  std::string truth_line;
  bool self_consistency = false;
  for (const auto& t : store->CampaignTruths(campaign_id)) {
    if (!truth_line.empty()) truth_line += "; ";
    const std::string what =
        t.truth == "self-consistency" ? "arena's own model (" + t.backend +
                                            " backend): self-consistency, "
                                            "not accuracy"
        : t.truth == "simulator" ? (t.backend == "mujoco" ? std::string("MuJoCo") : t.backend) +
                                       " (an independent engine)"
        : t.truth == "robot"    ? "a robot (" + t.backend + ")"
        : t.truth == "recorded" ? "recorded data (" + t.backend + ")"
        : t.truth == "measured" ? "measured data (" + t.backend +
                                      "): the observed streams are the truth, no separate "
                                      "true stream"
        : t.truth == db::kTruthMeasuredNoForces
            ? "measured data without forces (" + t.backend +
                  "): forces not measured or failed their import check, poses scored, forces "
                  "not"
            : "an unreported backend";
    self_consistency = self_consistency || t.truth == "self-consistency";
    truth_line += what + ", " + std::to_string(t.trials) + " trials";
  }
  std::printf("campaign %lld '%s': %s\n", static_cast<long long>(campaign_id),
              campaign.name.c_str(), db::ToString(campaign.state));
  std::printf("  trials      %lld: %lld done, %lld failed%s\n", static_cast<long long>(total),
              static_cast<long long>(done), static_cast<long long>(failed),
              other ? (", " + std::to_string(other) + " unfinished").c_str() : "");
  std::printf("  time        %s wall, %.1f trials/min\n", FormatDuration(wall_s).c_str(),
              wall_s > 0 ? 60.0 * (done + failed) / wall_s : 0.0);
  if (pos_err.empty()) {
    // No number rather than "nan mm": nothing was predicted and scored.
    std::printf("  model error none: no trial was predicted and scored\n");
  } else {
    std::printf(
        "  model error (median over %zu predictions): final position %.3g mm, final angle %.3g "
        "deg,\n",
        pos_err.size(), Median(pos_err) * 1e3, Median(ang_err) * 180 / M_PI);
    // Forces only where the truth measured them (a measured trial without
    // forces is not scored on them): say over how many.
    if (force_err.empty())
      std::printf("              contact force not scored (no truth measured forces)\n");
    else
      std::printf("              contact force %.3g N RMS, contact-mode agreement %.1f %%%s\n",
                  Median(force_err), 100 * Median(mode),
                  force_err.size() < pos_err.size()
                      ? (" (over " + std::to_string(force_err.size()) + "; " +
                         std::to_string(pos_err.size() - force_err.size()) +
                         " without measured forces not scored)")
                            .c_str()
                      : "");
  }
  if (!truth_line.empty()) {
    std::printf("  truth       model error is against %s\n", truth_line.c_str());
    if (self_consistency)
      std::printf(
          "              (arena's model against itself at higher settings: run --backend mujoco "
          "for an independent truth)\n");
  }
  if (!pred_time.empty())
    std::printf("  predictor   %.3g ms median per trial%s\n", Median(pred_time) * 1e3,
                prediction_failures
                    ? (", " + std::to_string(prediction_failures) + " predictions failed").c_str()
                    : "");
  PrintFlags(flags, pred_time.size());
  if (!overhead_s.empty()) {
    std::printf(
        "  orchestration %.2f ms median, %.2f ms p95 per trial (cell busy time minus its own "
        "execute\n"
        "              and reset time, %zu clean trials)\n",
        Median(overhead_s) * 1e3, Percentile(overhead_s, 0.95) * 1e3, overhead_s.size());
  }
  // Every failure with its reason (the cell's, the driver's, the predictor's).
  std::fputs(FormatFailures(CampaignFailures(*store, campaign_id), "  ").c_str(), stdout);
  std::fputs(FormatDeadlines(CampaignDeadlines(*store, campaign_id), "  ").c_str(), stdout);
  std::printf("  store       %s  (arena status --db %s; arena query --db %s \"select ...\")\n",
              db_path.c_str(), db_path.c_str(), db_path.c_str());
  return failed;
}

// The controller a closed-loop campaign's scenes name (variations never
// change the name); nullopt for an open-loop campaign.
std::optional<std::string> CampaignController(const orchestrator::Campaign& campaign) {
  const auto& pusher = campaign.scene.pusher;
  if (!pusher || !pusher->controller) return std::nullopt;
  return pusher->controller->name;
}

// Issue 26: the cells this run started and stopped say so in `arena status`
// ("stopped: its arena run ended"), not "no sign within its lease" as a lost
// cell would. A cell that never announced is not in the store: nothing to say.
void MarkRunCellsStopped(const RunOptions& opt, const std::string& run_tag) {
  try {
    auto store = db::Store::Open(opt.db_path);
    for (int k = 0; k < opt.cells; ++k) {
      try {
        store->MarkCellGone("sim" + std::to_string(k + 1) + run_tag,
                            "stopped: its arena run ended");
      } catch (const db::StoreError& e) {
        if (e.kind() != db::StoreError::Kind::kNotFound) throw;
      }
    }
  } catch (const db::StoreError& e) {
    spdlog::warn("arena run: marking its cells stopped: {}", e.what());
  }
}

// Issue 26: a campaign the cells this run starts cannot host is refused
// before anything is stored, with the reason a cell would give (the same
// checks: executors' defect layer), instead of every trial failing at the
// cells. The run knows what a service does not: the cells' backend and
// profile. Physics defects a backend cannot emulate refuse the campaign; so
// does a limit (workspace, pusher speed, contact types) every trial exceeds;
// a limit some trials exceed is warned about (those trials will fail).
void RefuseWhatTheCellsCannotRun(const orchestrator::Campaign& campaign, const RunOptions& opt) {
  executors::DefectProfile cell_profile;
  if (!opt.defects_path.empty()) {
    std::ifstream in(opt.defects_path);
    if (!in) return;  // the cells say why they cannot read it
    std::stringstream text;
    text << in.rdbuf();
    try {
      cell_profile = executors::ParseDefectProfile(text.str());
    } catch (const executors::DefectError& e) {
      throw CommandError(kExitBadInput, "--cell-defects " + opt.defects_path + ": " + e.what());
    }
  }
  executors::DefectProfile campaign_profile;
  try {
    campaign_profile = executors::ParseDefectProfile(campaign.defects_json);
  } catch (const executors::DefectError& e) {
    throw CommandError(kExitBadInput, std::string("defects: ") + e.what());
  }
  // The backend's capabilities, as a cell sees them (an exec: driver says
  // hello and is shut down again).
  executors::BackendCapabilities caps;
  const auto level = spdlog::get_level();
  spdlog::set_level(spdlog::level::warn);  // the driver's greeting is not the run's output
  try {
    caps = executors::MakeBackend(opt.backend, executors::ModelFidelity{}, opt.backend_settings)
               ->Capabilities();
  } catch (const std::exception& e) {
    spdlog::set_level(level);
    throw CommandError(kExitBadInput, e.what());
  }
  spdlog::set_level(level);
  if (!caps.emulates_defects && executors::PerturbsPhysics(campaign_profile)) {
    throw CommandError(
        kExitBadInput,
        "defects: the campaign perturbs the physics (friction_variability or actuation noise), "
        "and the cells' " +
            caps.name + " backend cannot (" + executors::ToString(caps.truth) +
            " truth is not simulated): every trial would be refused; run it on model or mujoco "
            "cells, or without those defects");
  }
  if (campaign.adaptive) return;  // its trials are chosen as it runs
  // The cells' rule: a recording's own extent is their workspace unless
  // their profile sets one.
  const executors::DefectProfile effective = executors::CombineProfiles(
      executors::WithBackendWorkspace(cell_profile, caps), campaign_profile);
  const std::int64_t n = orchestrator::TrialCount(campaign);
  std::int64_t refused = 0;
  std::string first;
  // Replicates of a condition share its scene: one check per condition.
  const std::int64_t step = std::max(1, campaign.replicates);
  for (std::int64_t i = 0; i < n; i += step) {
    const mechanics::Scene scene = orchestrator::PlanTrial(campaign, i).scene;
    std::string why = executors::CheckCapabilities(effective, scene);
    for (std::size_t f = 0; why.empty() && f < scene.fingers.size(); ++f) {
      if (!caps.contact_types.empty() &&
          std::find(caps.contact_types.begin(), caps.contact_types.end(), scene.fingers[f].type) ==
              caps.contact_types.end())
        why = "fingers[" + std::to_string(f) + "].type: the " + caps.name + " backend has no " +
              mechanics::ToString(scene.fingers[f].type) + " contacts";
    }
    if (why.empty()) continue;
    if (refused == 0) first = "trial " + std::to_string(i) + ": " + why;
    refused += std::min(step, n - i);
  }
  if (refused == n && n > 0) {
    throw CommandError(kExitBadInput,
                       "every trial of the campaign is beyond what the cells can do (" +
                           (opt.defects_path.empty() ? std::string("their default profile")
                                                     : "--cell-defects " + opt.defects_path) +
                           " with the campaign's defects), e.g. " + first);
  }
  if (refused > 0 && !opt.quiet)
    std::fprintf(stderr,
                 "warning: %lld of %lld trials are beyond what the cells can do and will be "
                 "refused, e.g. %s\n",
                 static_cast<long long>(refused), static_cast<long long>(n), first.c_str());
}

void CheckRunOptions(const RunOptions& opt) {
  if (opt.cells < 1 || opt.cells > 64)
    throw CommandError(kExitBadInput, "--cells: must be 1..64, got " + std::to_string(opt.cells));
  if (!(opt.speed >= 0)) throw CommandError(kExitBadInput, "--speed: must be >= 0");
  if (opt.domain > dds::kMaxDomainId || opt.domain < -1)
    throw CommandError(kExitBadInput, "--domain: must be 0.." + std::to_string(dds::kMaxDomainId) +
                                          ", got " + std::to_string(opt.domain));
}

// A DDS-Security identity of the lab's (--security): service, simN, a controller.
std::string RunIdentity(const RunOptions& opt, const std::string& name) {
  return opt.security_lab + "/" + name;
}

// Every identity checked before anything is stored: a missing one is named here.
void CheckRunIdentities(const RunOptions& opt, const orchestrator::Campaign& campaign) {
  if (opt.security_lab.empty()) return;
  try {
    dds::CheckIdentityDir(RunIdentity(opt, "service"));
    for (int k = 0; k < opt.cells; ++k)
      dds::CheckIdentityDir(RunIdentity(opt, "sim" + std::to_string(k + 1)));
    // A controller's identity is issued for its name (its name is bound to it).
    if (const auto name = CampaignController(campaign))
      dds::CheckIdentityDir(RunIdentity(opt, *name));
  } catch (const dds::SecurityError& e) {
    throw CommandError(kExitBadInput, std::string("--security: ") + e.what() +
                                          " (issue it with `arena certs issue " + opt.security_lab +
                                          " --role cell|service|controller --name NAME`)");
  }
}

// The simulated cells as child processes of this one.
std::vector<ChildProcess> StartRunCells(const RunOptions& opt, const std::string& run_tag,
                                        const std::string& self) {
  std::vector<ChildProcess> cells;
  for (int k = 0; k < opt.cells; ++k) {
    std::vector<std::string> argv = {self,           "cell",
                                     "--id",         "sim" + std::to_string(k + 1) + run_tag,
                                     "--domain",     std::to_string(opt.domain),
                                     "--speed",      std::to_string(opt.speed),
                                     "--parent-pid", std::to_string(getpid())};
    if (!opt.defects_path.empty()) argv.insert(argv.end(), {"--defects", opt.defects_path});
    argv.insert(argv.end(), {"--backend", opt.backend});
    if (!opt.backend_settings.empty())
      argv.insert(argv.end(), {"--backend-settings", opt.backend_settings});
    if (!opt.security_lab.empty())
      argv.insert(argv.end(), {"--security", RunIdentity(opt, "sim" + std::to_string(k + 1))});
    cells.emplace_back(argv, opt.db_path + ".sim" + std::to_string(k + 1) + ".log");
  }
  return cells;
}

// A closed-loop campaign's controller (issue 19), started like the cells
// when arena's library has it; a lab's own one the lab starts.
std::vector<ChildProcess> StartRunController(const RunOptions& opt,
                                             const orchestrator::Campaign& campaign,
                                             const std::string& self) {
  std::vector<ChildProcess> controllers;
  const auto name = CampaignController(campaign);
  if (!name) return controllers;
  const auto laws = executors::LibraryLaws();
  if (std::find(laws.begin(), laws.end(), *name) != laws.end()) {
    std::vector<std::string> argv = {self,           "controller",
                                     "--name",       *name,
                                     "--domain",     std::to_string(opt.domain),
                                     "--parent-pid", std::to_string(getpid())};
    if (!opt.security_lab.empty()) argv.insert(argv.end(), {"--security", RunIdentity(opt, *name)});
    controllers.emplace_back(argv, opt.db_path + ".controller.log");
  } else if (!opt.quiet) {
    std::fprintf(stderr,
                 "closed loop: start controller '%s' on domain %d yourself (it is not one of "
                 "arena's own)\n",
                 name->c_str(), opt.domain);
  }
  return controllers;
}

std::unique_ptr<orchestrator::Service> MakeRunService(const RunOptions& opt,
                                                      std::int64_t campaign_id) {
  orchestrator::ServiceOptions so;
  so.db_path = opt.db_path;
  so.domain_id = opt.domain;
  so.exit_when_done = true;
  so.only_campaign = campaign_id;
  if (!opt.security_lab.empty()) so.network.security_dir = RunIdentity(opt, "service");
  try {
    return std::make_unique<orchestrator::Service>(so);
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  }
}

// Each service tick: stops the run when no cell is left to finish the
// campaign (every cell process exited, or every cell quarantined or lost
// for 5 s), and shows the progress line. `failed` says why it stopped.
std::function<void(const orchestrator::ServiceCounters&)> WatchRunCells(
    const RunOptions& opt, std::vector<ChildProcess>* cells, orchestrator::Service* service,
    ProgressLine* progress, std::string* failed) {
  auto no_usable_since = std::make_shared<std::optional<std::chrono::steady_clock::time_point>>();
  return [=, &opt](const orchestrator::ServiceCounters& c) {
    int alive = 0;
    for (auto& cell : *cells) alive += !cell.Poll().has_value();
    if (alive == 0 && failed->empty()) {
      *failed = "every simulated cell exited (see " + opt.db_path + ".sim*.log)";
      service->Stop();
    }
    // Quarantined or lost cells get no trials: with none left the campaign cannot finish.
    const auto now = std::chrono::steady_clock::now();
    if (c.cells_known > 0 && c.cells_usable == 0) {
      if (!*no_usable_since) *no_usable_since = now;
      if (now - **no_usable_since > std::chrono::seconds(5) && failed->empty()) {
        *failed = "no usable cell left: every cell is quarantined or lost (arena status --db " +
                  opt.db_path + "; log " + orchestrator::ServiceLogPath(opt.db_path) + ")";
        service->Stop();
      }
    } else {
      no_usable_since->reset();
    }
    if (!opt.quiet) progress->Update(c.done + c.failed, c.failed, std::to_string(alive) + " cells");
  };
}

int Run(RunOptions opt) {
  CheckRunOptions(opt);
  // Signals first: the log's flusher, the cells and DDS threads inherit the blocked mask.
  std::atomic<orchestrator::Service*> running{nullptr};
  SignalWatcher signals([&running](int) {
    if (auto* s = running.load()) s->Stop();
  });

  const orchestrator::Campaign campaign = LoadValidCampaign(opt.campaign_path);
  RefuseWhatTheCellsCannotRun(campaign, opt);
  CheckRunIdentities(opt, campaign);
  // Held for the whole run, so no other arena process picks this domain.
  std::optional<dds::HostDomainClaim> domain_claim;
  if (opt.domain < 0) {
    opt.domain = QuietDomain(opt.network_for_probe, domain_claim);
  } else {
    // A domain given by hand is used whether or not another process holds
    // it (two runs may share one on purpose; their cells never mix); it is
    // claimed when free so that no quiet-domain pick lands on it.
    domain_claim = dds::HostDomainClaim::TryClaim(opt.domain);
  }
  std::int64_t campaign_id = 0;
  {
    db::StoreOptions so;
    so.scene_facts = orchestrator::SceneFactsOfJson;  // an older store's migration reads scenes
    auto store = db::Store::Open(opt.db_path, so);
    campaign_id = orchestrator::SubmitCampaign(*store, campaign);
  }
  orchestrator::SetUpServiceLog(opt.db_path, opt.log_level, /*to_stderr=*/false);
  // An adaptive campaign's count is open: its cap bounds the progress bar.
  const std::int64_t trials =
      campaign.adaptive
          ? std::min<std::int64_t>(campaign.adaptive->max_trials, orchestrator::kMaxTrials)
          : orchestrator::TrialCount(campaign);
  if (!opt.quiet)
    std::fprintf(
        stderr, "campaign %lld '%s': %s%lld trials on %d simulated cells (DDS domain %d, log %s)\n",
        static_cast<long long>(campaign_id), campaign.name.c_str(),
        campaign.adaptive ? "adaptive, up to " : "", static_cast<long long>(trials), opt.cells,
        opt.domain, orchestrator::ServiceLogPath(opt.db_path).c_str());

  // Cell ids unique to this run (sim1-3fa2c1, ...): two runs that end up on
  // one domain still never address each other's cells. With --security the
  // identities are the lab's sim1..N.
  const std::string run_tag = opt.security_lab.empty() ? "-" + RunTag() : "";
  const std::string self = SelfExecutable();
  std::vector<ChildProcess> cells = StartRunCells(opt, run_tag, self);
  std::unique_ptr<orchestrator::Service> service = MakeRunService(opt, campaign_id);
  std::vector<ChildProcess> controllers = StartRunController(opt, campaign, self);
  running = service.get();
  if (signals.received()) service->Stop();

  std::vector<double> overhead_s;
  service->OnTrialTiming(
      [&](const orchestrator::TrialTiming& t) { overhead_s.push_back(t.overhead_s); });
  const auto start = std::chrono::steady_clock::now();
  ProgressLine progress(trials, "trials");
  std::string cells_failed;
  service->OnTick(WatchRunCells(opt, &cells, service.get(), &progress, &cells_failed));
  service->Run();
  progress.Finish();
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  service.reset();
  running = nullptr;
  for (auto& cell : cells) cell.Stop();
  for (auto& controller : controllers) controller.Stop();
  MarkRunCellsStopped(opt, run_tag);
  spdlog::default_logger()->flush();

  const std::int64_t failed = PrintSummary(opt.db_path, campaign_id, wall, overhead_s);
  if (!cells_failed.empty()) throw CommandError(kExitCommunication, cells_failed);
  if (signals.received()) return kExitInterrupted;
  // README's exit codes: a campaign with failed trials is a failed command.
  if (failed > 0)
    throw CommandError(kExitFailure,
                       std::to_string(failed) + " trials failed (their reasons are listed above)");
  return kExitOk;
}

}  // namespace

void AddRunCommand(CLI::App& app, Action* action) {
  auto opt = std::make_shared<RunOptions>();
  CLI::App* cmd = app.add_subcommand("run", "Run a campaign end to end on local simulated cells");
  cmd->footer(
      "Example:\n  arena run examples/campaigns/smoke.json --db smoke.db --cells 2\n"
      "Starts the cells as child processes on a private DDS domain (this host only), runs the\n"
      "service until the campaign is finished, prints a summary. Ctrl-C stops cleanly; run the\n"
      "same store with `arena serve` to finish what was left.\n"
      "  arena run examples/campaigns/smoke.json --db smoke.db --cells 2 --security lab-pki\n"
      "runs it with DDS-Security: identities lab-pki/service and lab-pki/sim1, sim2 (arena "
      "certs).");
  cmd->add_option("campaign", opt->campaign_path, "Campaign JSON (orchestrator/README.md)")
      ->required();
  cmd->add_option("--db", opt->db_path, "SQLite store (created if missing)")->capture_default_str();
  cmd->add_option("--cells", opt->cells, "Simulated cells to start")->capture_default_str();
  cmd->add_option("--domain", opt->domain,
                  "DDS domain id (default: a domain in 100..231 with no participant on it)");
  cmd->add_option("--speed", opt->speed, "Cells' pacing: 0 = as fast as possible, 1 = wall clock")
      ->capture_default_str();
  cmd->add_option("--backend", opt->backend,
                  "The cells' backend: model (arena's own model: the error is self-consistency), "
                  "mujoco (an independent engine), exec:COMMAND, replay:DATASET")
      ->capture_default_str();
  cmd->add_option("--backend-settings", opt->backend_settings,
                  "The backend's settings (JSON object), passed to every cell");
  cmd->add_option("--cell-defects", opt->defects_path,
                  "Defect profile for the cells (executors/README.md)");
  cmd->add_option("--log-level", opt->log_level,
                  "Service log level (the log is FILE.log next to the store)")
      ->capture_default_str();
  cmd->add_flag("--quiet", opt->quiet, "No progress line");
  cmd->add_option(
      "--security", opt->security_lab,
      "DDS-Security: a lab from `arena certs init` holding identities service, sim1..simN");
  cmd->callback([opt, action] { *action = [opt] { return Run(*opt); }; });
}

}  // namespace arena::cli
