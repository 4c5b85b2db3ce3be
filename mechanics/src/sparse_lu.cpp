#include "sparse_lu.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

namespace arena::mechanics {
namespace {

// A plan pivots on entries at least this fraction of their column's largest
// (threshold partial pivoting: stability traded for less fill); a replay
// accepts a pivot down to the smaller fraction before it plans again.
constexpr double kPlanThreshold = 0.1;
constexpr double kReplayThreshold = 1e-2;

constexpr std::uint64_t Bit(int i) { return std::uint64_t{1} << i; }
constexpr std::uint64_t Low(int n) {
  return n >= SmallSparseLu::kMaxSize ? ~std::uint64_t{0} : Bit(n) - 1;
}

}  // namespace

void SmallSparseLu::Clear(int n) {
  // Rows past the larger of the two sizes are zero already.
  std::fill(bits_.begin(), bits_.begin() + std::clamp(std::max(n_, n), 0, kMaxSize), 0);
  n_ = n;
  entries_.clear();
  active_ = nullptr;
}

bool SmallSparseLu::BuildPlan(Plan& plan) const {
  const int n = n_;
  std::vector<double> V(static_cast<size_t>(n) * n, 0.0);
  for (const Entry& e : entries_) V[static_cast<size_t>(e.row) * n + e.col] += e.value;
  Pattern S = bits_;
  std::uint64_t rows_left = Low(n), cols_left = Low(n);
  plan.n = 0;
  plan.pattern = bits_;
  plan.steps.clear();
  plan.rows.clear();
  plan.cols.clear();
  plan.filled.clear();
  auto at = [&](int r, int c) -> double& { return V[static_cast<size_t>(r) * n + c]; };
  for (int step = 0; step < n; ++step) {
    int best_r = -1, best_c = -1;
    long best_cost = std::numeric_limits<long>::max();
    double best_ratio = 0;
    for (std::uint64_t cs = cols_left; cs != 0; cs &= cs - 1) {
      const int c = std::countr_zero(cs);
      double colmax = 0;
      int col_count = 0;
      for (std::uint64_t rs = rows_left; rs != 0; rs &= rs - 1) {
        const int r = std::countr_zero(rs);
        if (!(S[static_cast<size_t>(r)] & Bit(c))) continue;
        ++col_count;
        colmax = std::max(colmax, std::abs(at(r, c)));
      }
      if (!(colmax > 0) || !std::isfinite(colmax)) continue;
      for (std::uint64_t rs = rows_left; rs != 0; rs &= rs - 1) {
        const int r = std::countr_zero(rs);
        if (!(S[static_cast<size_t>(r)] & Bit(c))) continue;
        const double ratio = std::abs(at(r, c)) / colmax;
        if (ratio < kPlanThreshold) continue;
        const long row_count = std::popcount(S[static_cast<size_t>(r)] & cols_left);
        const long cost = (row_count - 1) * (col_count - 1);
        if (cost < best_cost || (cost == best_cost && ratio > best_ratio)) {
          best_cost = cost;
          best_ratio = ratio;
          best_r = r;
          best_c = c;
        }
      }
    }
    if (best_r < 0) return false;  // no usable pivot: singular
    Elimination el;
    el.row = best_r;
    el.col = best_c;
    rows_left &= ~Bit(el.row);
    cols_left &= ~Bit(el.col);
    el.r0 = static_cast<int>(plan.rows.size());
    for (std::uint64_t rs = rows_left; rs != 0; rs &= rs - 1) {
      const int r = std::countr_zero(rs);
      if (S[static_cast<size_t>(r)] & Bit(el.col)) plan.rows.push_back(r);
    }
    el.r1 = static_cast<int>(plan.rows.size());
    const std::uint64_t pivot_cols = S[static_cast<size_t>(el.row)] & cols_left;
    el.c0 = static_cast<int>(plan.cols.size());
    for (std::uint64_t cs = pivot_cols; cs != 0; cs &= cs - 1)
      plan.cols.push_back(std::countr_zero(cs));
    el.c1 = static_cast<int>(plan.cols.size());
    const double p = at(el.row, el.col);
    for (int k = el.r0; k < el.r1; ++k) {
      const int r = plan.rows[static_cast<size_t>(k)];
      const double f = at(r, el.col) / p;
      S[static_cast<size_t>(r)] |= pivot_cols;  // fill
      for (std::uint64_t cs = pivot_cols; cs != 0; cs &= cs - 1) {
        const int c = std::countr_zero(cs);
        at(r, c) -= f * at(el.row, c);
      }
    }
    plan.steps.push_back(el);
  }
  for (int r = 0; r < n; ++r) {
    for (std::uint64_t cs = S[static_cast<size_t>(r)]; cs != 0; cs &= cs - 1)
      plan.filled.push_back(r * kMaxSize + std::countr_zero(cs));
  }
  plan.n = n;
  return true;
}

bool SmallSparseLu::Replay(const Plan& plan) {
  double* a = a_.data();
  for (const int pos : plan.filled) a[pos] = 0.0;
  for (const Entry& e : entries_) a[e.row * kMaxSize + e.col] += e.value;
  const int* rows = plan.rows.data();
  const int* cols = plan.cols.data();
  for (const Elimination& el : plan.steps) {
    const double* prow = a + el.row * kMaxSize;
    const double p = prow[el.col];
    double colmax = 0;
    for (int k = el.r0; k < el.r1; ++k)
      colmax = std::max(colmax, std::abs(a[rows[k] * kMaxSize + el.col]));
    if (!std::isfinite(p) || !(std::abs(p) > 0) || std::abs(p) < kReplayThreshold * colmax)
      return false;
    for (int k = el.r0; k < el.r1; ++k) {
      double* row = a + rows[k] * kMaxSize;
      const double f = row[el.col] / p;
      row[el.col] = f;  // L, kept where the eliminated entry was
      if (f == 0) continue;
      for (int j = el.c0; j < el.c1; ++j) row[cols[j]] -= f * prow[cols[j]];
    }
  }
  return true;
}

bool SmallSparseLu::Factor() {
  active_ = nullptr;
  if (n_ <= 0 || n_ > kMaxSize) return false;
  ++clock_;
  auto same = [&](const Plan& p) {
    return p.n == n_ && std::equal(p.pattern.begin(), p.pattern.begin() + n_, bits_.begin());
  };
  Plan* plan = nullptr;
  if (last_ < plans_.size() && same(plans_[last_])) {
    plan = &plans_[last_];  // a warm step's basis usually keeps its pattern
  } else {
    for (Plan& p : plans_) {
      if (same(p)) plan = &p;
    }
  }
  if (plan != nullptr) {
    plan->last_used = clock_;
    if (Replay(*plan)) {
      active_ = plan;
      last_ = static_cast<size_t>(plan - plans_.data());
      return true;
    }
    // This step's values need other pivots: plan again on them.
  } else if (plans_.size() < kPlans) {
    plans_.reserve(kPlans);  // plans stay where they are
    plan = &plans_.emplace_back();
  } else {
    plan = &*std::min_element(plans_.begin(), plans_.end(), [](const Plan& x, const Plan& y) {
      return x.last_used < y.last_used;
    });
  }
  plan->last_used = clock_;
  if (!BuildPlan(*plan) || !Replay(*plan)) {
    plan->n = 0;  // matches nothing
    return false;
  }
  active_ = plan;
  last_ = static_cast<size_t>(plan - plans_.data());
  return true;
}

void SmallSparseLu::Solve(const double* rhs, double* x) const {
  const Plan& plan = *active_;
  const double* a = a_.data();
  const int* rows = plan.rows.data();
  const int* cols = plan.cols.data();
  std::array<double, kMaxSize> y;
  std::copy(rhs, rhs + n_, y.begin());
  for (const Elimination& el : plan.steps) {
    const double yp = y[static_cast<size_t>(el.row)];
    if (yp == 0) continue;
    for (int k = el.r0; k < el.r1; ++k)
      y[static_cast<size_t>(rows[k])] -= a[rows[k] * kMaxSize + el.col] * yp;
  }
  for (auto it = plan.steps.rbegin(); it != plan.steps.rend(); ++it) {
    const Elimination& el = *it;
    const double* prow = a + el.row * kMaxSize;
    double sum = y[static_cast<size_t>(el.row)];
    for (int k = el.c0; k < el.c1; ++k) sum -= prow[cols[k]] * x[cols[k]];
    x[el.col] = sum / prow[el.col];
  }
}

void SmallSparseLu::Residual(const double* rhs, const double* x, double* r) const {
  std::copy(rhs, rhs + n_, r);
  for (const Entry& e : entries_) r[e.row] -= e.value * x[e.col];
}

}  // namespace arena::mechanics
