// arena calibrate --db F --campaign ID --params mu_fingers,mu_pusher[,...]
//                 [--predictor arena] [--holdout 0.3] [--bootstrap 20] ...
// Fits model parameters to a campaign's done trials (assessment/calibration.hpp),
// prints the fit with its uncertainty and the held-out error before/after,
// and stores it; a campaign's "prediction": {"calibration": ID} then uses it.
#include <unistd.h>

#include <cstdio>
#include <memory>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/simulate.hpp"
#include "commands.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

struct CalibrateOptions {
  std::string db_path;
  std::int64_t campaign = 0;
  std::string params;
  std::string predictor = "arena";
  double holdout = 0.3;
  int bootstrap = 20;
  int max_evaluations = 150;
  std::uint64_t seed = 1;
  int threads = 1;
  double lower = 0.2, upper = 5.0;
  bool json = false;
};

std::vector<assessment::CalibrationParam> ParseParams(const std::string& list) {
  std::vector<assessment::CalibrationParam> out;
  std::stringstream in(list);
  std::string name;
  while (std::getline(in, name, ',')) {
    if (name.empty()) continue;
    out.push_back(assessment::ParseCalibrationParam(name));
  }
  return out;
}

int RunCalibrate(const CalibrateOptions& o) {
  if (o.predictor != "arena") {
    throw CommandError(kExitBadInput, "--predictor: '" + o.predictor +
                                          "' is not available in this build (only 'arena', the "
                                          "contact model of mechanics/)");
  }
  assessment::CalibrationOptions co;
  try {
    co.params = ParseParams(o.params);
  } catch (const assessment::CalibrationError& e) {
    throw CommandError(kExitBadInput, e.what());
  }
  co.holdout = o.holdout;
  co.bootstrap = o.bootstrap;
  co.max_evaluations = o.max_evaluations;
  co.seed = o.seed;
  co.threads = o.threads;
  co.lower = o.lower;
  co.upper = o.upper;
  if (isatty(STDERR_FILENO))
    co.progress = [](const std::string& line) {
      std::fprintf(stderr, "calibrate: %s\n", line.c_str());
    };

  std::unique_ptr<db::Store> store;
  std::vector<assessment::CalibrationTrial> trials;
  nlohmann::json model;
  try {
    db::StoreOptions so;
    so.create = false;  // calibrating needs a campaign: a missing file is an error
    store = db::Store::Open(o.db_path, so);
    const db::Campaign campaign = store->GetCampaign(o.campaign);
    const auto spec = nlohmann::json::parse(campaign.spec_json);
    if (spec.contains("prediction")) model = spec["prediction"];
    // Fit against the uncalibrated model: a previous calibration is not stacked.
    if (model.is_object()) model.erase("calibrated");
    trials = assessment::LoadCalibrationTrials(*store, o.campaign, [&](const mechanics::Scene& s) {
      return assessment::ApplyModelSettings(s, model);
    });
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  }

  assessment::CalibrationResult r;
  try {
    r = assessment::Calibrate(
        trials, [](const mechanics::Scene& s) { return mechanics::Simulate(s); }, co);
  } catch (const assessment::CalibrationError& e) {
    throw CommandError(kExitBadInput, e.what());
  }

  db::Calibration cal;
  cal.campaign_id = o.campaign;
  cal.params_json = assessment::ParamsJson(r);
  cal.settings_json = nlohmann::json{{"params", o.params},
                                     {"predictor", o.predictor},
                                     {"model", model},
                                     {"holdout", o.holdout},
                                     {"bootstrap", o.bootstrap},
                                     {"max_evaluations", o.max_evaluations},
                                     {"seed", o.seed},
                                     {"bounds", {o.lower, o.upper}},
                                     {"loss_scales",
                                      {{"position_m", co.scales.position_m},
                                       {"angle_rad", co.scales.angle_rad},
                                       {"force_n", co.scales.force_n}}}}
                          .dump();
  cal.heldout_error_before = r.heldout_before;
  cal.heldout_error_after = r.heldout_after;
  cal.applied = r.improved;
  cal.report_json = assessment::ReportJson(r);
  std::int64_t id = 0;
  try {
    id = store->RecordCalibration(cal);
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  }

  if (o.json) {
    std::printf("%s\n", nlohmann::json{{"id", id},
                                       {"campaign", o.campaign},
                                       {"applied", r.improved},
                                       {"params", nlohmann::json::parse(cal.params_json)},
                                       {"report", nlohmann::json::parse(cal.report_json)}}
                            .dump()
                            .c_str());
  } else {
    std::printf(
        "calibration %lld of campaign %lld (%s, %d loss evaluations, %zu trials fitted, "
        "%zu held out)\n\n",
        static_cast<long long>(id), static_cast<long long>(o.campaign), r.optimizer.c_str(),
        r.evaluations, r.train_ids.size(), r.heldout_ids.size());
    std::printf("%-12s %9s %9s %21s %12s\n", "parameter", "scale", "+-std", "95% CI (bootstrap)",
                "value");
    for (const auto& f : r.fitted) {
      std::printf("%-12s %9.4f %9.4f   [%8.4f, %8.4f] ", f.name.c_str(), f.scale, f.std, f.ci_low,
                  f.ci_high);
      if (f.nominal)
        std::printf("%6.4g -> %.4g\n", *f.nominal, *f.nominal * f.scale);
      else
        std::printf("%12s\n", "(varies)");
    }
    std::printf("\nheld-out error       before      after\n");
    std::printf("  loss (weighted) %10.4g %10.4g\n", r.heldout_before, r.heldout_after);
    std::printf("  position (mm)   %10.4f %10.4f\n", r.heldout_position_before * 1e3,
                r.heldout_position_after * 1e3);
    std::printf("  angle (deg)     %10.4f %10.4f\n", r.heldout_angle_before * 57.29577951,
                r.heldout_angle_after * 57.29577951);
    std::printf("  force RMS (N)   %10.4f %10.4f\n", r.heldout_force_before, r.heldout_force_after);
    if (r.improved) {
      std::printf("\napplied: a campaign uses it with \"prediction\": {\"calibration\": %lld}\n",
                  static_cast<long long>(id));
    } else {
      std::printf("\nNOT applied: the fit does not lower the held-out error\n");
    }
  }
  return r.improved ? kExitOk : kExitFailure;
}

}  // namespace

void AddCalibrateCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<CalibrateOptions>();
  auto* cmd = app.add_subcommand(
      "calibrate", "Fit model parameters (friction, ...) to a campaign's ground truth");
  cmd->add_option("--db", o->db_path, "Store file")->required();
  cmd->add_option("--campaign", o->campaign, "Campaign id whose done trials are fitted")
      ->required()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--params", o->params,
                  "Comma-separated: mu_fingers, mu_pusher, grip_force, object_mass (scales)")
      ->required();
  cmd->add_option("--predictor", o->predictor, "The model fitted: arena");
  cmd->add_option("--holdout", o->holdout, "Fraction of trials held out to judge the fit")
      ->check(CLI::Range(0.05, 0.9));
  cmd->add_option("--bootstrap", o->bootstrap, "Resamples for the uncertainty (0: none)")
      ->check(CLI::Range(0, 1000));
  cmd->add_option("--max-evaluations", o->max_evaluations, "Loss evaluations of the main fit")
      ->check(CLI::Range(5, 100000));
  cmd->add_option("--seed", o->seed, "Seed of the hold-out split and the bootstrap");
  cmd->add_option("--threads", o->threads, "Simulations in parallel")->check(CLI::Range(1, 256));
  cmd->add_option("--lower", o->lower, "Lower bound of every scale")->check(CLI::Range(0.01, 0.99));
  cmd->add_option("--upper", o->upper, "Upper bound of every scale")
      ->check(CLI::Range(1.01, 100.0));
  cmd->add_flag("--json", o->json, "JSON instead of a table");
  cmd->footer(
      "Example:\n"
      "  arena calibrate --db lab.db --campaign 1 --params mu_fingers,mu_pusher --holdout 0.3\n"
      "Exit 0: stored and applied; 1: stored, but it did not lower the held-out error (not "
      "applied).\nLoss weights and method: docs/closed_loop.md.\n");
  cmd->callback([o, action] { *action = [o] { return RunCalibrate(*o); }; });
}

}  // namespace arena::cli
