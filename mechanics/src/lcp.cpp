// Lemke's complementary pivoting method with a lexicographic ratio test.
//
// Variables are numbered w_0..w_{n-1}, z_0..z_{n-1}, z0 (the artificial
// variable). The basis inverse is kept explicitly and updated by rank-one
// pivots (O(n^2) each); the final basis is then re-solved from scratch
// ("polish") so the reported solution does not carry the drift of the pivots.
#include "arena/mechanics/lcp.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>

#include <Eigen/LU>

namespace arena::mechanics {
namespace {

// Pivots between rebuilds of the basis inverse (drift control).
constexpr int kRefactorInterval = 32;
// The lexicographic rule's ties: entries of two scaled basis-inverse rows
// equal within this fraction of the rows' own size.
constexpr double kLexicographicTolerance = 1e-12;
// A refactored basis block whose reciprocal condition number (LU estimate)
// is below this is singular for the method: 1e-13 leaves ~3 digits.
constexpr double kMinBasisRcond = 1e-13;

double NaturalResidual(const Eigen::VectorXd& z, const Eigen::VectorXd& w) {
  double worst = 0;
  for (Eigen::Index i = 0; i < z.size(); ++i) {
    worst = std::max(worst, std::abs(std::min(z[i], w[i])));
  }
  return worst;
}

bool AllFinite(const Eigen::VectorXd& v) { return v.allFinite(); }

// A dense matrix as columns (its storage is column-major).
class DenseColumns final : public LcpColumns {
 public:
  explicit DenseColumns(const Eigen::MatrixXd& A) : A_(A) {}
  Eigen::Index size() const override { return A_.rows(); }
  const double* Column(Eigen::Index j) const override { return A_.data() + j * A_.rows(); }
  bool AllFinite() const override { return A_.allFinite(); }

 private:
  const Eigen::MatrixXd& A_;
};

// LU factorisation with partial pivoting of a basis block, on work space
// kept between calls (no dispatch, no heap). Up to 16 rows it runs Eigen's
// unblocked algorithm and its panel-of-8 triangular solves written out in
// the same order, so the answer is Eigen's to the last bit; larger blocks go
// to Eigen's blocked PartialPivLU. (The unblocked LU up to 32 rows, where
// Eigen blocks in panels of 8 and so rounds differently, was tried: a
// closed-loop pivot, executors_closed_loop_test, then ended 0.48 rad from
// its target instead of within 0.02 -- a step's last bits can choose
// another of a friction LCP's solutions -- so the bits stay Eigen's.)
class BasisLu {
 public:
  void Compute(const Eigen::MatrixXd& block) {
    m_ = block.rows();
    if (m_ > kUnblocked) {
      large_.compute(block);
      return;
    }
    const Eigen::Index m = m_;
    double* a = lu_.data();
    std::copy(block.data(), block.data() + m * m, a);
    for (Eigen::Index k = 0; k < m; ++k) {
      Eigen::Index best = k;
      double biggest = std::abs(a[k + k * m]);
      for (Eigen::Index i = k + 1; i < m; ++i) {
        const double s = std::abs(a[i + k * m]);
        if (s > biggest) {
          biggest = s;
          best = i;
        }
      }
      swap_[static_cast<size_t>(k)] = best;
      if (biggest != 0) {
        if (best != k) {
          for (Eigen::Index j = 0; j < m; ++j) std::swap(a[k + j * m], a[best + j * m]);
        }
        const double pivot = a[k + k * m];
        for (Eigen::Index i = k + 1; i < m; ++i) a[i + k * m] /= pivot;
      }
      const double* l = a + k * m;
      for (Eigen::Index j = k + 1; j < m; ++j) {
        double* col = a + j * m;
        const double u = col[k];
        for (Eigen::Index i = k + 1; i < m; ++i) col[i] -= l[i] * u;
      }
    }
  }
  // x = block⁻¹ rhs.
  void Solve(const Eigen::VectorXd& rhs, Eigen::VectorXd& x) const {
    if (m_ > kUnblocked) {
      x = large_.solve(rhs);
      return;
    }
    std::array<double, kUnblocked> y;
    std::copy(rhs.data(), rhs.data() + m_, y.data());
    for (Eigen::Index k = 0; k < m_; ++k) std::swap(y[k], y[swap_[static_cast<size_t>(k)]]);
    ForwardUnitLower(y.data());
    BackwardUpper(y.data());
    x = Eigen::Map<const Eigen::VectorXd>(y.data(), m_);
  }

 private:
  // Eigen's triangular_solve_vector (column-major): panels of kPanel
  // columns solved column by column, the rows past a panel updated by one
  // matrix-vector product (each row's sum from zero in column order).
  void ForwardUnitLower(double* x) const {
    const Eigen::Index m = m_;
    const double* a = lu_.data();
    for (Eigen::Index p0 = 0; p0 < m; p0 += kPanel) {
      const Eigen::Index p1 = std::min(p0 + kPanel, m);
      for (Eigen::Index i = p0; i < p1; ++i) {
        const double xi = x[i];
        if (xi == 0) continue;
        for (Eigen::Index r = i + 1; r < p1; ++r) x[r] -= xi * a[r + i * m];
      }
      for (Eigen::Index r = p1; r < m; ++r) {
        double sum = 0;
        for (Eigen::Index j = p0; j < p1; ++j) sum += a[r + j * m] * x[j];
        x[r] += -1.0 * sum;
      }
    }
  }
  void BackwardUpper(double* x) const {
    const Eigen::Index m = m_;
    const double* a = lu_.data();
    for (Eigen::Index p1 = m; p1 > 0; p1 -= kPanel) {
      const Eigen::Index p0 = std::max<Eigen::Index>(p1 - kPanel, 0);
      for (Eigen::Index i = p1 - 1; i >= p0; --i) {
        if (x[i] == 0) continue;
        x[i] /= a[i + i * m];
        const double xi = x[i];
        for (Eigen::Index r = p0; r < i; ++r) x[r] -= xi * a[r + i * m];
      }
      for (Eigen::Index r = 0; r < p0; ++r) {
        double sum = 0;
        for (Eigen::Index j = p0; j < p1; ++j) sum += a[r + j * m] * x[j];
        x[r] += -1.0 * sum;
      }
    }
  }

  static constexpr Eigen::Index kUnblocked = 16;  // Eigen's UnBlockedBound
  static constexpr Eigen::Index kPanel = 8;       // EIGEN_TUNE_TRIANGULAR_PANEL_WIDTH
  Eigen::Index m_ = 0;
  std::array<double, kUnblocked * kUnblocked> lu_{};
  std::array<Eigen::Index, kUnblocked> swap_{};
  Eigen::PartialPivLU<Eigen::MatrixXd> large_;
};

// r = rhs - block x (the product summed from zero in column order, as
// Eigen's column-major matrix-vector product sums it).
void BasisResidual(const Eigen::MatrixXd& block, const Eigen::VectorXd& x,
                   const Eigen::VectorXd& rhs, Eigen::VectorXd& r) {
  const Eigen::Index m = block.rows();
  r.setZero(m);
  for (Eigen::Index j = 0; j < m; ++j) {
    const double xj = x[j];
    const double* a = block.data() + j * m;
    for (Eigen::Index i = 0; i < m; ++i) r[i] += a[i] * xj;
  }
  for (Eigen::Index i = 0; i < m; ++i) r[i] = rhs[i] - r[i];
}

// Solves the complementary basis "z_i basic where basis[i]" exactly:
// A_bb z_b = -b_b, all other z zero. False when that basis is singular.
bool SolveBasis(const LcpColumns& A, const Eigen::VectorXd& b, const std::vector<char>& basis,
                Eigen::VectorXd& z, Eigen::VectorXd& w) {
  // Called on every warm-started step: keep the work space between calls.
  thread_local std::vector<Eigen::Index> idx;
  thread_local Eigen::MatrixXd Abb;
  thread_local Eigen::VectorXd bb, zb, rb, db;
  thread_local BasisLu lu;
  const Eigen::Index n = b.size();
  idx.clear();
  for (Eigen::Index i = 0; i < n; ++i) {
    if (basis[static_cast<size_t>(i)]) idx.push_back(i);
  }
  z.setZero(n);
  if (!idx.empty()) {
    const auto m = static_cast<Eigen::Index>(idx.size());
    bb.resize(m);
    for (Eigen::Index c = 0; c < m; ++c) bb[c] = -b[idx[static_cast<size_t>(c)]];
    if (A.SolveBasisBlock(idx, bb, zb)) {
      for (Eigen::Index r = 0; r < m; ++r) z[idx[static_cast<size_t>(r)]] = zb[r];
      A.Multiply(z, w);
      w += b;
      return AllFinite(w);
    }
    A.GatherBasis(idx, Abb);
    lu.Compute(Abb);
    lu.Solve(bb, zb);
    if (!AllFinite(zb)) return false;
    // One step of iterative refinement: the contact blocks can be
    // ill-conditioned (a 0.1 mm object: entries from 1 to 1e7).
    BasisResidual(Abb, zb, bb, rb);
    lu.Solve(rb, db);
    zb += db;
    if (!AllFinite(zb)) return false;
    // A singular basis shows as a large solve residual.
    const double scale = 1.0 + bb.lpNorm<Eigen::Infinity>();
    BasisResidual(Abb, zb, bb, rb);
    if (rb.lpNorm<Eigen::Infinity>() > 1e-9 * scale) return false;
    for (Eigen::Index r = 0; r < m; ++r) z[idx[static_cast<size_t>(r)]] = zb[r];
  }
  A.Multiply(z, w);
  w += b;
  return AllFinite(w);
}

// Accepts a candidate solution when it is finite, nonnegative and
// complementary within tolerance (nondimensional, relative to the data).
bool Acceptable(const Eigen::VectorXd& z, const Eigen::VectorXd& w, const Eigen::VectorXd& b,
                double tol) {
  if (!AllFinite(z) || !AllFinite(w)) return false;
  // Relative to the data, not to z: a near-singular basis can give a huge z
  // whose relative residual looks small. Only relative: with a floor of 1, a
  // problem scaled by 1e-15 accepted any z (its residual was below 1e-9
  // whatever z was) and Lemke's first pivot came back as a solution.
  return NaturalResidual(z, w) <= tol * b.lpNorm<Eigen::Infinity>();
}

// Murty's least-index principal pivoting from a basis that is nearly right:
// a Lemke run on an ill-conditioned problem can end on a basis a few indices
// off (drift in the ratio tests), whose exact solution then has slightly
// negative z or w. Flipping the least violated index and re-solving fixes
// that in a few steps (finite for P-matrices; here a bounded repair that
// either reaches an acceptable solution or gives up).
bool RepairBasis(const LcpColumns& A, const Eigen::VectorXd& b, std::vector<char> basis, double tol,
                 LcpResult& out) {
  const Eigen::Index n = b.size();
  const double thr = tol * std::max(1.0, b.lpNorm<Eigen::Infinity>());
  Eigen::VectorXd z, w;
  for (Eigen::Index iter = 0; iter < 2 * n + 10; ++iter) {
    if (!SolveBasis(A, b, basis, z, w)) return false;
    if (Acceptable(z, w, b, tol)) {
      out.ok = true;
      out.status = LcpStatus::kOk;
      out.reason.clear();
      out.z = z;
      out.w = w;
      out.basis = basis;
      out.natural_residual = NaturalResidual(z, w);
      return true;
    }
    Eigen::Index flip = -1;
    for (Eigen::Index i = 0; i < n && flip < 0; ++i) {
      if (basis[static_cast<size_t>(i)] ? z[i] < -thr : w[i] < -thr) flip = i;
    }
    if (flip < 0) return false;  // complementary and feasible but still inaccurate
    basis[static_cast<size_t>(flip)] = !basis[static_cast<size_t>(flip)];
  }
  return false;
}

// Lemke's basis inverse, which knows where it may hold anything but +0: the
// columns a pivot or a refactorisation wrote, the rows a pivot scaled, and
// its unit entries. Clear() zeroes just those (a fresh inverse used to be
// n² zeros, and at n = 650 zeroing it twice per 32 pivots was a third of a
// cold solve); afterwards every entry is +0, as after setZero().
class TrackedInverse {
 public:
  Eigen::MatrixXd B;
  void Identity(Eigen::Index n) {
    if (B.rows() != n) {
      B.setZero(n, n);
      dirty_col_.assign(static_cast<size_t>(n), 0);
      scaled_row_.assign(static_cast<size_t>(n), 0);
      cols_.clear();
      rows_.clear();
      units_.clear();
    } else {
      Clear();
    }
    for (Eigen::Index i = 0; i < n; ++i) Unit(i, i);
  }
  void Clear() {
    for (Eigen::Index j : cols_) {
      B.col(j).setZero();
      dirty_col_[static_cast<size_t>(j)] = 0;
    }
    for (Eigen::Index r : rows_) {
      B.row(r).setZero();
      scaled_row_[static_cast<size_t>(r)] = 0;
    }
    for (const auto& [i, j] : units_) B(i, j) = 0;
    cols_.clear();
    rows_.clear();
    units_.clear();
  }
  void Unit(Eigen::Index i, Eigen::Index j) {
    B(i, j) = 1;
    units_.emplace_back(i, j);
  }
  void ColumnWritten(Eigen::Index j) {
    if (!dirty_col_[static_cast<size_t>(j)]) {
      dirty_col_[static_cast<size_t>(j)] = 1;
      cols_.push_back(j);
    }
  }
  void RowScaled(Eigen::Index r) {
    if (!scaled_row_[static_cast<size_t>(r)]) {
      scaled_row_[static_cast<size_t>(r)] = 1;
      rows_.push_back(r);
    }
  }
  // y = B b right after a refactorisation (every column a written one or a
  // unit column), summed as Eigen's dense product sums it (MultiplyColumns):
  // a unit column adds b_j to one row and exact zeros elsewhere.
  void MultiplyFresh(const Eigen::VectorXd& b, const std::vector<Eigen::Index>& unit_row,
                     Eigen::VectorXd& y) const {
    const Eigen::Index n = B.rows();
    const Eigen::Index block =
        n < 128 ? n : (n * static_cast<Eigen::Index>(sizeof(double)) < 32000 ? 16 : 4);
    y.setZero(n);
    thread_local Eigen::VectorXd sum;
    for (Eigen::Index j0 = 0; j0 < n; j0 += block) {
      const Eigen::Index j1 = std::min(j0 + block, n);
      sum.setZero(n);
      for (Eigen::Index j = j0; j < j1; ++j) {
        const Eigen::Index i = unit_row[static_cast<size_t>(j)];
        if (i >= 0) {
          sum[i] += b[j];
        } else {
          sum += B.col(j) * b[j];
        }
      }
      y += sum;
    }
  }

 private:
  std::vector<char> dirty_col_, scaled_row_;
  std::vector<Eigen::Index> cols_, rows_;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> units_;
};

// Lemke's work space, kept per thread between calls (most solves are small
// and allocation was a sixth of their cost).
struct LemkeWork {
  // Column-major: while the slack w_v is basic at position i, column v of
  // the inverse is exactly e_i, and a pivot row is zero on all those columns
  // but the leaving slack's. The rank-one update (Pivot) therefore touches
  // only the columns of the rows no slack covers (k + 1 of n), and the
  // entering column is formed from them plus the slack positions: O(n k)
  // per pivot instead of O(n²), with the same arithmetic on what remains.
  TrackedInverse inverse;
  Eigen::VectorXd x, d;  // x: values of the basic variables; d: the entering column
  Eigen::RowVectorXd pivot_row;
  std::vector<Eigen::Index> basis;
  std::vector<Eigen::Index> slack_pos;  // position of basic w_v, or -1
  std::vector<Eigen::Index> ties;
  // RefactorInverse: non-unit positions, uncovered rows, and where column v
  // of the inverse is e_(unit_row[v]).
  std::vector<Eigen::Index> cpos, srows, unit_row;
  std::vector<char> covered;
  Eigen::MatrixXd Cs, Cu, G;
  Eigen::PartialPivLU<Eigen::MatrixXd> cs_lu;
};

// Pivots the entering variable (column w.d) in at row r; returns the one
// that left.
Eigen::Index Pivot(LemkeWork& w, Eigen::Index n, Eigen::Index r, Eigen::Index entering) {
  Eigen::MatrixXd& Binv = w.inverse.B;
  const double p = w.d[r];
  w.x[r] /= p;
  Binv.row(r) /= p;
  w.inverse.RowScaled(r);
  w.pivot_row = Binv.row(r);
  w.d[r] = 0;
  w.x.noalias() -= w.d * w.x[r];
  for (Eigen::Index j = 0; j < n; ++j) {
    if (w.pivot_row[j] != 0) {
      Binv.col(j).noalias() -= w.d * w.pivot_row[j];
      w.inverse.ColumnWritten(j);
    }
  }
  const Eigen::Index leaving = w.basis[static_cast<size_t>(r)];
  w.basis[static_cast<size_t>(r)] = entering;
  if (leaving < n) w.slack_pos[static_cast<size_t>(leaving)] = -1;
  if (entering < n) w.slack_pos[static_cast<size_t>(entering)] = r;
  return leaving;
}

// Rebuilds the basis inverse from scratch, so rank-one drift does not pile
// up. Most basic variables are slacks w_v (unit columns e_v), so only the
// k x k block of the other columns on the rows no slack covers needs a
// factorisation: with C the k non-unit columns and S those rows,
//   x_C = C_S⁻¹ y_S,   x_(slack of row r) = y_r - C_r x_C,
// which costs O(k³ + (n - k) k²) instead of O(n³) for the full inverse.
bool RefactorInverse(const LcpColumns& A, const Eigen::VectorXd& b, const Eigen::VectorXd& cover,
                     LemkeWork& w) {
  const Eigen::Index n = b.size();
  Eigen::MatrixXd& Binv = w.inverse.B;
  // Entries of the basic columns, -A(., v - n) or -cover for z0: a pointer
  // per column, then one entry per row.
  auto column_of = [&](Eigen::Index v) -> const double* {
    return v < 2 * n ? A.Column(v - n) : cover.data();
  };
  w.cpos.clear();
  w.srows.clear();
  w.covered.assign(static_cast<size_t>(n), 0);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index v = w.basis[static_cast<size_t>(i)];
    if (v < n) {
      w.covered[static_cast<size_t>(v)] = 1;
    } else {
      w.cpos.push_back(i);
    }
  }
  for (Eigen::Index r = 0; r < n; ++r) {
    if (!w.covered[static_cast<size_t>(r)]) w.srows.push_back(r);
  }
  const auto k = static_cast<Eigen::Index>(w.cpos.size());
  if (static_cast<Eigen::Index>(w.srows.size()) != k) return false;
  w.inverse.Clear();
  if (k > 0) {
    w.Cs.resize(k, k);
    for (Eigen::Index c = 0; c < k; ++c) {
      const double* a = column_of(w.basis[static_cast<size_t>(w.cpos[static_cast<size_t>(c)])]);
      for (Eigen::Index r = 0; r < k; ++r) w.Cs(r, c) = -a[w.srows[static_cast<size_t>(r)]];
    }
    w.cs_lu.compute(w.Cs);
    // Near-singular, not only non-finite: below kMinBasisRcond the inverse
    // has lost all but a few digits, and the ratio tests that follow would
    // pick rows by rounding (a wrong basis, not a solution). The caller
    // stops with the typed kSingularBasis.
    if (!(w.cs_lu.rcond() >= kMinBasisRcond)) return false;
    const Eigen::MatrixXd cs_inv = w.cs_lu.inverse();
    if (!cs_inv.allFinite()) return false;
    for (Eigen::Index c = 0; c < k; ++c) {
      for (Eigen::Index r = 0; r < k; ++r) {
        Binv(w.cpos[static_cast<size_t>(c)], w.srows[static_cast<size_t>(r)]) = cs_inv(c, r);
      }
    }
    // Slack rows: -C_r C_S⁻¹ on the uncovered rows.
    w.Cu.resize(n - k, k);
    for (Eigen::Index c = 0; c < k; ++c) {
      const double* a = column_of(w.basis[static_cast<size_t>(w.cpos[static_cast<size_t>(c)])]);
      Eigen::Index u = 0;
      for (Eigen::Index i = 0; i < n; ++i) {
        const Eigen::Index v = w.basis[static_cast<size_t>(i)];
        if (v >= n) continue;
        w.Cu(u++, c) = -a[v];
      }
    }
    w.G.noalias() = w.Cu * cs_inv;
    Eigen::Index u = 0;
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Index v = w.basis[static_cast<size_t>(i)];
      if (v >= n) continue;
      for (Eigen::Index r = 0; r < k; ++r) Binv(i, w.srows[static_cast<size_t>(r)]) = -w.G(u, r);
      ++u;
    }
  }
  for (Eigen::Index r = 0; r < k; ++r) w.inverse.ColumnWritten(w.srows[static_cast<size_t>(r)]);
  w.unit_row.assign(static_cast<size_t>(n), -1);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index v = w.basis[static_cast<size_t>(i)];
    if (v < n) {
      w.inverse.Unit(i, v);
      w.unit_row[static_cast<size_t>(v)] = i;
    }
  }
  w.inverse.MultiplyFresh(b, w.unit_row, w.x);
  return w.x.allFinite();
}

// w.d = the entering variable's column through the basis inverse.
void EnteringColumn(const LcpColumns& A, Eigen::Index n, Eigen::Index entering, LemkeWork& w) {
  const Eigen::MatrixXd& Binv = w.inverse.B;
  if (entering < n) {
    w.d = Binv.col(entering);
    return;
  }
  // d = -Binv a: covered rows contribute a_v e_(slack position).
  const double* a = A.Column(entering - n);
  w.d.setZero();
  for (Eigen::Index j = 0; j < n; ++j) {
    const double aj = a[j];
    if (aj == 0) continue;
    const Eigen::Index sp = w.slack_pos[static_cast<size_t>(j)];
    if (sp >= 0) {
      w.d[sp] -= aj;
    } else {
      w.d.noalias() -= Binv.col(j) * aj;
    }
  }
}

// The row that leaves, among those reaching the minimum ratio `best`:
// z0's if it is one of them (that ends the method), otherwise the
// lexicographic minimum of the basis inverse's rows scaled by the column.
Eigen::Index LeavingRow(LemkeWork& w, Eigen::Index n, Eigen::Index z0, double best, double dtol) {
  const Eigen::MatrixXd& Binv = w.inverse.B;
  w.ties.clear();
  const double slack = 1e-12 * std::max(1.0, std::abs(best));
  for (Eigen::Index i = 0; i < n; ++i) {
    if (w.d[i] > dtol && w.x[i] / w.d[i] <= best + slack) w.ties.push_back(i);
  }
  Eigen::Index r = w.ties.front();
  for (Eigen::Index i : w.ties) {
    if (w.basis[static_cast<size_t>(i)] == z0) return i;
  }
  // Rows compare equal within rounding of their own size (relative): the
  // absolute 1e-14 it was made every row of a problem scaled by 1e15 (basis
  // inverse entries ~1e-15) tie, the first won, and cycling was no longer
  // excluded.
  auto row_size = [&](Eigen::Index i) {
    return Binv.row(i).lpNorm<Eigen::Infinity>() / std::abs(w.d[i]);
  };
  double r_size = row_size(r);
  for (size_t t = 1; t < w.ties.size(); ++t) {
    const Eigen::Index c = w.ties[t];
    const double eps = kLexicographicTolerance * std::max(r_size, row_size(c));
    for (Eigen::Index j = 0; j < n; ++j) {
      const double a = Binv(c, j) / w.d[c];
      const double bb = Binv(r, j) / w.d[r];
      if (a < bb - eps) {
        r = c;
        r_size = row_size(r);
        break;
      }
      if (a > bb + eps) break;
    }
  }
  return r;
}

// z and w from the final basis (re-solved exactly when that is better), and
// whether they pass as a solution.
void FinishLemke(const LcpColumns& A, const Eigen::VectorXd& b, const LemkeWork& work, int pivots,
                 const LcpOptions& options, LcpResult& out) {
  const Eigen::Index n = b.size();
  out.pivots = pivots;
  Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index v = work.basis[static_cast<size_t>(i)];
    if (v >= n && v < 2 * n) {
      z[v - n] = work.x[i];
      out.basis[static_cast<size_t>(v - n)] = 1;
    }
  }
  Eigen::VectorXd w;
  MultiplyColumns(A, z, w);
  w += b;
  // Polish: re-solve the final basis exactly and keep the better answer.
  Eigen::VectorXd zp, wp;
  if (SolveBasis(A, b, out.basis, zp, wp)) {
    const double raw =
        AllFinite(w) ? NaturalResidual(z, w) : std::numeric_limits<double>::infinity();
    if (NaturalResidual(zp, wp) <= raw) {
      z = zp;
      w = wp;
    }
  }
  if (!AllFinite(z) || !AllFinite(w)) {
    out.status = LcpStatus::kNonFiniteSolution;
    out.reason = "non-finite solution after " + std::to_string(pivots) + " pivots";
    return;
  }
  out.natural_residual = NaturalResidual(z, w);
  if (!Acceptable(z, w, b, options.feasibility)) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "inaccurate solution (natural residual %.3g) after %d pivots",
                  out.natural_residual, pivots);
    out.status = LcpStatus::kInaccurate;
    out.reason = buf;
    return;
  }
  out.ok = true;
  out.status = LcpStatus::kOk;
  out.reason.clear();
  out.z = z;
  out.w = w;
}

void Stopped(LcpResult& out, LcpStatus status, const std::string& why, int pivots) {
  out.status = status;
  out.reason = why + " after " + std::to_string(pivots) + " pivots";
  out.pivots = pivots;
}

// One run of Lemke's method with covering vector `cover`; fills z, w,
// basis, pivots and ok/reason of `out`.
void LemkeOnce(const LcpColumns& A, const Eigen::VectorXd& b, const Eigen::VectorXd& cover,
               const LcpOptions& options, LcpResult& out) {
  const Eigen::Index n = b.size();
  out.ok = false;
  out.basis.assign(static_cast<size_t>(n), 0);
  const int max_pivots =
      options.max_pivots > 0 ? options.max_pivots : static_cast<int>(50 * n + 200);
  const double tol = options.pivot_tolerance;
  const Eigen::Index z0 = 2 * n;
  thread_local LemkeWork w;
  w.inverse.Identity(n);
  w.x = b;
  w.d.resize(n);
  w.pivot_row.resize(n);
  w.basis.resize(static_cast<size_t>(n));
  w.slack_pos.resize(static_cast<size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    w.basis[static_cast<size_t>(i)] = i;
    w.slack_pos[static_cast<size_t>(i)] = i;
  }

  // z0 enters with column -cover at the row that needs the largest z0.
  Eigen::Index r = 0;
  for (Eigen::Index i = 1; i < n; ++i) {
    if (w.x[i] / cover[i] <= w.x[r] / cover[r]) r = i;
  }
  w.d = -cover;
  Eigen::Index leaving = Pivot(w, n, r, z0);
  int pivots = 1;
  int fresh_at = -1;  // pivot count at the last refactor
  for (;;) {
    if (pivots % kRefactorInterval == 0 && pivots != fresh_at) {
      if (!RefactorInverse(A, b, cover, w)) {
        return Stopped(out, LcpStatus::kSingularBasis, "singular basis", pivots);
      }
      fresh_at = pivots;
    }
    if (pivots >= max_pivots) {
      out.status = LcpStatus::kPivotLimit;
      out.reason = "pivot limit (" + std::to_string(max_pivots) + ") reached";
      out.pivots = pivots;
      return;
    }
    const Eigen::Index entering = leaving < n ? leaving + n : leaving - n;
    EnteringColumn(A, n, entering, w);
    // Minimum ratio over rows where the entering variable decreases a basic one.
    // Pivots are judged relative to the column (the problem is scaled, but
    // far-away contacts still make columns of very different sizes).
    // Relative only: with a floor of 1, every entry of a problem scaled by
    // 1e-15 was below it and the run ended on a false ray.
    const double dtol = tol * w.d.lpNorm<Eigen::Infinity>();
    double best = std::numeric_limits<double>::infinity();
    for (Eigen::Index i = 0; i < n; ++i) {
      if (w.d[i] > dtol) best = std::min(best, w.x[i] / w.d[i]);
    }
    if (!std::isfinite(best)) {
      // On degenerate problems z0 can reach zero without being chosen to
      // leave; the point reached is then already a solution. Otherwise this
      // is a genuine secondary ray.
      double z0_value = std::numeric_limits<double>::infinity();
      for (Eigen::Index i = 0; i < n; ++i) {
        if (w.basis[static_cast<size_t>(i)] == z0) z0_value = w.x[i];
      }
      // Relative: with a floor of 1 any z0 of a problem scaled small passed.
      if (std::abs(z0_value) <= 1e-9 * w.x.lpNorm<Eigen::Infinity>()) break;
      // A ray seen through a drifted inverse may be an artefact of the
      // drift: look again with a fresh one (cheap, see RefactorInverse) first.
      if (fresh_at != pivots) {
        if (!RefactorInverse(A, b, cover, w)) {
          return Stopped(out, LcpStatus::kSingularBasis, "singular basis", pivots);
        }
        fresh_at = pivots;
        continue;
      }
      return Stopped(out, LcpStatus::kRayTermination, "ray termination", pivots);
    }
    leaving = Pivot(w, n, LeavingRow(w, n, z0, best, dtol), entering);
    ++pivots;
    if (leaving == z0) break;
  }
  FinishLemke(A, b, w, pivots, options, out);
}

}  // namespace

const char* ToString(LcpStatus status) {
  switch (status) {
    case LcpStatus::kOk:
      return "ok";
    case LcpStatus::kSingularBasis:
      return "singular basis";
    case LcpStatus::kPivotLimit:
      return "pivot limit";
    case LcpStatus::kRayTermination:
      return "ray termination";
    case LcpStatus::kNonFiniteSolution:
      return "non-finite solution";
    case LcpStatus::kInaccurate:
      return "inaccurate solution";
    case LcpStatus::kBadProblem:
      return "bad problem";
  }
  return "?";
}

void LcpColumns::GatherBasis(const std::vector<Eigen::Index>& idx, Eigen::MatrixXd& block) const {
  const auto m = static_cast<Eigen::Index>(idx.size());
  block.resize(m, m);
  for (Eigen::Index c = 0; c < m; ++c) {
    const double* a = Column(idx[static_cast<size_t>(c)]);
    for (Eigen::Index r = 0; r < m; ++r) block(r, c) = a[idx[static_cast<size_t>(r)]];
  }
}

void LcpColumns::Multiply(const Eigen::VectorXd& z, Eigen::VectorXd& w) const {
  MultiplyColumns(*this, z, w);
}

bool LcpColumns::SolveBasisBlock(const std::vector<Eigen::Index>&, const Eigen::VectorXd&,
                                 Eigen::VectorXd&) const {
  return false;
}

void MultiplyColumns(const LcpColumns& A, const Eigen::VectorXd& z, Eigen::VectorXd& w) {
  // Eigen 3.4's general_matrix_vector_product (column-major): columns in
  // blocks of all of them (n < 128), 16 (n < 4000) or 4; per block and row a
  // sum from zero over the block's columns in order, then added to w.
  const Eigen::Index n = A.size();
  const Eigen::Index block =
      n < 128 ? n : (n * static_cast<Eigen::Index>(sizeof(double)) < 32000 ? 16 : 4);
  w.setZero(n);
  thread_local Eigen::VectorXd sum;
  for (Eigen::Index j0 = 0; j0 < n; j0 += block) {
    const Eigen::Index j1 = std::min(j0 + block, n);
    bool any = false;
    for (Eigen::Index j = j0; j < j1; ++j) {
      const double zj = z[j];
      if (zj == 0) continue;
      if (!any) sum.setZero(n);
      any = true;
      const double* a = A.Column(j);
      for (Eigen::Index i = 0; i < n; ++i) sum[i] += a[i] * zj;
    }
    if (any) w += sum;
  }
}

LcpResult SolveLcp(const Eigen::MatrixXd& A, const Eigen::VectorXd& b,
                   const std::vector<char>* warm_basis, const LcpOptions& options) {
  if (A.rows() != b.size() || A.cols() != b.size()) {
    LcpResult out;
    out.basis.assign(static_cast<size_t>(b.size()), 0);
    out.status = LcpStatus::kBadProblem;
    out.reason = "matrix and vector sizes differ";
    return out;
  }
  return SolveLcp(DenseColumns(A), b, warm_basis, options);
}

LcpResult SolveLcp(const LcpColumns& A, const Eigen::VectorXd& b,
                   const std::vector<char>* warm_basis, const LcpOptions& options) {
  LcpResult out;
  SolveLcp(A, b, warm_basis, options, out);
  return out;
}

void SolveLcp(const LcpColumns& A, const Eigen::VectorXd& b, const std::vector<char>* warm_basis,
              const LcpOptions& options, LcpResult& out) {
  // Every field is set again; the vectors keep their storage.
  out.ok = false;
  out.status = LcpStatus::kBadProblem;
  out.reason.clear();
  out.pivots = 0;
  out.warm_start_used = false;
  out.natural_residual = 0;
  const Eigen::Index n = b.size();
  if (A.size() != n) {
    out.basis.assign(static_cast<size_t>(n), 0);
    out.reason = "matrix and vector sizes differ";
    return;
  }
  if (!A.AllFinite() || !b.allFinite()) {
    out.basis.assign(static_cast<size_t>(n), 0);
    out.reason = "non-finite problem data";
    return;
  }
  if (n == 0 || b.minCoeff() >= 0) {
    out.basis.assign(static_cast<size_t>(n), 0);
    out.ok = true;
    out.status = LcpStatus::kOk;
    out.z.setZero(n);
    out.w = b;
    return;
  }

  // Warm start: the previous step's basis usually still holds.
  if (warm_basis != nullptr && static_cast<Eigen::Index>(warm_basis->size()) == n) {
    if (SolveBasis(A, b, *warm_basis, out.z, out.w) &&
        Acceptable(out.z, out.w, b, options.feasibility)) {
      out.ok = true;
      out.status = LcpStatus::kOk;
      out.natural_residual = NaturalResidual(out.z, out.w);
      out.basis = *warm_basis;
      out.warm_start_used = true;
      return;
    }
  }
  out.basis.assign(static_cast<size_t>(n), 0);

  // Lemke's method is only guaranteed for copositive-plus matrices; the
  // friction rows make ours merely copositive, and a ray can end a run on a
  // problem that has a solution. Other covering vectors take other paths:
  // retry with a few fixed pseudo-random ones (deterministic).
  //
  // The default first covering vector is one of those pseudo-random ones,
  // not all ones: the contact LCP is full of symmetric rows (the points of a
  // patch ring, a pad's y+ / y- pair) and the uniform vector makes their
  // ratios tie at every step. On the 3x3-patch family the all-ones run ended
  // on a ray or an inaccurate basis for half the problems (each then paid a
  // second run); a generic vector solved all of them in one run. All ones
  // stays in the sequence, second.
  const bool user_cover = options.covering.size() == n && options.covering.minCoeff() > 0;
  Eigen::VectorXd cover(n);
  const int attempts = std::max(1, options.covering_attempts);
  std::uint64_t seed = 0x9E3779B97F4A7C15ull;
  int total = 0;
  std::string first_reason;
  auto random_cover = [&] {
    for (Eigen::Index i = 0; i < n; ++i) {
      seed = seed * 6364136223846793005ull + 1442695040888963407ull;
      cover[i] = 0.5 + static_cast<double>(seed >> 11) * (1.0 / 9007199254740992.0) * 1.5;
    }
  };
  // The k-th covering vector of the sequence (k = 0, 1, ...), called in order.
  auto next_cover = [&](int k) {
    if (k == 0 && user_cover) {
      cover = options.covering;
    } else if (k == 1 && !user_cover) {
      cover.setOnes();
    } else {
      random_cover();
    }
  };
  for (int k = 0; k < options.first_covering; ++k) next_cover(k);
  for (int attempt = 0; attempt < attempts; ++attempt) {
    next_cover(options.first_covering + attempt);
    LemkeOnce(A, b, cover, options, out);
    total += out.pivots;
    if (out.ok) break;
    // An inaccurate end leaves its basis in out.basis: try to repair it.
    if (out.status == LcpStatus::kInaccurate &&
        RepairBasis(A, b, out.basis, options.feasibility, out))
      break;
    if (attempt == 0) first_reason = out.reason;
  }
  out.pivots = total;
  if (!out.ok) {
    out.reason = first_reason + "; " + std::to_string(attempts - 1) +
                 " other covering vectors failed too (last: " + out.reason + ")";
    out.z.resize(0);
    out.w.resize(0);
  }
}

}  // namespace arena::mechanics
