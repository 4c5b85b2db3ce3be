#include "boundary_report.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include <nlohmann/json.hpp>

#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/outcome.hpp"

namespace arena::cli {

std::optional<BoundaryStatement> FindBoundary(const db::Store& store, std::int64_t campaign_id) {
  const db::Campaign stored = store.GetCampaign(campaign_id);
  orchestrator::Campaign c;
  try {
    c = orchestrator::ParseCampaign(stored.spec_json, "", orchestrator::ConditionCheck::kBaseScene);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  if (!c.adaptive || c.adaptive->kind != orchestrator::AdaptiveKind::kBoundary) return std::nullopt;
  BoundaryStatement b;
  b.outcome = orchestrator::ToString(c.adaptive->outcome);
  b.positive = orchestrator::ClassName(c.adaptive->outcome, true);
  b.negative = orchestrator::ClassName(c.adaptive->outcome, false);
  b.parameters = orchestrator::SampledVariations(c);
  std::vector<double> span;  // each parameter's range, to measure distance in unit steps
  for (const auto& name : b.parameters) {
    double s = 1;
    for (const auto& v : c.variations)
      if (v.name == name && v.max > v.min) s = v.max - v.min;
    span.push_back(s);
  }
  // Classified points: the trial's parameter values and its class.
  struct Point {
    std::vector<double> x;
    bool positive;
  };
  std::vector<Point> points;
  const auto outcomes = store.ReadTrialOutcomes(campaign_id);
  for (const auto& t : store.ListTrials(campaign_id)) {
    if (t.state != db::TrialState::kDone) continue;
    const auto it = outcomes.find(t.id);
    if (it == outcomes.end()) continue;
    const auto o = orchestrator::FromStoredOutcome(it->second);
    if (!o) continue;
    const auto params = nlohmann::json::parse(t.params_json, nullptr, false);
    Point p{{}, orchestrator::Classify(c.adaptive->outcome, c.adaptive->threshold, *o)};
    for (const auto& name : b.parameters) {
      if (!params.is_object() || !params.contains(name) || !params[name].is_number()) break;
      p.x.push_back(params[name].get<double>());
    }
    if (p.x.size() == b.parameters.size()) points.push_back(std::move(p));
  }
  b.classified = static_cast<int>(points.size());
  // Each point's nearest neighbour of the other class (in range units):
  // mutual pairs bracket the boundary.
  auto distance = [&](const Point& a, const Point& q) {
    double d = 0;
    for (size_t k = 0; k < a.x.size(); ++k) d += std::pow((a.x[k] - q.x[k]) / span[k], 2);
    return d;
  };
  auto nearest_other = [&](size_t i) {
    size_t best = points.size();
    double bd = std::numeric_limits<double>::infinity();
    for (size_t j = 0; j < points.size(); ++j) {
      if (points[j].positive == points[i].positive) continue;
      const double d = distance(points[i], points[j]);
      if (d < bd) {
        bd = d;
        best = j;
      }
    }
    return best;
  };
  std::map<std::vector<double>, BoundaryCrossing> crossings;  // sorted by midpoint
  for (size_t i = 0; i < points.size(); ++i) {
    const size_t j = nearest_other(i);
    if (j == points.size() || nearest_other(j) != i || i > j) continue;
    BoundaryCrossing x;
    for (size_t k = 0; k < b.parameters.size(); ++k) {
      x.at.push_back(0.5 * (points[i].x[k] + points[j].x[k]));
      x.half.push_back(0.5 * std::abs(points[i].x[k] - points[j].x[k]));
    }
    // Sorted by the other parameters first, so a 2-D boundary reads as a
    // curve: the first parameter's crossing at each value of the second.
    std::vector<double> key(x.at.rbegin(), x.at.rend());
    crossings[key] = std::move(x);
  }
  for (auto& [key, x] : crossings) b.crossings.push_back(std::move(x));
  return b;
}

std::string FormatBoundary(const BoundaryStatement& b, const std::string& indent) {
  std::string out = indent + "boundary between " + b.positive + " and " + b.negative + " (" +
                    std::to_string(b.classified) + " classified trials): ";
  if (b.crossings.empty()) {
    return out + "not bracketed yet (no neighbouring trials of different class)\n";
  }
  out += std::to_string(b.crossings.size()) + " bracketing pair" +
         (b.crossings.size() == 1 ? "" : "s") + ", midpoint +- half the bracket\n";
  constexpr size_t kShown = 12;
  for (size_t i = 0; i < b.crossings.size() && i < kShown; ++i) {
    const auto& x = b.crossings[i];
    out += indent + "  ";
    for (size_t k = 0; k < b.parameters.size(); ++k) {
      out += (k ? (k == 1 ? " at " : ", ") : "") + b.parameters[k] + " " +
             orchestrator::HumanVariationValue(b.parameters[k], x.at[k]);
      if (x.half[k] > 0) {
        std::string h = orchestrator::HumanVariationValue(b.parameters[k], x.half[k]);
        out += " +- " + h;
      }
    }
    out += "\n";
  }
  if (b.crossings.size() > kShown)
    out += indent + "  ... " + std::to_string(b.crossings.size() - kShown) + " more\n";
  return out;
}

}  // namespace arena::cli
