#include "arena/orchestrator/evaluation.hpp"

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

#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/prediction.hpp"
#include "arena/orchestrator/trial_data.hpp"

namespace arena::orchestrator {

// ------------------------------------------------------------ grid

std::vector<mechanics::ModelOptions> ExpandGrid(const FidelityGrid& g) {
  auto nonempty_unique = [](const auto& list, const char* name) {
    if (list.empty()) throw std::invalid_argument(std::string(name) + ": needs at least one value");
    std::set<std::decay_t<decltype(list[0])>> seen(list.begin(), list.end());
    if (seen.size() != list.size())
      throw std::invalid_argument(std::string(name) + ": a value is repeated");
  };
  nonempty_unique(g.facets, "facets");
  nonempty_unique(g.points, "points");
  nonempty_unique(g.dt, "dt");
  nonempty_unique(g.reduce, "reduce");
  for (int f : g.facets) {
    if (f < 3) throw std::invalid_argument("facets: must be >= 3, got " + std::to_string(f));
  }
  for (int k : g.points) {
    if (k < 2) throw std::invalid_argument("points: must be >= 2, got " + std::to_string(k));
  }
  for (double dt : g.dt) {
    if (!std::isfinite(dt) || dt <= 0) {
      throw std::invalid_argument("dt: must be a finite number > 0, got " + std::to_string(dt));
    }
  }
  std::vector<mechanics::ModelOptions> out;
  for (int f : g.facets)
    for (int k : g.points)
      for (double dt : g.dt)
        for (auto r : g.reduce) out.push_back(mechanics::ModelOptions{f, k, dt, r});
  return out;
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) throw std::invalid_argument("Percentile: no values");
  if (!(p >= 0 && p <= 1)) throw std::invalid_argument("Percentile: p must be in [0, 1]");
  std::sort(v.begin(), v.end());
  const double h = (static_cast<double>(v.size()) - 1) * p;
  const auto lo = static_cast<std::size_t>(std::floor(h));
  const std::size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

// ------------------------------------------------------------ budgets

namespace {

constexpr std::pair<ErrorMetric, const char*> kMetricNames[] = {
    {ErrorMetric::kPositionMedian, "position_median"},
    {ErrorMetric::kPositionP95, "position_p95"},
    {ErrorMetric::kAngleMedian, "angle_median"},
    {ErrorMetric::kAngleP95, "angle_p95"},
    {ErrorMetric::kForceMedian, "force_median"},
    {ErrorMetric::kForceP95, "force_p95"},
    {ErrorMetric::kModeAgreementMedian, "mode_agreement_median"},
};

enum class Quantity { kLength, kAngle, kForce, kFraction };

Quantity QuantityOf(ErrorMetric m) {
  switch (m) {
    case ErrorMetric::kPositionMedian:
    case ErrorMetric::kPositionP95:
      return Quantity::kLength;
    case ErrorMetric::kAngleMedian:
    case ErrorMetric::kAngleP95:
      return Quantity::kAngle;
    case ErrorMetric::kForceMedian:
    case ErrorMetric::kForceP95:
      return Quantity::kForce;
    case ErrorMetric::kModeAgreementMedian:
      return Quantity::kFraction;
  }
  return Quantity::kLength;
}

const char* SiUnit(ErrorMetric m) {
  switch (QuantityOf(m)) {
    case Quantity::kLength:
      return "m";
    case Quantity::kAngle:
      return "rad";
    case Quantity::kForce:
      return "N";
    case Quantity::kFraction:
      return "";
  }
  return "";
}

}  // namespace

const char* ToString(ErrorMetric metric) {
  for (const auto& [m, name] : kMetricNames) {
    if (m == metric) return name;
  }
  return "?";
}

bool LowerIsBetter(ErrorMetric metric) { return metric != ErrorMetric::kModeAgreementMedian; }

Budget ParseBudget(const std::string& text) {
  Budget b;
  std::string value = text;
  const auto eq = text.find('=');
  if (eq != std::string::npos) {
    const std::string name = text.substr(0, eq);
    bool found = false;
    for (const auto& [m, n] : kMetricNames) {
      if (name == n) {
        b.metric = m;
        found = true;
      }
    }
    if (!found) {
      std::string names;
      for (const auto& [m, n] : kMetricNames) names += std::string(names.empty() ? "" : ", ") + n;
      throw std::invalid_argument("budget '" + text + "': unknown metric '" + name + "' (one of " +
                                  names + ")");
    }
    value = text.substr(eq + 1);
  }
  std::size_t used = 0;
  double number = 0;
  try {
    number = std::stod(value, &used);
  } catch (const std::exception&) {
    throw std::invalid_argument("budget '" + text + "': '" + value +
                                "' is not a number with a unit");
  }
  const std::string unit = value.substr(used);
  struct UnitScale {
    const char* unit;
    Quantity quantity;
    double scale;
  };
  static const UnitScale kUnits[] = {
      {"m", Quantity::kLength, 1},      {"mm", Quantity::kLength, 1e-3},
      {"um", Quantity::kLength, 1e-6},  {"rad", Quantity::kAngle, 1},
      {"mrad", Quantity::kAngle, 1e-3}, {"deg", Quantity::kAngle, M_PI / 180},
      {"N", Quantity::kForce, 1},       {"mN", Quantity::kForce, 1e-3},
      {"%", Quantity::kFraction, 1e-2},
  };
  double scale = 1;
  if (!unit.empty()) {
    const UnitScale* u = nullptr;
    for (const auto& candidate : kUnits) {
      if (unit == candidate.unit) u = &candidate;
    }
    if (!u) throw std::invalid_argument("budget '" + text + "': unknown unit '" + unit + "'");
    if (u->quantity != QuantityOf(b.metric)) {
      throw std::invalid_argument("budget '" + text + "': unit '" + unit + "' does not fit " +
                                  ToString(b.metric));
    }
    scale = u->scale;
  }
  b.limit = number * scale;
  if (!std::isfinite(b.limit) || b.limit < 0) {
    throw std::invalid_argument("budget '" + text + "': must be a finite value >= 0");
  }
  if (QuantityOf(b.metric) == Quantity::kFraction && b.limit > 1) {
    throw std::invalid_argument("budget '" + text + "': a fraction must be <= 1 (or <= 100%)");
  }
  return b;
}

std::string FormatBudget(const Budget& b) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%s %s %g%s%s", ToString(b.metric),
                LowerIsBetter(b.metric) ? "<=" : ">=", b.limit, *SiUnit(b.metric) ? " " : "",
                SiUnit(b.metric));
  return buf;
}

// ------------------------------------------------------------ summary

std::optional<double> SettingSummary::Metric(ErrorMetric metric) const {
  auto pick = [](const std::optional<Distribution>& d, bool median) -> std::optional<double> {
    if (!d) return std::nullopt;
    return median ? d->median : d->p95;
  };
  switch (metric) {
    case ErrorMetric::kPositionMedian:
      return pick(position, true);
    case ErrorMetric::kPositionP95:
      return pick(position, false);
    case ErrorMetric::kAngleMedian:
      return pick(angle, true);
    case ErrorMetric::kAngleP95:
      return pick(angle, false);
    case ErrorMetric::kForceMedian:
      return pick(force, true);
    case ErrorMetric::kForceP95:
      return pick(force, false);
    case ErrorMetric::kModeAgreementMedian:
      return pick(mode_agreement, true);
  }
  return std::nullopt;
}

namespace {

std::optional<Distribution> Distribute(const std::vector<double>& v) {
  if (v.empty()) return std::nullopt;
  return Distribution{Percentile(v, 0.5), Percentile(v, 0.95)};
}

// Error oriented so that smaller is better.
double Cost(const SettingSummary& s, ErrorMetric m) {
  const double v = *s.Metric(m);
  return LowerIsBetter(m) ? v : -v;
}

}  // namespace

void MarkParetoFront(std::vector<SettingSummary>& settings, ErrorMetric primary) {
  for (auto& s : settings) s.pareto = false;
  for (auto& s : settings) {
    if (!s.eligible() || !s.Metric(primary)) continue;
    bool dominated = false;
    for (const auto& o : settings) {
      if (&o == &s || !o.eligible() || !o.Metric(primary)) continue;
      const double se = Cost(s, primary), oe = Cost(o, primary);
      const double st = s.time.median, ot = o.time.median;
      if (oe <= se && ot <= st && (oe < se || ot < st)) {
        dominated = true;
        break;
      }
    }
    s.pareto = !dominated;
  }
}

EvaluationReport Summarise(const std::vector<mechanics::ModelOptions>& models,
                           const std::vector<TrialEvaluation>& results,
                           const std::vector<Budget>& budgets) {
  EvaluationReport report;
  report.budgets = budgets;
  if (!budgets.empty()) report.primary = budgets.front().metric;
  struct Collect {
    std::vector<double> position, angle, force, mode, time;
  };
  std::vector<Collect> c(models.size());
  report.settings.resize(models.size());
  std::set<std::int64_t> trials;
  for (std::size_t i = 0; i < models.size(); ++i) {
    report.settings[i].model = models[i];
    report.settings[i].model_key = ModelKey(models[i]);
  }
  for (const auto& r : results) {
    if (r.setting >= models.size())
      throw std::invalid_argument("Summarise: setting index out of range");
    trials.insert(r.trial_id);
    auto& s = report.settings[r.setting];
    auto& col = c[r.setting];
    const auto& p = r.prediction;
    ++s.trials;
    col.time.push_back(p.wall_s);
    if (p.status == "ok" && p.final_position_error && p.final_angle_error && p.force_error &&
        p.mode_agreement) {
      ++s.ok;
      col.position.push_back(*p.final_position_error);
      col.angle.push_back(*p.final_angle_error);
      col.force.push_back(*p.force_error);
      col.mode.push_back(*p.mode_agreement);
    } else {
      ++s.failures;
    }
  }
  report.trials = static_cast<int>(trials.size());
  for (std::size_t i = 0; i < models.size(); ++i) {
    auto& s = report.settings[i];
    s.position = Distribute(c[i].position);
    s.angle = Distribute(c[i].angle);
    s.force = Distribute(c[i].force);
    s.mode_agreement = Distribute(c[i].mode);
    if (!c[i].time.empty()) s.time = *Distribute(c[i].time);
    s.within_budget =
        s.eligible() && std::all_of(budgets.begin(), budgets.end(), [&](const Budget& b) {
          const auto v = s.Metric(b.metric);
          return v && (LowerIsBetter(b.metric) ? *v <= b.limit : *v >= b.limit);
        });
  }
  MarkParetoFront(report.settings, report.primary);

  // Cheapest (median time) setting within budget; ties go to the smaller error.
  for (std::size_t i = 0; i < report.settings.size(); ++i) {
    const auto& s = report.settings[i];
    if (!s.within_budget) continue;
    if (!report.recommended) {
      report.recommended = i;
      continue;
    }
    const auto& best = report.settings[*report.recommended];
    if (s.time.median < best.time.median ||
        (s.time.median == best.time.median &&
         Cost(s, report.primary) < Cost(best, report.primary))) {
      report.recommended = i;
    }
  }
  std::string budget_text;
  for (const auto& b : budgets)
    budget_text += (budget_text.empty() ? "" : " and ") + FormatBudget(b);
  if (report.recommended) {
    const auto& s = report.settings[*report.recommended];
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s: the cheapest setting (median %.3g ms per trial) %s",
                  s.model_key.c_str(), s.time.median * 1e3,
                  budgets.empty() ? "that predicted every trial (no --budget given)"
                                  : ("within " + budget_text).c_str());
    report.recommendation = buf;
  } else if (report.trials == 0) {
    report.recommendation = "none: the campaign has no done trial to evaluate";
  } else if (std::none_of(report.settings.begin(), report.settings.end(),
                          [](const SettingSummary& s) { return s.eligible(); })) {
    report.recommendation = "none: every setting failed on some trial";
  } else {
    report.recommendation = "none: no setting that predicted every trial is within " + budget_text;
  }
  return report;
}

nlohmann::json ToJson(const EvaluationReport& r) {
  auto dist = [](const std::optional<Distribution>& d) -> nlohmann::json {
    if (!d) return nullptr;
    return {{"median", d->median}, {"p95", d->p95}};
  };
  nlohmann::json settings = nlohmann::json::array();
  for (const auto& s : r.settings) {
    settings.push_back(
        {{"model_key", s.model_key},
         {"facets", s.model.facets},
         {"points", s.model.points},
         {"dt", s.model.dt},
         {"reduce", mechanics::ToString(s.model.reduce)},
         {"trials", s.trials},
         {"ok", s.ok},
         {"failures", s.failures},
         {"position_error_m", dist(s.position)},
         {"angle_error_rad", dist(s.angle)},
         {"force_error_n", dist(s.force)},
         {"mode_agreement", dist(s.mode_agreement)},
         {"time_s", dist(s.time)},
         {"primary_error", s.Metric(r.primary) ? nlohmann::json(*s.Metric(r.primary)) : nullptr},
         {"pareto", s.pareto},
         {"within_budget", s.within_budget}});
  }
  nlohmann::json budgets = nlohmann::json::array();
  for (const auto& b : r.budgets) {
    budgets.push_back(
        {{"metric", ToString(b.metric)}, {"limit", b.limit}, {"text", FormatBudget(b)}});
  }
  nlohmann::json out = {{"campaign_id", r.campaign_id},
                        {"trials", r.trials},
                        {"primary_metric", ToString(r.primary)},
                        {"budgets", budgets},
                        {"settings", settings},
                        {"recommended", nullptr},
                        {"recommendation", r.recommendation}};
  if (r.recommended) out["recommended"] = r.settings[*r.recommended].model_key;
  return out;
}

// ------------------------------------------------------------ running

namespace {

struct LoadedTrial {
  std::int64_t id = -1;
  mechanics::Scene scene;
  std::vector<mechanics::TrajectorySample> truth;
  RecordedCommands commands;  // closed loop: replayed (issue 19); empty otherwise
  std::string error;          // non-empty: the trial could not be loaded
};

LoadedTrial LoadTrial(const db::Store& store, const db::Trial& t) {
  LoadedTrial out;
  out.id = t.id;
  try {
    out.scene = mechanics::ParseScene(t.scene_json);
    const auto normals = ContactNormals(out.scene);
    const db::GroundTruth gt = store.ReadGroundTruth(t.id);
    out.truth.reserve(gt.samples.size());
    for (const auto& s : gt.samples) {
      out.truth.push_back(ToTrajectorySample(s, normals, out.scene.pusher.has_value()));
    }
    if (auto run = store.GetClosedLoop(t.id)) out.commands = CommandsOf(*run);
  } catch (const std::exception& e) {
    out.error = e.what();
  }
  return out;
}

nlohmann::json ModelJson(const mechanics::ModelOptions& m) {
  return {{"facets", m.facets},
          {"points", m.points},
          {"dt", m.dt},
          {"reduce", mechanics::ToString(m.reduce)}};
}

}  // namespace

EvaluationRun EvaluateCampaign(db::Store& store, std::int64_t campaign_id,
                               const EvaluationOptions& options) {
  const auto models = ExpandGrid(options.grid);
  (void)store.GetCampaign(campaign_id);  // kNotFound for an unknown campaign
  std::vector<db::Trial> trials;
  for (auto& t : store.ListTrials(campaign_id)) {
    if (t.state == db::TrialState::kDone && t.gt_stream_id) trials.push_back(std::move(t));
  }
  const std::size_t total = trials.size() * models.size();
  std::vector<TrialEvaluation> results(total);
  std::atomic<std::size_t> next{0};
  std::atomic<long> done{0}, failed{0};
  std::mutex error_mutex;
  std::string worker_error;
  std::atomic<bool> worker_failed{false};

  int threads =
      options.threads > 0 ? options.threads : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::max(1, std::min<int>(threads, static_cast<int>(std::max<std::size_t>(total, 1))));

  // Jobs are trial-major, so a worker usually reuses the trial it loaded last.
  auto worker = [&]() {
    try {
      db::StoreOptions ro;
      ro.read_only = true;
      auto reader = db::Store::Open(store.path(), ro);
      LoadedTrial loaded;
      for (;;) {
        if (options.cancel && options.cancel->load()) return;
        const std::size_t job = next.fetch_add(1);
        if (job >= total) return;
        const auto& t = trials[job / models.size()];
        const std::size_t setting = job % models.size();
        if (loaded.id != t.id) loaded = LoadTrial(*reader, t);
        TrialEvaluation& r = results[job];
        r.trial_id = t.id;
        r.attempt = t.attempt;
        r.setting = setting;
        if (!loaded.error.empty()) {
          r.prediction = PredictionFailure("error", loaded.error);
        } else {
          try {
            mechanics::Scene scene = loaded.scene;
            scene.model = models[setting];
            mechanics::ValidateScene(scene);
            r.prediction = PredictTrial(scene, loaded.truth,
                                        loaded.commands.empty() ? nullptr : &loaded.commands);
          } catch (const std::exception& e) {
            r.prediction = PredictionFailure("invalid_scene", e.what());
          }
        }
        r.prediction.model_key = ModelKey(models[setting]);
        r.prediction.model_json = ModelJson(models[setting]).dump();
        if (r.prediction.status != "ok") failed.fetch_add(1);
        done.fetch_add(1);
      }
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (worker_error.empty()) worker_error = e.what();
      worker_failed.store(true);
      next.store(total);  // stop the others too
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
  run.report = Summarise(models, results, options.budgets);
  run.report.campaign_id = campaign_id;

  nlohmann::json grid = {{"facets", options.grid.facets},
                         {"points", options.grid.points},
                         {"dt", options.grid.dt},
                         {"reduce", nlohmann::json::array()},
                         {"budgets", nlohmann::json::array()},
                         {"threads", threads}};
  for (auto r : options.grid.reduce) grid["reduce"].push_back(mechanics::ToString(r));
  for (const auto& b : options.budgets) grid["budgets"].push_back(FormatBudget(b));
  std::vector<db::EvaluationResult> rows;
  rows.reserve(results.size());
  for (auto& r : results)
    rows.push_back(db::EvaluationResult{r.trial_id, r.attempt, std::move(r.prediction)});
  run.evaluation_id =
      store.RecordEvaluation(campaign_id, grid.dump(), ToJson(run.report).dump(), rows);
  return run;
}

}  // namespace arena::orchestrator
