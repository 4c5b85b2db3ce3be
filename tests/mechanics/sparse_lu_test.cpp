// The sparse LU behind the planar basis solve (mechanics/src/sparse_lu.hpp):
// its answers against Eigen's dense LU on the patterns it meets, its plans
// reused and replaced, and singular systems refused rather than solved.
#include "sparse_lu.hpp"

#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Dense>

namespace arena::mechanics {
namespace {

struct Triplet {
  int row, col;
  double value;
};

// A bordered system shaped like the planar basis: m basic rows, the first
// nf of them force rows with 3 grasp-map entries each, a few constants in
// other rows and columns, 3 border rows mass · K - I.
std::vector<Triplet> Bordered(std::mt19937& rng, int m, int nf) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Triplet> t;
  for (int r = 0; r < nf; ++r) {
    for (int k = 0; k < 3; ++k) t.push_back({r, m + k, u(rng)});
    for (int k = 0; k < 3; ++k) t.push_back({m + k, r, 2.0 * u(rng)});
  }
  for (int k = 0; k < 3; ++k) t.push_back({m + k, m + k, -1.0});
  // Friction-like rows: a slack row ties a normal force to its frictions,
  // a friction row gets its slack variable.
  for (int r = nf; r < m; ++r) {
    t.push_back({r, r - nf, 0.5});
    t.push_back({r, (r - nf + 1) % nf, -1.0});
    t.push_back({(r - nf + 1) % nf, r, 1.0});
  }
  return t;
}

Eigen::MatrixXd Dense(const std::vector<Triplet>& t, int n) {
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n, n);
  for (const Triplet& e : t) M(e.row, e.col) += e.value;
  return M;
}

void Load(SmallSparseLu& lu, const std::vector<Triplet>& t, int n) {
  lu.Clear(n);
  for (const Triplet& e : t) lu.Add(e.row, e.col, e.value);
}

TEST(SmallSparseLu, SolvesBorderedSystemsAsTheDenseLuDoes) {
  std::mt19937 rng(7);
  SmallSparseLu lu;
  int solved = 0, invertible = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const int nf = 2 + trial % 9, m = nf + trial % 5, n = m + 3;
    const std::vector<Triplet> t = Bordered(rng, m, nf);
    const Eigen::MatrixXd M = Dense(t, n);
    Eigen::FullPivLU<Eigen::MatrixXd> dense(M);
    Load(lu, t, n);
    const bool ok = lu.Factor();
    if (!dense.isInvertible()) {
      EXPECT_FALSE(ok) << "trial " << trial;
      continue;
    }
    ++invertible;
    // Random data may be invertible but badly conditioned: the sparse LU
    // may refuse those (the caller then solves densely); what it answers
    // must be right.
    if (!ok) continue;
    ++solved;
    Eigen::VectorXd rhs = Eigen::VectorXd::Random(n), x(n), r(n);
    lu.Solve(rhs.data(), x.data());
    const Eigen::VectorXd expected = dense.solve(rhs);
    const double cond = M.norm() * M.inverse().norm();
    EXPECT_LE((x - expected).norm(), 1e-12 * cond * (1 + expected.norm())) << "trial " << trial;
    lu.Residual(rhs.data(), x.data(), r.data());
    EXPECT_NEAR((r - (rhs - M * x)).norm(), 0.0, 1e-12 * (1 + rhs.norm())) << "trial " << trial;
  }
  // (More than m - 3 force rows make many of these singular: rank 3 plus
  // the constants.)
  EXPECT_GE(invertible, 150);
  EXPECT_GE(solved, invertible * 95 / 100);
}

TEST(SmallSparseLu, ReusesAPlanOnNewValuesAndPlansAgainWhenAPivotVanishes) {
  // [[a, 1], [1, 0]] pivots on a while a is large against the column; a plan
  // made there must not divide by a = 0 later: it plans again on the 1s.
  SmallSparseLu lu;
  auto solve = [&](double a, const Eigen::Vector2d& rhs) {
    lu.Clear(2);
    lu.Add(0, 0, a);
    lu.Add(0, 1, 1.0);
    lu.Add(1, 0, 1.0);
    EXPECT_TRUE(lu.Factor()) << "a = " << a;
    Eigen::Vector2d x;
    lu.Solve(rhs.data(), x.data());
    Eigen::Matrix2d M;
    M << a, 1, 1, 0;
    EXPECT_LE((M * x - rhs).norm(), 1e-14) << "a = " << a;
    EXPECT_TRUE(x.allFinite());
  };
  for (double a : {4.0, 3.0, 0.0, 1e-300, 5.0, -2.0, 0.0}) solve(a, Eigen::Vector2d(1.0, -2.0));
}

TEST(SmallSparseLu, RefusesSingularAndOversizedSystems) {
  SmallSparseLu lu;
  // Two equal rows.
  lu.Clear(3);
  for (int c = 0; c < 3; ++c) {
    lu.Add(0, c, 1.0 + c);
    lu.Add(1, c, 1.0 + c);
  }
  lu.Add(2, 2, 1.0);
  EXPECT_FALSE(lu.Factor());
  // A column with no entry at all.
  lu.Clear(2);
  lu.Add(0, 0, 1.0);
  lu.Add(1, 0, 1.0);
  EXPECT_FALSE(lu.Factor());
  // Non-finite data.
  lu.Clear(1);
  lu.Add(0, 0, std::nan(""));
  EXPECT_FALSE(lu.Factor());
  lu.Clear(SmallSparseLu::kMaxSize + 1);
  EXPECT_FALSE(lu.Factor());
}

}  // namespace
}  // namespace arena::mechanics
