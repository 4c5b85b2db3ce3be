// The adaptive samplers' decision rules: pure functions (adaptive.hpp).
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

#include "arena/orchestrator/adaptive.hpp"

namespace arena::orchestrator {
namespace {

double Distance(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0;
  for (size_t k = 0; k < a.size(); ++k) s += (a[k] - b[k]) * (a[k] - b[k]);
  return std::sqrt(s);
}

// Candidate lattice: `levels` per dimension, spacing 1 / (levels - 1).
std::vector<double> LatticePoint(std::int64_t index, int dims, int levels) {
  std::vector<double> u(static_cast<size_t>(dims));
  for (int d = 0; d < dims; ++d) {
    u[static_cast<size_t>(d)] =
        static_cast<double>(index % levels) / static_cast<double>(levels - 1);
    index /= levels;
  }
  return u;
}

// Standard normal quantile by bisection on erfc (monotone; 1e-12 is plenty).
double NormalQuantile(double p) {
  double lo = -40, hi = 40;
  for (int i = 0; i < 200 && hi - lo > 1e-12; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p)
      lo = mid;
    else
      hi = mid;
  }
  return 0.5 * (lo + hi);
}

// Student t quantile: exact for 1 and 2 degrees of freedom, Cornish-Fisher
// expansion (Abramowitz & Stegun 26.7.5) above; error < 1e-3 from 3 dof.
double StudentQuantile(double p, int dof) {
  if (dof == 1) return std::tan(M_PI * (p - 0.5));
  if (dof == 2) return (2 * p - 1) / std::sqrt(2 * p * (1 - p));
  const double z = NormalQuantile(p);
  const double v = dof;
  const double z3 = z * z * z, z5 = z3 * z * z, z7 = z5 * z * z, z9 = z7 * z * z;
  return z + (z3 + z) / (4 * v) + (5 * z5 + 16 * z3 + 3 * z) / (96 * v * v) +
         (3 * z7 + 19 * z5 + 17 * z3 - 15 * z) / (384 * v * v * v) +
         (79 * z9 + 776 * z7 + 1482 * z5 - 1920 * z3 - 945 * z) / (92160 * v * v * v * v);
}

}  // namespace

int DefaultCoarseLevels(int dims) { return dims <= 1 ? 5 : dims == 2 ? 4 : 3; }

int DefaultCoarseLevels(int dims, double resolution) {
  const int by_resolution = static_cast<int>(std::ceil(1.0 / (8.0 * resolution) - 1e-9)) + 1;
  return std::clamp(by_resolution, 3, std::max(3, DefaultCoarseLevels(dims)));
}

std::vector<std::vector<double>> CoarseGrid(int dims, int levels) {
  if (dims < 1 || levels < 2) throw std::invalid_argument("CoarseGrid: dims >= 1, levels >= 2");
  std::int64_t n = 1;
  for (int d = 0; d < dims; ++d) n *= levels;
  std::vector<std::vector<double>> out;
  for (std::int64_t i = 0; i < n; ++i) out.push_back(LatticePoint(i, dims, levels));
  return out;
}

std::vector<BoundaryProposal> ProposeBoundaryPoints(
    const std::vector<LabelledPoint>& labelled, const std::vector<std::vector<double>>& excluded,
    int dims, double resolution, int count, double* max_uncertainty) {
  if (max_uncertainty) *max_uncertainty = 0;
  std::vector<BoundaryProposal> out;
  const bool any_positive =
      std::any_of(labelled.begin(), labelled.end(), [](const auto& p) { return p.positive; });
  const bool any_negative =
      std::any_of(labelled.begin(), labelled.end(), [](const auto& p) { return !p.positive; });
  if (!any_positive || !any_negative) return out;

  // Lattice of spacing resolution / 2, at most ~300,000 candidates.
  int levels = static_cast<int>(std::ceil(2.0 / resolution)) + 1;
  const int max_levels =
      static_cast<int>(std::floor(std::pow(300000.0, 1.0 / static_cast<double>(dims))));
  levels = std::clamp(levels, 3, std::max(3, max_levels));
  const double h = 1.0 / static_cast<double>(levels - 1);
  std::int64_t n = 1;
  for (int d = 0; d < dims; ++d) n *= levels;

  struct Candidate {
    std::int64_t index;
    double d_pos, d_neg, score;
    std::int64_t near_pos, near_neg;
  };
  // 1-D: the labelled points in order; a candidate is uncertain when its
  // neighbours on either side disagree (a bracket), so a batch of b splits
  // the brackets (b = 1: bisection).
  std::vector<std::pair<double, const LabelledPoint*>> line;
  if (dims == 1) {
    for (const auto& p : labelled) line.emplace_back(p.u[0], &p);
    std::sort(line.begin(), line.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
  }
  std::vector<Candidate> on_boundary;
  for (std::int64_t i = 0; i < n; ++i) {
    const std::vector<double> u = LatticePoint(i, dims, levels);
    Candidate c{
        i, std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(), 0, 0,
        0};
    for (const auto& p : labelled) {
      const double d = Distance(u, p.u);
      if (p.positive && d < c.d_pos) {
        c.d_pos = d;
        c.near_pos = p.trial_id;
      } else if (!p.positive && d < c.d_neg) {
        c.d_neg = d;
        c.near_neg = p.trial_id;
      }
    }
    if (dims == 1) {
      const auto hi = std::upper_bound(line.begin(), line.end(), u[0],
                                       [](double x, const auto& e) { return x < e.first; });
      if (hi == line.begin() || hi == line.end()) continue;
      const auto lo = std::prev(hi);
      if (lo->second->positive == hi->second->positive) continue;  // not in a bracket
      c.near_pos = lo->second->positive ? lo->second->trial_id : hi->second->trial_id;
      c.near_neg = lo->second->positive ? hi->second->trial_id : lo->second->trial_id;
      c.score = std::min(u[0] - lo->first, hi->first - u[0]);
    } else {
      if (std::abs(c.d_pos - c.d_neg) > h) continue;  // not on the 1-NN decision boundary
      c.score = std::min(c.d_pos, c.d_neg);
    }
    for (const auto& e : excluded) c.score = std::min(c.score, Distance(u, e));
    on_boundary.push_back(c);
  }
  for (const auto& c : on_boundary)
    if (max_uncertainty) *max_uncertainty = std::max(*max_uncertainty, c.score);

  for (int pick = 0; pick < count; ++pick) {
    const Candidate* best = nullptr;
    for (const auto& c : on_boundary) {
      // Ties go to the lowest lattice index: deterministic.
      if (c.score > resolution && (!best || c.score > best->score)) best = &c;
    }
    if (!best) break;
    BoundaryProposal p;
    p.u = LatticePoint(best->index, dims, levels);
    p.uncertainty = best->score;
    p.near_positive = best->near_pos;
    p.near_negative = best->near_neg;
    for (auto& c : on_boundary)
      c.score = std::min(c.score, Distance(LatticePoint(c.index, dims, levels), p.u));
    out.push_back(std::move(p));
  }
  return out;
}

double ExpectedHalfWidth(const std::vector<double>& values, double confidence, int extra) {
  const size_t n = values.size();
  if (n < 2) return std::numeric_limits<double>::infinity();
  const double mean = std::accumulate(values.begin(), values.end(), 0.0) / static_cast<double>(n);
  double ss = 0;
  for (double v : values) ss += (v - mean) * (v - mean);
  const double sd = std::sqrt(ss / static_cast<double>(n - 1));
  const size_t m = n + static_cast<size_t>(std::max(extra, 0));
  const double t = StudentQuantile(0.5 + confidence / 2, static_cast<int>(m - 1));
  return t * sd / std::sqrt(static_cast<double>(m));
}

double ConfidenceHalfWidth(const std::vector<double>& values, double confidence) {
  return ExpectedHalfWidth(values, confidence, 0);
}

double PositionHalfWidth(const ConditionOutcomes& c, double confidence, int extra) {
  double worst = 0;
  for (size_t k = 0; k < 3; ++k) {
    std::vector<double> v;
    for (const auto& p : c.final_position) v.push_back(p[k]);
    worst = std::max(worst, ExpectedHalfWidth(v, confidence, extra));
  }
  return worst;
}

std::vector<ReplicateProposal> ProposeReplicates(const std::vector<ConditionOutcomes>& conditions,
                                                 const AdaptiveSpec& spec, int count) {
  struct Need {
    ReplicateProposal p;
    double ratio;  // how far above target (the largest of position and angle)
  };
  std::vector<Need> needs;
  for (const auto& c : conditions) {
    if (c.planned >= spec.max_replicates) continue;
    const double pos = PositionHalfWidth(c, spec.confidence);
    const double ang = ConfidenceHalfWidth(c.final_angle, spec.confidence);
    // Judged by what the pending replicates are expected to leave (the same
    // spread, more of them): a pipelined round does not pile replicates on
    // a condition that its running ones will probably bring on target.
    const double pos_expected = PositionHalfWidth(c, spec.confidence, c.pending);
    double ratio = pos_expected / spec.ci_position;
    if (spec.ci_angle > 0)
      ratio = std::max(
          ratio, ExpectedHalfWidth(c.final_angle, spec.confidence, c.pending) / spec.ci_angle);
    if (!(ratio > 1)) continue;  // on target (NaN cannot happen: outcomes are finite)
    needs.push_back({{c.condition, pos, ang, pos_expected}, ratio});
  }
  // Widest first; ties by condition index (deterministic).
  std::stable_sort(needs.begin(), needs.end(),
                   [](const Need& a, const Need& b) { return a.ratio > b.ratio; });
  std::vector<ReplicateProposal> out;
  for (const auto& n : needs) {
    if (static_cast<int>(out.size()) >= count) break;
    out.push_back(n.p);
  }
  return out;
}

}  // namespace arena::orchestrator
