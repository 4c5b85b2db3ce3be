// Summarising an evaluation: tails, failures, floor multiples, the Pareto
// front, the recommendation and the report's JSON.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <set>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arena/assessment/evaluation.hpp"
#include "arena/assessment/prediction.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::assessment {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr std::size_t kWorstListed = 5;

std::optional<Distribution> Distribute(const std::vector<double>& v, bool low_tail = false) {
  if (v.empty()) return std::nullopt;
  if (low_tail) {
    return Distribution{Percentile(v, 0.5), Percentile(v, 0.05),
                        *std::min_element(v.begin(), v.end())};
  }
  return Distribution{Percentile(v, 0.5), Percentile(v, 0.95),
                      *std::max_element(v.begin(), v.end())};
}

double Median(const std::vector<double>& v) { return v.empty() ? 0 : Percentile(v, 0.5); }

// Error oriented so that smaller is better, failures as +inf.
double Cost(const SettingSummary& s, ErrorMetric m) {
  const double v = s.Judged(m);
  return LowerIsBetter(m) ? v : -v;
}

std::string Millimetres(double m) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g mm", m * 1e3);
  return buf;
}

}  // namespace

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
    case ErrorMetric::kTimeP95:
      return trials > 0 ? std::optional<double>(time.p95) : std::nullopt;
  }
  return std::nullopt;
}

double SettingSummary::Judged(ErrorMetric metric) const {
  if (metric == ErrorMetric::kPositionP95) return position_p95_all;
  if (metric == ErrorMetric::kAngleP95) return angle_p95_all;
  if (metric == ErrorMetric::kTimeP95) return trials > 0 ? time.p95 : kInf;
  const auto v = Metric(metric);
  if (!v || !eligible()) return LowerIsBetter(metric) ? kInf : -kInf;
  return *v;
}

std::vector<SettingInfo> ArenaSettings(const std::vector<mechanics::ModelOptions>& models) {
  const auto predictor = MakeArenaPredictor(models);
  std::vector<SettingInfo> out;
  for (std::size_t i = 0; i < models.size(); ++i) {
    out.push_back(SettingInfo{"arena", predictor->settings()[i], models[i]});
  }
  return out;
}

void MarkParetoFront(std::vector<SettingSummary>& settings, ErrorMetric primary) {
  for (auto& s : settings) s.pareto = false;
  for (auto& s : settings) {
    if (!s.eligible() || !std::isfinite(Cost(s, primary))) continue;
    bool dominated = false;
    for (const auto& o : settings) {
      if (&o == &s || !o.eligible() || !std::isfinite(Cost(o, primary))) continue;
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

namespace {

struct Collect {
  std::vector<double> position, angle, force, mode, time, per_sim_s;
  std::vector<double> position_all, angle_all;  // failures as +inf
  std::vector<std::pair<double, std::int64_t>> by_error;
  std::vector<std::pair<double, double>> duration_error;       // ok trials
  std::vector<PlanarOutcome> outcome_predicted, outcome_true;  // ok trials with an outcome
};

// The outcomes ScoreSimulation put in a prediction's detail, if any.
bool ReadOutcomes(const std::string& detail_json, PlanarOutcome* predicted, PlanarOutcome* truth) {
  const auto d = nlohmann::json::parse(detail_json, nullptr, false);
  if (d.is_discarded() || !d.is_object() || !d.contains("outcome")) return false;
  const auto& o = d["outcome"];
  auto read = [](const nlohmann::json& a, PlanarOutcome* out) {
    if (!a.is_array() || a.size() != 3) return false;
    for (const auto& v : a)
      if (!v.is_number()) return false;
    *out = PlanarOutcome{a[0].get<double>(), a[1].get<double>(), a[2].get<double>()};
    return true;
  };
  return o.is_object() && o.contains("true") && o.contains("predicted") &&
         read(o["predicted"], predicted) && read(o["true"], truth);
}

void Add(SettingSummary& s, Collect& c, const TrialEvaluation& r) {
  const auto& p = r.prediction;
  ++s.trials;
  c.time.push_back(p.wall_s);
  if (r.truth_duration_s > 0) c.per_sim_s.push_back(p.wall_s / r.truth_duration_s);
  const db::PredictionStatus outcome = p.status;
  // A measured truth whose force stream failed its import check has no
  // contact forces: the poses are scored, the forces and modes are not.
  const bool scored = p.final_position_error && p.final_angle_error;
  std::string reason;
  if (outcome != db::PredictionStatus::kOk || !scored) {
    try {
      reason = nlohmann::json::parse(p.detail_json).value("error", "");
    } catch (const std::exception&) {
    }
    if (reason.empty()) reason = db::ToString(p.status);
  }
  if (outcome == db::PredictionStatus::kOk && scored) {
    ++s.ok;
    c.position.push_back(*p.final_position_error);
    c.angle.push_back(*p.final_angle_error);
    if (p.force_error) {
      c.force.push_back(*p.force_error);
      ++s.force_trials;
    }
    if (p.mode_agreement) c.mode.push_back(*p.mode_agreement);
    if (mechanics::HasRunFlag(p.detail_json, "steered_slip")) ++s.steered;
    if (mechanics::HasRunFlag(p.detail_json, "oscillation")) ++s.oscillating;
    c.position_all.push_back(*p.final_position_error);
    c.angle_all.push_back(*p.final_angle_error);
    c.by_error.emplace_back(*p.final_position_error, r.trial_id);
    PlanarOutcome predicted, truth;
    if (ReadOutcomes(p.detail_json, &predicted, &truth)) {
      c.outcome_predicted.push_back(predicted);
      c.outcome_true.push_back(truth);
    }
    if (r.truth_duration_s > 0)
      c.duration_error.emplace_back(r.truth_duration_s, *p.final_position_error);
  } else if (outcome == db::PredictionStatus::kDiverged) {
    ++s.diverged;
    s.diverged_trials.push_back(TrialNote{r.trial_id, 0, reason});
    c.position_all.push_back(kInf);
    c.angle_all.push_back(kInf);
  } else {
    ++s.failures;
    s.failed_trials.push_back(
        TrialNote{r.trial_id, 0, std::string(db::ToString(p.status)) + ": " + reason});
    c.position_all.push_back(kInf);
    c.angle_all.push_back(kInf);
  }
}

// Error against ground-truth duration: one point per distinct duration, or
// per eighth of the trials (by duration) when there are more than 8.
std::vector<DurationPoint> DurationPoints(std::vector<std::pair<double, double>> de) {
  std::vector<DurationPoint> out;
  if (de.empty()) return out;
  std::sort(de.begin(), de.end());
  std::vector<std::vector<std::pair<double, double>>> bins;
  std::set<double> distinct;
  for (const auto& [d, e] : de) distinct.insert(std::round(d * 1e6) / 1e6);
  if (distinct.size() <= 8) {
    std::map<double, std::vector<std::pair<double, double>>> by;
    for (const auto& x : de) by[std::round(x.first * 1e6) / 1e6].push_back(x);
    for (auto& [d, v] : by) bins.push_back(std::move(v));
  } else {
    const std::size_t n = de.size();
    for (std::size_t b = 0; b < 8; ++b) {
      const std::size_t lo = b * n / 8, hi = (b + 1) * n / 8;
      if (hi > lo) bins.emplace_back(de.begin() + lo, de.begin() + hi);
    }
  }
  for (const auto& bin : bins) {
    std::vector<double> d, e;
    for (const auto& [x, y] : bin) {
      d.push_back(x);
      e.push_back(y);
    }
    out.push_back(
        DurationPoint{Median(d), static_cast<int>(bin.size()), Median(e), Percentile(e, 0.95)});
  }
  return out;
}

void Recommend(EvaluationReport& report, const std::vector<Budget>& budgets) {
  const bool error_budget = std::any_of(budgets.begin(), budgets.end(), [](const Budget& b) {
    return b.metric != ErrorMetric::kTimeP95;
  });
  // With an error budget: the cheapest (median time) meeting every budget.
  // With only time budgets: the most accurate (primary) meeting them.
  for (std::size_t i = 0; i < report.settings.size(); ++i) {
    const auto& s = report.settings[i];
    if (!s.within_budget) continue;
    if (!report.recommended) {
      report.recommended = i;
      continue;
    }
    const auto& best = report.settings[*report.recommended];
    const double se = Cost(s, report.primary), be = Cost(best, report.primary);
    const bool better = error_budget ? (s.time.median < best.time.median ||
                                        (s.time.median == best.time.median && se < be))
                                     : (se < be || (se == be && s.time.median < best.time.median));
    if (better) report.recommended = i;
  }
  std::string budget_text;
  for (const auto& b : budgets)
    budget_text += (budget_text.empty() ? "" : " and ") + FormatBudget(b);
  if (report.recommended) {
    const auto& s = report.settings[*report.recommended];
    char buf[512];
    std::snprintf(
        buf, sizeof buf,
        "%s %s: the %s setting within %s (median %.3g ms per trial, p95 %.3g ms; final "
        "position error median %s, p95 %s%s)",
        s.predictor.c_str(), s.model_key.c_str(), error_budget ? "cheapest" : "most accurate",
        budget_text.c_str(), s.time.median * 1e3, s.time.p95 * 1e3,
        s.position ? Millimetres(s.position->median).c_str() : "-",
        s.position ? Millimetres(s.position->p95).c_str() : "-",
        report.floor && report.floor->position_median > 0 && s.position
            ? (", " + std::to_string(s.position->p95 / report.floor->position_median).substr(0, 4) +
               "x the noise floor")
                  .c_str()
            : "");
    report.recommendation = buf;
  } else if (report.trials == 0) {
    report.recommendation = "none: the campaign has no done trial to evaluate";
  } else if (budgets.empty()) {
    report.recommendation = "none asked (no --budget): see the front";
  } else if (std::none_of(report.settings.begin(), report.settings.end(),
                          [](const SettingSummary& s) { return s.eligible(); })) {
    report.recommendation = "none: every setting diverged or failed on some trial";
  } else {
    report.recommendation = "none: no setting is within " + budget_text + " on its p95";
  }
}

// What the front looks like, cheapest first: each point's time, error and
// floor multiple, and where more time stops buying accuracy.
std::string DescribeFront(const EvaluationReport& r) {
  std::vector<const SettingSummary*> front;
  for (const auto& s : r.settings) {
    if (s.pareto) front.push_back(&s);
  }
  if (front.empty()) return "no setting predicted every trial, so there is no front";
  std::sort(front.begin(), front.end(),
            [](const auto* a, const auto* b) { return a->time.median < b->time.median; });
  std::string out = std::to_string(front.size()) + " setting(s) on the front of " +
                    ToString(r.primary) + " against median time:";
  for (const auto* s : front) {
    char buf[256];
    const double e = s->Judged(r.primary);
    // The table's units: mm and degrees, never metres beside millimetres.
    const bool angle =
        r.primary == ErrorMetric::kAngleMedian || r.primary == ErrorMetric::kAngleP95;
    const bool fraction = r.primary == ErrorMetric::kModeAgreementMedian;
    const bool force =
        r.primary == ErrorMetric::kForceMedian || r.primary == ErrorMetric::kForceP95;
    const bool time = r.primary == ErrorMetric::kTimeP95;
    std::snprintf(buf, sizeof buf, " %s %s %.3g ms -> %.4g%s", s->predictor.c_str(),
                  s->model_key.c_str(), s->time.median * 1e3,
                  fraction || force ? e
                  : angle           ? e * 180 / M_PI
                                    : e * 1e3,
                  fraction ? ""
                  : force  ? " N"
                  : angle  ? " deg"
                  : time   ? " ms"
                           : " mm");
    out += buf;
    if (r.floor && r.floor->position_median > 0 &&
        (r.primary == ErrorMetric::kPositionMedian || r.primary == ErrorMetric::kPositionP95)) {
      std::snprintf(buf, sizeof buf, " (%.2gx floor)", e / r.floor->position_median);
      out += buf;
    }
    out += ";";
  }
  const auto* cheapest = front.front();
  const auto* best = front.back();
  char buf[256];
  std::snprintf(buf, sizeof buf,
                " from the cheapest to the most accurate, %.3gx the time buys %.3gx less error",
                best->time.median / std::max(cheapest->time.median, 1e-12),
                cheapest->Judged(r.primary) / std::max(best->Judged(r.primary), 1e-300));
  out += buf;
  if (r.floor && r.floor->position_median > 0 &&
      (r.primary == ErrorMetric::kPositionMedian || r.primary == ErrorMetric::kPositionP95)) {
    out += best->Judged(r.primary) <= 1.5 * r.floor->position_median
               ? "; the most accurate is within 1.5x the noise floor, so further fidelity "
                 "cannot be told apart from replicate spread"
               : "; even the most accurate is above 1.5x the noise floor: the model, not the "
                 "discretisation, limits accuracy (see the convergence table)";
  }
  return out;
}

}  // namespace

EvaluationReport Summarise(const std::vector<SettingInfo>& infos,
                           const std::vector<TrialEvaluation>& results,
                           const std::vector<Budget>& budgets_in,
                           const std::optional<NoiseFloor>& floor) {
  EvaluationReport report;
  report.floor = floor;
  std::vector<Budget> budgets = budgets_in;
  for (auto& b : budgets) {
    if (b.floor_multiple > 0) {
      const bool angle =
          b.metric == ErrorMetric::kAngleMedian || b.metric == ErrorMetric::kAngleP95;
      b.limit = floor ? b.floor_multiple * (angle ? floor->angle_median : floor->position_median)
                      : -1;  // no floor: nothing can meet it
    }
  }
  report.budgets = budgets;
  const auto first_error = std::find_if(budgets.begin(), budgets.end(), [](const Budget& b) {
    return b.metric != ErrorMetric::kTimeP95;
  });
  if (first_error != budgets.end()) report.primary = first_error->metric;
  std::vector<Collect> c(infos.size());
  report.settings.resize(infos.size());
  std::set<std::int64_t> trials;
  std::map<std::string, std::pair<int, std::size_t>> finest;  // predictor -> (refinement, index)
  for (std::size_t i = 0; i < infos.size(); ++i) {
    auto& s = report.settings[i];
    s.predictor = infos[i].predictor;
    s.model_key = infos[i].setting.key;
    s.knobs_json = infos[i].setting.knobs_json;
    s.model = infos[i].model;
    s.step = infos[i].setting.step;
    if (std::find(report.predictors.begin(), report.predictors.end(), s.predictor) ==
        report.predictors.end()) {
      report.predictors.push_back(s.predictor);
    }
    auto it = finest.find(s.predictor);
    if (it == finest.end() || infos[i].setting.refinement > it->second.first) {
      finest[s.predictor] = {infos[i].setting.refinement, i};
    }
  }
  for (const auto& [name, f] : finest) report.settings[f.second].finest = true;
  for (const auto& r : results) {
    if (r.setting >= infos.size())
      throw std::invalid_argument("Summarise: setting index out of range");
    trials.insert(r.trial_id);
    Add(report.settings[r.setting], c[r.setting], r);
  }
  report.trials = static_cast<int>(trials.size());
  for (std::size_t i = 0; i < infos.size(); ++i) {
    auto& s = report.settings[i];
    s.position = Distribute(c[i].position);
    s.angle = Distribute(c[i].angle);
    s.force = Distribute(c[i].force);
    s.mode_agreement = Distribute(c[i].mode, /*low_tail=*/true);
    if (!c[i].time.empty()) s.time = *Distribute(c[i].time);
    s.time_per_sim_s = Distribute(c[i].per_sim_s);
    s.position_p95_all = c[i].position_all.empty() ? kInf : Percentile(c[i].position_all, 0.95);
    s.angle_p95_all = c[i].angle_all.empty() ? kInf : Percentile(c[i].angle_all, 0.95);
    if (c[i].outcome_true.size() < static_cast<std::size_t>(s.ok)) {
      s.nmse_note = "predictions stored without their outcome";
    } else {
      s.nmse = ComputeNmse(c[i].outcome_predicted, c[i].outcome_true, &s.nmse_note);
    }
    auto& by = c[i].by_error;
    std::sort(by.begin(), by.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    for (std::size_t k = 0; k < std::min(kWorstListed, by.size()); ++k) {
      s.worst.push_back(TrialNote{by[k].second, by[k].first, ""});
    }
    s.within_budget = s.trials > 0 && !budgets.empty() &&
                      std::all_of(budgets.begin(), budgets.end(), [&](const Budget& b) {
                        if (b.limit < 0) return false;
                        const double v = s.Judged(b.metric);
                        return LowerIsBetter(b.metric) ? v <= b.limit : v >= b.limit;
                      });
  }
  MarkParetoFront(report.settings, report.primary);
  Recommend(report, budgets);
  report.front = DescribeFront(report);

  // Error against duration per predictor, at its most accurate setting that
  // predicted every trial (else its finest).
  for (const auto& name : report.predictors) {
    std::optional<std::size_t> pick;
    for (std::size_t i = 0; i < report.settings.size(); ++i) {
      const auto& s = report.settings[i];
      if (s.predictor != name || !s.eligible()) continue;
      if (!pick || s.position_p95_all < report.settings[*pick].position_p95_all) pick = i;
    }
    if (!pick) pick = finest[name].second;
    DurationCurve curve{name, report.settings[*pick].model_key,
                        DurationPoints(c[*pick].duration_error)};
    report.duration_curves.push_back(std::move(curve));
  }
  return report;
}

std::vector<GroupReport> SummariseGroups(
    const std::vector<SettingInfo>& settings, const std::vector<TrialEvaluation>& results,
    const std::map<std::int64_t, std::string>& group_of_trial) {
  std::map<std::string, std::vector<TrialEvaluation>> by;
  for (const auto& r : results) {
    const auto it = group_of_trial.find(r.trial_id);
    if (it == group_of_trial.end())
      throw std::invalid_argument("SummariseGroups: trial " + std::to_string(r.trial_id) +
                                  " has no group");
    by[it->second].push_back(r);
  }
  std::vector<GroupReport> out;
  for (const auto& [value, rs] : by) {
    const EvaluationReport g = Summarise(settings, rs, {});
    out.push_back(GroupReport{value, g.trials, g.settings});
  }
  return out;
}

namespace {

nlohmann::json Nmse(const SettingSummary& s) {
  if (!s.nmse) return {{"value", nullptr}, {"note", s.nmse_note}};
  return {{"value", s.nmse->mean},
          {"dx", s.nmse->dx},
          {"dy", s.nmse->dy},
          {"dtheta", s.nmse->dtheta},
          {"trials", s.nmse->trials}};
}

nlohmann::json Dist(const std::optional<Distribution>& d) {
  if (!d) return nullptr;
  return {{"median", d->median}, {"p95", d->p95}, {"max", d->max}};
}

nlohmann::json Notes(const std::vector<TrialNote>& notes, bool with_value) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& n : notes) {
    nlohmann::json j = {{"trial_id", n.trial_id}};
    if (with_value) j["position_error_m"] = n.value;
    if (!n.reason.empty()) j["reason"] = n.reason;
    out.push_back(j);
  }
  return out;
}

nlohmann::json Finite(double v) { return std::isfinite(v) ? nlohmann::json(v) : nullptr; }

nlohmann::json Multiple(const std::optional<Distribution>& d, double floor) {
  if (!d || !(floor > 0)) return nullptr;
  return {{"median", d->median / floor}, {"p95", d->p95 / floor}, {"max", d->max / floor}};
}

// A setting's counts and error figures: the whole of a group's row, and the
// part of a report's setting row the two share.
nlohmann::json SettingErrorsJson(const SettingSummary& s) {
  return {{"predictor", s.predictor},
          {"model_key", s.model_key},
          {"trials", s.trials},
          {"ok", s.ok},
          {"diverged", s.diverged},
          {"failures", s.failures},
          {"position_error_m", Dist(s.position)},
          {"angle_error_rad", Dist(s.angle)},
          {"force_error_n", Dist(s.force)},
          {"force_trials", s.force_trials},
          {"time_s", Dist(std::optional<Distribution>(s.time))},
          {"outcome_nmse", Nmse(s)}};
}

// The SI unit of a metric's value.
const char* SiUnit(ErrorMetric m) {
  switch (m) {
    case ErrorMetric::kAngleMedian:
    case ErrorMetric::kAngleP95:
      return "rad";
    case ErrorMetric::kForceMedian:
    case ErrorMetric::kForceP95:
      return "N";
    case ErrorMetric::kModeAgreementMedian:
      return "1";
    case ErrorMetric::kTimeP95:
      return "s";
    default:
      return "m";
  }
}

// The front's points, cheapest first, in SI: what `front` says in prose.
nlohmann::json FrontPoints(const EvaluationReport& r) {
  std::vector<std::size_t> front;
  for (std::size_t i = 0; i < r.settings.size(); ++i)
    if (r.settings[i].pareto) front.push_back(i);
  std::stable_sort(front.begin(), front.end(), [&](std::size_t a, std::size_t b) {
    return r.settings[a].time.median < r.settings[b].time.median;
  });
  const bool position =
      r.primary == ErrorMetric::kPositionMedian || r.primary == ErrorMetric::kPositionP95;
  nlohmann::json points = nlohmann::json::array();
  for (const std::size_t i : front) {
    const SettingSummary& s = r.settings[i];
    const double e = s.Judged(r.primary);
    points.push_back({{"setting", i},
                      {"predictor", s.predictor},
                      {"model_key", s.model_key},
                      {"time_median_s", s.time.median},
                      {"metric", ToString(r.primary)},
                      {"error", Finite(e)},
                      {"error_unit", SiUnit(r.primary)},
                      {"floor_multiple", position && r.floor && r.floor->position_median > 0
                                             ? Finite(e / r.floor->position_median)
                                             : nlohmann::json(nullptr)},
                      {"recommended", r.recommended && *r.recommended == i}});
  }
  return points;
}

}  // namespace

nlohmann::json ToJson(const EvaluationReport& r) {
  const double pos_floor = r.floor ? r.floor->position_median : 0;
  const double ang_floor = r.floor ? r.floor->angle_median : 0;
  nlohmann::json settings = nlohmann::json::array();
  for (const auto& s : r.settings) {
    nlohmann::json j = SettingErrorsJson(s);
    j.update(
        {{"knobs", nlohmann::json::parse(s.knobs_json, nullptr, false)},
         {"step_s", s.step},
         {"finest", s.finest},
         {"mode_agreement", Dist(s.mode_agreement)},
         {"position_floor_multiple", Multiple(s.position, pos_floor)},
         {"angle_floor_multiple", Multiple(s.angle, ang_floor)},
         {"time_per_simulated_s", Dist(s.time_per_sim_s)},
         {"primary_error", s.Metric(r.primary) ? nlohmann::json(*s.Metric(r.primary)) : nullptr},
         {"position_p95_all_trials_m", Finite(s.position_p95_all)},
         {"worst_trials", Notes(s.worst, true)},
         {"diverged_trials", Notes(s.diverged_trials, false)},
         {"failed_trials", Notes(s.failed_trials, false)},
         {"steered_slip_trials", s.steered},
         {"oscillating_trials", s.oscillating},
         {"convergence", nullptr},
         {"pareto", s.pareto},
         {"within_budget", s.within_budget}});
    if (j["knobs"].is_discarded()) j["knobs"] = nlohmann::json::object();
    if (s.model) {
      j["facets"] = s.model->facets;
      j["points"] = s.model->points;
      j["dt"] = s.model->dt;
      j["reduce"] = mechanics::ToString(s.model->reduce);
    }
    if (s.convergence) {
      j["convergence"] = {{"pieces", s.convergence->pieces},
                          {"position_m", Dist(s.convergence->position)},
                          {"angle_rad", Dist(s.convergence->angle)}};
    }
    settings.push_back(std::move(j));
  }
  nlohmann::json budgets = nlohmann::json::array();
  for (const auto& b : r.budgets) {
    budgets.push_back(
        {{"metric", ToString(b.metric)},
         {"limit", b.limit >= 0 ? nlohmann::json(b.limit) : nullptr},
         {"floor_multiple", b.floor_multiple > 0 ? nlohmann::json(b.floor_multiple) : nullptr},
         {"text", FormatBudget(b)}});
  }
  nlohmann::json floor = nullptr;
  if (r.floor) {
    floor = {{"conditions", r.floor->conditions},
             {"trials", r.floor->trials},
             {"position_m", {{"median", r.floor->position_median}, {"p95", r.floor->position_p95}}},
             {"angle_rad", {{"median", r.floor->angle_median}, {"p95", r.floor->angle_p95}}}};
  }
  nlohmann::json curves = nlohmann::json::array();
  for (const auto& c : r.duration_curves) {
    nlohmann::json points = nlohmann::json::array();
    for (const auto& p : c.points) {
      points.push_back(
          {{"duration_s", p.duration_s},
           {"trials", p.trials},
           {"position_error_m", {{"median", p.position_median}, {"p95", p.position_p95}}}});
    }
    curves.push_back({{"predictor", c.predictor}, {"model_key", c.model_key}, {"points", points}});
  }
  nlohmann::json out = {{"campaign_id", r.campaign_id},
                        {"trials", r.trials},
                        {"truth",
                         {{"source", r.truth.source},
                          {"independent", r.truth.independent},
                          {"statement", r.truth.statement}}},
                        {"noise_floor", floor},
                        {"predictors", r.predictors},
                        {"primary_metric", ToString(r.primary)},
                        {"budgets", budgets},
                        {"settings", settings},
                        {"duration_curves", curves},
                        {"recommended", nullptr},
                        {"recommended_predictor", nullptr},
                        {"recommendation", r.recommendation},
                        {"front", r.front},
                        {"front_points", FrontPoints(r)}};
  out["scales"] = r.scales;
  if (!r.group_by.empty()) {
    nlohmann::json groups = nlohmann::json::array();
    for (const auto& g : r.groups) {
      nlohmann::json gs = nlohmann::json::array();
      for (const auto& s : g.settings) {
        gs.push_back(SettingErrorsJson(s));
      }
      groups.push_back({{"value", g.value}, {"trials", g.trials}, {"settings", gs}});
    }
    out["group_by"] = r.group_by;
    out["groups"] = groups;
  }
  if (r.recommended) {
    out["recommended"] = r.settings[*r.recommended].model_key;
    out["recommended_predictor"] = r.settings[*r.recommended].predictor;
  }
  return out;
}

}  // namespace arena::assessment
