// The Lemke solver on problems with known answers, degenerate ties, and
// the failures it must report instead of hanging or returning NaN.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/LU>

#include "arena/mechanics/lcp.hpp"
#include "arena/mechanics/model.hpp"
#include "extremes_suite.hpp"

namespace arena::mechanics {
namespace {

void ExpectSolution(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, const LcpResult& r,
                    double tol = 1e-12) {
  ASSERT_TRUE(r.ok) << r.reason;
  const Eigen::VectorXd w = A * r.z + b;
  for (Eigen::Index i = 0; i < b.size(); ++i) {
    EXPECT_GE(r.z[i], -tol);
    EXPECT_GE(w[i], -tol);
    EXPECT_LE(std::abs(r.z[i] * w[i]), tol);
  }
}

TEST(Lemke, SolvesKnownTwoByTwo) {
  Eigen::MatrixXd A(2, 2);
  A << 2, 1, 1, 2;
  Eigen::VectorXd b(2);
  b << -5, -6;
  const LcpResult r = SolveLcp(A, b);
  ExpectSolution(A, b, r);
  EXPECT_EQ(r.status, LcpStatus::kOk);
  EXPECT_NEAR(r.z[0], 4.0 / 3.0, 1e-14);
  EXPECT_NEAR(r.z[1], 7.0 / 3.0, 1e-14);
}

TEST(Lemke, NonnegativeDataNeedsNoPivot) {
  const Eigen::MatrixXd A = Eigen::MatrixXd::Identity(3, 3);
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(3);
  const LcpResult r = SolveLcp(A, b);
  ExpectSolution(A, b, r);
  EXPECT_EQ(r.pivots, 0);
  EXPECT_EQ(r.status, LcpStatus::kOk);
  EXPECT_EQ(r.z.norm(), 0.0);
}

TEST(Lemke, DegenerateTiesAreResolved) {
  // Every first-step ratio ties and the matrix is singular.
  const Eigen::MatrixXd A = Eigen::MatrixXd::Ones(4, 4);
  const Eigen::VectorXd b = -Eigen::VectorXd::Ones(4);
  const LcpResult r = SolveLcp(A, b);
  ExpectSolution(A, b, r);
  EXPECT_NEAR(r.z.sum(), 1.0, 1e-12);
}

TEST(Lemke, InfeasibleProblemEndsOnARay) {
  Eigen::MatrixXd A(1, 1);
  A << -1;
  Eigen::VectorXd b(1);
  b << -1;
  const LcpResult r = SolveLcp(A, b);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.reason.find("ray termination"), std::string::npos) << r.reason;
  EXPECT_EQ(r.status, LcpStatus::kRayTermination);  // typed: nobody parses the reason
}

TEST(Lemke, NonFiniteDataIsRefused) {
  Eigen::MatrixXd A = Eigen::MatrixXd::Identity(2, 2);
  A(0, 1) = std::numeric_limits<double>::quiet_NaN();
  const Eigen::VectorXd b = -Eigen::VectorXd::Ones(2);
  const LcpResult r = SolveLcp(A, b);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.reason.find("non-finite"), std::string::npos) << r.reason;
}

TEST(Lemke, PivotLimitIsReported) {
  std::mt19937 rng(3);
  std::normal_distribution<double> N;
  const int n = 20;
  Eigen::MatrixXd B(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) B(i, j) = N(rng);
  const Eigen::MatrixXd A = B.transpose() * B + Eigen::MatrixXd::Identity(n, n);
  const Eigen::VectorXd b = -Eigen::VectorXd::Ones(n);
  LcpOptions opt;
  opt.max_pivots = 2;
  const LcpResult r = SolveLcp(A, b, nullptr, opt);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.reason.find("pivot limit"), std::string::npos) << r.reason;
}

// Random monotone problems (PSD plus skew part, like a frictionless contact
// problem with bilateral terms) all solve, and a warm start from the
// solution's basis solves the same problem without pivoting.
TEST(Lemke, RandomMonotoneProblemsAndWarmStart) {
  std::mt19937 rng(7);
  std::normal_distribution<double> N;
  for (int trial = 0; trial < 200; ++trial) {
    const int n = 2 + trial % 40;
    Eigen::MatrixXd B(n, n), S(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        B(i, j) = N(rng);
        S(i, j) = N(rng);
      }
    const Eigen::MatrixXd A =
        B.transpose() * B + 0.01 * Eigen::MatrixXd::Identity(n, n) + (S - S.transpose());
    Eigen::VectorXd b(n);
    for (int i = 0; i < n; ++i) b[i] = N(rng);
    const LcpResult r = SolveLcp(A, b);
    ExpectSolution(A, b, r, 1e-8);
    const LcpResult warm = SolveLcp(A, b, &r.basis);
    ExpectSolution(A, b, warm, 1e-8);
    if (b.minCoeff() < 0) {
      EXPECT_TRUE(warm.warm_start_used);
      EXPECT_EQ(warm.pivots, 0);
    }
  }
}

// A matrix handed over by columns, which counts the columns read (the
// contact model forms its columns on demand: lcp.hpp, LcpColumns).
class CountingColumns final : public LcpColumns {
 public:
  explicit CountingColumns(const Eigen::MatrixXd& A)
      : A_(A), read_(Eigen::VectorXi::Zero(A.cols())) {}
  Eigen::Index size() const override { return A_.rows(); }
  const double* Column(Eigen::Index j) const override {
    read_[j] = 1;
    return A_.data() + j * A_.rows();
  }
  bool AllFinite() const override { return A_.allFinite(); }
  long read() const { return read_.sum(); }

 private:
  const Eigen::MatrixXd& A_;
  mutable Eigen::VectorXi read_;
};

bool SameBits(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<size_t>(a.size())) == 0;
}

// MultiplyColumns sums as Eigen's dense product does (one block below 128
// columns, blocks of 16 above), so skipping the zero entries of z changes no
// bit; solving through columns gives the dense solve's z and w exactly, and a
// warm-started solve reads only the basic columns.
TEST(Lemke, ColumnsGiveTheDenseAnswerBitForBit) {
  std::mt19937 rng(11);
  std::normal_distribution<double> N;
  for (int n : {3, 40, 127, 128, 200, 650}) {
    Eigen::MatrixXd B(n, n), S(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        B(i, j) = N(rng);
        S(i, j) = N(rng);
      }
    const Eigen::MatrixXd A =
        B.transpose() * B / n + 0.01 * Eigen::MatrixXd::Identity(n, n) + (S - S.transpose());
    Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
    for (int i = 0; i < n; i += 3) z[i] = N(rng);  // mostly zero, as a basic solution is
    Eigen::VectorXd w;
    MultiplyColumns(CountingColumns(A), z, w);
    const Eigen::VectorXd dense = A * z;
    EXPECT_TRUE(SameBits(w, dense)) << "n = " << n;

    Eigen::VectorXd b(n);
    for (int i = 0; i < n; ++i) b[i] = N(rng);
    const LcpResult d = SolveLcp(A, b);
    const CountingColumns cold(A);
    const LcpResult c = SolveLcp(cold, b);
    ASSERT_TRUE(d.ok && c.ok) << d.reason << c.reason;
    EXPECT_TRUE(SameBits(d.z, c.z)) << "n = " << n;
    EXPECT_TRUE(SameBits(d.w, c.w)) << "n = " << n;
    EXPECT_EQ(d.pivots, c.pivots);
    const CountingColumns warm(A);
    const LcpResult again = SolveLcp(warm, b, &c.basis);
    ASSERT_TRUE(again.warm_start_used);
    long basic = 0;
    for (char x : c.basis) basic += x;
    EXPECT_EQ(warm.read(), basic) << "n = " << n;
  }
}

// A warm-started solve factorises its basis with lcp.cpp's own small LU
// (BasisLu): Eigen's unblocked algorithm and triangular solves written out,
// so up to 16 basic unknowns the answer must be Eigen's PartialPivLU answer
// (with the one refinement step SolveBasis takes) to the last bit; beyond
// that it is Eigen's own (checked to the bit as well). Problems are made with a chosen basis: z > 0
// on it, w > 0 off it; the matrices have the contact LCP's exact ties (entries ±1, 0.3, 0) so the
// pivot choice between equal magnitudes is exercised.
TEST(Lemke, WarmBasisSolveMatchesEigensLu) {
  std::mt19937 rng(23);
  std::normal_distribution<double> N;
  std::uniform_int_distribution<int> kind(0, 5);
  int small = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const int m = 1 + trial % 40;
    const int n = m + 1 + trial % 7;
    Eigen::MatrixXd A(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const int k = kind(rng);
        A(i, j) = k == 0 ? 0.0 : k == 1 ? 1.0 : k == 2 ? -1.0 : k == 3 ? 0.3 : N(rng);
      }
    A.diagonal().array() += 4.0;  // keep the bases well away from singular
    std::vector<char> basis(static_cast<size_t>(n), 0);
    std::vector<int> order(static_cast<size_t>(n));
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), rng);
    for (int i = 0; i < m; ++i) basis[static_cast<size_t>(order[static_cast<size_t>(i)])] = 1;
    Eigen::VectorXd z = Eigen::VectorXd::Zero(n), w = Eigen::VectorXd::Zero(n);
    for (int i = 0; i < n; ++i)
      (basis[static_cast<size_t>(i)] ? z[i] : w[i]) = 0.5 + N(rng) * N(rng);
    z = z.cwiseAbs();
    w = w.cwiseAbs();
    const Eigen::VectorXd b = w - A * z;
    if (b.minCoeff() >= 0) continue;  // trivial: solved without the basis
    const LcpResult r = SolveLcp(A, b, &basis);
    ASSERT_TRUE(r.ok && r.warm_start_used) << "m = " << m << ": " << r.reason;

    std::vector<Eigen::Index> idx;
    for (int i = 0; i < n; ++i)
      if (basis[static_cast<size_t>(i)]) idx.push_back(i);
    Eigen::MatrixXd Abb(m, m);
    Eigen::VectorXd bb(m);
    for (int c = 0; c < m; ++c) {
      bb[c] = -b[idx[static_cast<size_t>(c)]];
      for (int q = 0; q < m; ++q)
        Abb(q, c) = A(idx[static_cast<size_t>(q)], idx[static_cast<size_t>(c)]);
    }
    const Eigen::PartialPivLU<Eigen::MatrixXd> lu(Abb);
    Eigen::VectorXd zb = lu.solve(bb);
    zb += lu.solve(bb - Abb * zb);
    for (int c = 0; c < m; ++c) {
      const double got = r.z[idx[static_cast<size_t>(c)]];
      EXPECT_EQ(std::memcmp(&got, &zb[c], sizeof got), 0)
          << "m = " << m << ": " << got << " vs " << zb[c];
    }
    if (m <= 16) ++small;
  }
  EXPECT_GT(small, 100);  // the bit-for-bit range really ran
}

// The contact LCPs of a 3x3-patch scene (n = 194; bench/README.md "LCP
// solvers"): every one is solved by the first Lemke run (no covering-vector
// retry), cold, to the benchmark's accuracy, with the user's all-ones
// covering vector still accepted. Guards the default generic covering vector
// (all ones tied the symmetric patch rows: half these runs ended on a ray)
// and the structured basis updates (lcp.cpp).
TEST(Lemke, PatchContactProblemsSolveInOneRun) {
  Scene s = testing::PatchScene();
  s.duration = 0.1;
  s.model.points = 9;
  std::vector<std::pair<Eigen::MatrixXd, Eigen::VectorXd>> problems;
  ContactModel model(s);
  ASSERT_EQ(model.status(), SimulationStatus::kOk) << model.error();
  model.SetLcpObserver(
      [&](const Eigen::MatrixXd& A, const Eigen::VectorXd& b) { problems.emplace_back(A, b); });
  for (int i = 0; i < 25; ++i) ASSERT_TRUE(model.Step().ok);
  // At least one solve a step; the held patch's quasi-static steps (the
  // default since issue 31) add a balance's re-solves.
  ASSERT_GE(problems.size(), 25u);
  LcpOptions one_run;
  one_run.covering_attempts = 1;
  for (const auto& [A, b] : problems) {
    ASSERT_EQ(b.size(), 194);
    const LcpResult r = SolveLcp(A, b, nullptr, one_run);
    ASSERT_TRUE(r.ok) << r.reason;
    const Eigen::VectorXd w = A * r.z + b;
    EXPECT_LE(r.z.cwiseMin(w).cwiseAbs().maxCoeff(), 1e-8 * (1 + b.cwiseAbs().maxCoeff()));
    EXPECT_LT(r.pivots, 50 * 194 + 200);
    LcpOptions ones;
    ones.covering = Eigen::VectorXd::Ones(b.size());
    const LcpResult u = SolveLcp(A, b, nullptr, ones);  // with its retries
    ASSERT_TRUE(u.ok) << u.reason;
  }
}

}  // namespace
}  // namespace arena::mechanics
