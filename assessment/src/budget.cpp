// Percentiles, budgets and the default grid of `arena evaluate`.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <stdexcept>

#include "arena/assessment/evaluation.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace arena::assessment {

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
  nonempty_unique(g.contacts, "contacts");
  nonempty_unique(g.pads, "pads");
  nonempty_unique(g.cone, "cone");
  nonempty_unique(g.inertia, "inertia");
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
        for (auto r : g.reduce)
          for (auto c : g.contacts)
            for (auto pads : g.pads)
              for (auto cone : g.cone)
                for (auto inertia : g.inertia)
                  out.push_back(mechanics::ModelOptions{f, k, dt, r, c, pads, cone, inertia});
  return out;
}

std::vector<mechanics::ModelOptions> DefaultArenaGrid(const std::vector<mechanics::Scene>& scenes) {
  FidelityGrid grid;
  int points = grid.points.front();
  for (const auto& s : scenes) points = std::max(points, s.model.points);
  grid.points = {points};
  std::vector<mechanics::ModelOptions> out;
  std::string last_reason;
  for (const auto& m : ExpandGrid(grid)) {
    bool fits = true;
    for (const auto& scene : scenes) {
      mechanics::Scene s = scene;
      s.model = m;
      try {
        mechanics::ValidateScene(s);
      } catch (const std::exception& e) {
        last_reason = e.what();
        fits = false;
        break;
      }
    }
    if (fits) out.push_back(m);
  }
  if (out.empty()) {
    throw std::invalid_argument("no default arena setting fits every trial's scene (" +
                                last_reason + "); give --facets/--points/--dt");
  }
  return out;
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) throw std::invalid_argument("Percentile: no values");
  if (!(p >= 0 && p <= 1)) throw std::invalid_argument("Percentile: p must be in [0, 1]");
  std::sort(v.begin(), v.end());
  const double h = (static_cast<double>(v.size()) - 1) * p;
  const auto lo = static_cast<std::size_t>(std::floor(h));
  const std::size_t hi = std::min(lo + 1, v.size() - 1);
  if (std::isinf(v[lo]) || std::isinf(v[hi])) return v[h - lo > 0 ? hi : lo];
  return v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

namespace {

constexpr std::pair<ErrorMetric, const char*> kMetricNames[] = {
    {ErrorMetric::kPositionMedian, "position_median"},
    {ErrorMetric::kPositionP95, "position_p95"},
    {ErrorMetric::kAngleMedian, "angle_median"},
    {ErrorMetric::kAngleP95, "angle_p95"},
    {ErrorMetric::kForceMedian, "force_median"},
    {ErrorMetric::kForceP95, "force_p95"},
    {ErrorMetric::kModeAgreementMedian, "mode_agreement_median"},
    {ErrorMetric::kTimeP95, "time_p95"},
};

// What a budget's metric measures, for its unit (not outcome.hpp's Quantity).
enum class Dimension { kLength, kAngle, kForce, kFraction, kTime };

Dimension DimensionOf(ErrorMetric m) {
  switch (m) {
    case ErrorMetric::kPositionMedian:
    case ErrorMetric::kPositionP95:
      return Dimension::kLength;
    case ErrorMetric::kAngleMedian:
    case ErrorMetric::kAngleP95:
      return Dimension::kAngle;
    case ErrorMetric::kForceMedian:
    case ErrorMetric::kForceP95:
      return Dimension::kForce;
    case ErrorMetric::kModeAgreementMedian:
      return Dimension::kFraction;
    case ErrorMetric::kTimeP95:
      return Dimension::kTime;
  }
  return Dimension::kLength;
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
  bool named = false;
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
    named = true;
  }
  std::size_t used = 0;
  double number = 0;
  try {
    number = std::stod(value, &used);
  } catch (const std::exception&) {
    throw std::invalid_argument("budget '" + text + "': '" + value +
                                "' is not a number with a unit");
  }
  if (used > 0 && std::isspace(static_cast<unsigned char>(value[0]))) {
    throw std::invalid_argument("budget '" + text + "': no space before the number");
  }
  const std::string unit = value.substr(used);
  struct UnitScale {
    const char* unit;
    Dimension dimension;
    double scale;
  };
  static const UnitScale kUnits[] = {
      {"m", Dimension::kLength, 1},      {"mm", Dimension::kLength, 1e-3},
      {"um", Dimension::kLength, 1e-6},  {"rad", Dimension::kAngle, 1},
      {"mrad", Dimension::kAngle, 1e-3}, {"deg", Dimension::kAngle, M_PI / 180},
      {"N", Dimension::kForce, 1},       {"mN", Dimension::kForce, 1e-3},
      {"%", Dimension::kFraction, 1e-2}, {"s", Dimension::kTime, 1},
      {"ms", Dimension::kTime, 1e-3},    {"us", Dimension::kTime, 1e-6},
  };
  // The bare shorthand picks its metric from the unit: a time is time_p95,
  // anything else the p95 final position error.
  if (!named && (unit == "s" || unit == "ms" || unit == "us")) b.metric = ErrorMetric::kTimeP95;
  double scale = 1;
  if (unit == "floor") {
    const Dimension q = DimensionOf(b.metric);
    if (q != Dimension::kLength && q != Dimension::kAngle) {
      throw std::invalid_argument("budget '" + text + "': 'floor' fits position and angle only");
    }
    if (!std::isfinite(number) || number <= 0) {
      throw std::invalid_argument("budget '" + text + "': a floor multiple must be > 0");
    }
    b.floor_multiple = number;
    return b;
  }
  if (!unit.empty()) {
    const UnitScale* u = nullptr;
    for (const auto& candidate : kUnits) {
      if (unit == candidate.unit) u = &candidate;
    }
    if (!u) throw std::invalid_argument("budget '" + text + "': unknown unit '" + unit + "'");
    if (u->dimension != DimensionOf(b.metric)) {
      throw std::invalid_argument("budget '" + text + "': unit '" + unit + "' does not fit " +
                                  ToString(b.metric));
    }
    scale = u->scale;
  }
  b.limit = number * scale;
  if (!std::isfinite(b.limit) || b.limit < 0) {
    throw std::invalid_argument("budget '" + text + "': must be a finite value >= 0");
  }
  if (DimensionOf(b.metric) == Dimension::kFraction && b.limit > 1) {
    throw std::invalid_argument("budget '" + text + "': a fraction must be <= 1 (or <= 100%)");
  }
  return b;
}

// A limit in the unit a person reads it in (one unit per quantity in human
// output: mm, degrees, N, ms); JSON keeps the SI value beside this text.
std::string HumanLimit(ErrorMetric m, double v) {
  char buf[64];
  switch (DimensionOf(m)) {
    case Dimension::kLength:
      std::snprintf(buf, sizeof buf, "%g mm", v * 1e3);
      break;
    case Dimension::kAngle:
      std::snprintf(buf, sizeof buf, "%.4g deg", v * 180 / 3.14159265358979323846);
      break;
    case Dimension::kTime:
      std::snprintf(buf, sizeof buf, "%g ms", v * 1e3);
      break;
    case Dimension::kForce:
      std::snprintf(buf, sizeof buf, "%g N", v);
      break;
    case Dimension::kFraction:
      std::snprintf(buf, sizeof buf, "%g", v);
      break;
  }
  return buf;
}

std::string FormatBudget(const Budget& b) {
  const std::string name = ToString(b.metric);
  if (b.floor_multiple > 0) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", b.floor_multiple);
    return name + " <= " + buf + " x noise floor" +
           (b.limit > 0 ? " (" + HumanLimit(b.metric, b.limit) + ")" : "");
  }
  return name + (LowerIsBetter(b.metric) ? " <= " : " >= ") + HumanLimit(b.metric, b.limit);
}

}  // namespace arena::assessment
