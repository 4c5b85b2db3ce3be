// Lemke's complementary pivoting method with a lexicographic ratio test.
//
// Variables are numbered w_0..w_{n-1}, z_0..z_{n-1}, z0 (the artificial
// variable). The basis inverse is kept explicitly and updated by rank-one
// pivots (O(n^2) each); the final basis is then re-solved from scratch
// ("polish") so the reported solution does not carry the drift of the pivots.
#include "arena/mechanics/lcp.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <Eigen/LU>

namespace arena::mechanics {
namespace {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

double NaturalResidual(const Eigen::VectorXd& z, const Eigen::VectorXd& w) {
  double worst = 0;
  for (Eigen::Index i = 0; i < z.size(); ++i) {
    worst = std::max(worst, std::abs(std::min(z[i], w[i])));
  }
  return worst;
}

bool AllFinite(const Eigen::VectorXd& v) { return v.allFinite(); }

// Solves the complementary basis "z_i basic where basis[i]" exactly:
// A_bb z_b = -b_b, all other z zero. False when that basis is singular.
bool SolveBasis(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, const std::vector<char>& basis,
                Eigen::VectorXd& z, Eigen::VectorXd& w) {
  const Eigen::Index n = b.size();
  std::vector<Eigen::Index> idx;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (basis[static_cast<size_t>(i)]) idx.push_back(i);
  }
  z = Eigen::VectorXd::Zero(n);
  if (!idx.empty()) {
    const auto m = static_cast<Eigen::Index>(idx.size());
    Eigen::MatrixXd Abb(m, m);
    Eigen::VectorXd bb(m);
    for (Eigen::Index r = 0; r < m; ++r) {
      bb[r] = -b[idx[static_cast<size_t>(r)]];
      for (Eigen::Index c = 0; c < m; ++c) {
        Abb(r, c) = A(idx[static_cast<size_t>(r)], idx[static_cast<size_t>(c)]);
      }
    }
    Eigen::PartialPivLU<Eigen::MatrixXd> lu(Abb);
    const Eigen::VectorXd zb = lu.solve(bb);
    if (!AllFinite(zb)) return false;
    // A singular basis shows as a large solve residual.
    const double scale = 1.0 + bb.lpNorm<Eigen::Infinity>();
    if ((Abb * zb - bb).lpNorm<Eigen::Infinity>() > 1e-9 * scale) return false;
    for (Eigen::Index r = 0; r < m; ++r) z[idx[static_cast<size_t>(r)]] = zb[r];
  }
  w = A * z + b;
  return AllFinite(w);
}

// Accepts a candidate solution when it is finite, nonnegative and
// complementary within tolerance (nondimensional, relative to the data).
bool Acceptable(const Eigen::VectorXd& z, const Eigen::VectorXd& w, double tol) {
  if (!AllFinite(z) || !AllFinite(w)) return false;
  const double scale = std::max({1.0, z.lpNorm<Eigen::Infinity>(), w.lpNorm<Eigen::Infinity>()});
  return NaturalResidual(z, w) <= tol * scale;
}

}  // namespace

LcpResult SolveLcp(const Eigen::MatrixXd& A, const Eigen::VectorXd& b,
                   const std::vector<char>* warm_basis, const LcpOptions& options) {
  LcpResult out;
  const Eigen::Index n = b.size();
  out.basis.assign(static_cast<size_t>(n), 0);
  if (A.rows() != n || A.cols() != n) {
    out.reason = "matrix and vector sizes differ";
    return out;
  }
  if (!A.allFinite() || !b.allFinite()) {
    out.reason = "non-finite problem data";
    return out;
  }
  if (n == 0 || b.minCoeff() >= 0) {
    out.ok = true;
    out.z = Eigen::VectorXd::Zero(n);
    out.w = b;
    return out;
  }

  // Warm start: the previous step's basis usually still holds.
  if (warm_basis != nullptr && static_cast<Eigen::Index>(warm_basis->size()) == n) {
    Eigen::VectorXd z, w;
    if (SolveBasis(A, b, *warm_basis, z, w) && Acceptable(z, w, options.feasibility)) {
      out.ok = true;
      out.z = z;
      out.w = w;
      out.basis = *warm_basis;
      out.warm_start_used = true;
      out.natural_residual = NaturalResidual(z, w);
      return out;
    }
  }

  const int max_pivots = options.max_pivots > 0 ? options.max_pivots
                                                : static_cast<int>(50 * n + 200);
  const double tol = options.pivot_tolerance;
  const Eigen::Index z0 = 2 * n;
  RowMatrix Binv = RowMatrix::Identity(n, n);
  Eigen::VectorXd x = b;  // values of the basic variables
  std::vector<Eigen::Index> basis(static_cast<size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) basis[static_cast<size_t>(i)] = i;

  Eigen::VectorXd d(n);
  Eigen::RowVectorXd pivot_row(n);
  auto pivot = [&](Eigen::Index r, Eigen::Index entering) {
    const double p = d[r];
    x[r] /= p;
    Binv.row(r) /= p;
    pivot_row = Binv.row(r);
    d[r] = 0;
    x.noalias() -= d * x[r];
    Binv.noalias() -= d * pivot_row;
    const Eigen::Index leaving = basis[static_cast<size_t>(r)];
    basis[static_cast<size_t>(r)] = entering;
    return leaving;
  };

  // First pivot: z0 enters (column -1) at the most negative b.
  Eigen::Index r = 0;
  for (Eigen::Index i = 1; i < n; ++i) {
    if (x[i] <= x[r]) r = i;
  }
  d.setConstant(-1.0);
  Eigen::Index leaving = pivot(r, z0);
  int pivots = 1;
  bool done = false;
  std::vector<Eigen::Index> ties;
  while (!done) {
    if (pivots >= max_pivots) {
      out.reason = "pivot limit (" + std::to_string(max_pivots) + ") reached";
      out.pivots = pivots;
      return out;
    }
    const Eigen::Index entering = leaving < n ? leaving + n : leaving - n;
    if (entering < n) {
      d = Binv.col(entering);
    } else {
      d.noalias() = -(Binv * A.col(entering - n));
    }
    // Minimum ratio over rows where the entering variable decreases a basic one.
    double best = std::numeric_limits<double>::infinity();
    for (Eigen::Index i = 0; i < n; ++i) {
      if (d[i] > tol) best = std::min(best, x[i] / d[i]);
    }
    if (!std::isfinite(best)) {
      out.reason = "ray termination after " + std::to_string(pivots) + " pivots";
      out.pivots = pivots;
      return out;
    }
    ties.clear();
    const double slack = 1e-12 * std::max(1.0, std::abs(best));
    for (Eigen::Index i = 0; i < n; ++i) {
      if (d[i] > tol && x[i] / d[i] <= best + slack) ties.push_back(i);
    }
    // Leaving z0 ends the method; otherwise break ties lexicographically
    // on the rows of the basis inverse scaled by the pivot column.
    r = ties.front();
    bool z0_leaves = false;
    for (Eigen::Index i : ties) {
      if (basis[static_cast<size_t>(i)] == z0) {
        r = i;
        z0_leaves = true;
      }
    }
    if (!z0_leaves && ties.size() > 1) {
      for (size_t t = 1; t < ties.size(); ++t) {
        const Eigen::Index c = ties[t];
        for (Eigen::Index j = 0; j < n; ++j) {
          const double a = Binv(c, j) / d[c];
          const double bb = Binv(r, j) / d[r];
          if (a < bb - 1e-14) {
            r = c;
            break;
          }
          if (a > bb + 1e-14) break;
        }
      }
    }
    leaving = pivot(r, entering);
    ++pivots;
    if (leaving == z0) done = true;
  }

  Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index v = basis[static_cast<size_t>(i)];
    if (v >= n && v < 2 * n) {
      z[v - n] = x[i];
      out.basis[static_cast<size_t>(v - n)] = 1;
    }
  }
  Eigen::VectorXd w = A * z + b;
  // Polish: re-solve the final basis exactly and keep the better answer.
  Eigen::VectorXd zp, wp;
  if (SolveBasis(A, b, out.basis, zp, wp)) {
    const double raw = AllFinite(w) ? NaturalResidual(z, w) : std::numeric_limits<double>::infinity();
    if (NaturalResidual(zp, wp) <= raw) {
      z = zp;
      w = wp;
    }
  }
  out.pivots = pivots;
  if (!AllFinite(z) || !AllFinite(w)) {
    out.reason = "non-finite solution after " + std::to_string(pivots) + " pivots";
    return out;
  }
  out.natural_residual = NaturalResidual(z, w);
  if (!Acceptable(z, w, options.feasibility)) {
    out.reason = "inaccurate solution (natural residual " + std::to_string(out.natural_residual) +
                 ") after " + std::to_string(pivots) + " pivots";
    return out;
  }
  out.ok = true;
  out.z = z;
  out.w = w;
  return out;
}

}  // namespace arena::mechanics
