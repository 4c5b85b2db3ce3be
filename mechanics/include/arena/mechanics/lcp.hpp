// Linear complementarity problems: find z >= 0 with w = A z + b >= 0 and
// z_i w_i = 0. Solved by Lemke's complementary pivoting (lexicographic ratio
// test against cycling on degenerate problems), with a bounded pivot count
// per run, an optional warm start from a previous basis, and a few runs with
// other covering vectors when a run ends on a ray (the contact LCP is
// copositive but not copositive-plus, so one run is not guaranteed). The model (model.hpp) hands it
// nondimensional problems, so the tolerances here are relative by construction.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace arena::mechanics {

struct LcpOptions {
  int max_pivots = 0;              // 0: 50 n + 200
  double pivot_tolerance = 1e-12;  // smallest usable pivot (nondimensional)
  double feasibility = 1e-9;       // accepted negativity of z, w (nondimensional)
  Eigen::VectorXd covering;   // Lemke's covering vector (> 0); empty: a fixed generic one (lcp.cpp)
  int covering_attempts = 8;  // runs with other covering vectors after a failed one
  int first_covering = 0;     // 0: start with `covering`; k > 0: with the k-th alternative
};

// Why a solve ended, for code (reason has the words and the numbers).
enum class LcpStatus {
  kOk,
  kSingularBasis,      // the basis could not be factorised
  kPivotLimit,         // max_pivots reached
  kRayTermination,     // Lemke's method ended on a secondary ray
  kNonFiniteSolution,  // z or w not finite
  kInaccurate,         // complementarity residual above feasibility
  kBadProblem,         // sizes differ or non-finite data
};
const char* ToString(LcpStatus status);

struct LcpResult {
  bool ok = false;
  LcpStatus status = LcpStatus::kBadProblem;  // kOk exactly when ok
  std::string reason;                         // why not ok: "pivot limit", "ray termination", ...
  Eigen::VectorXd z;
  Eigen::VectorXd w;             // A z + b
  std::vector<char> basis;       // basis[i] != 0: z_i is basic (a warm start for the next solve)
  int pivots = 0;                // Lemke pivots over all runs (0: trivial or warm-started)
  bool warm_start_used = false;  // the previous basis solved the problem directly
  double natural_residual = 0;   // max_i |min(z_i, w_i)|
};

// The matrix of an LCP, read column by column. A solve touches only the
// columns of the variables it makes basic (a warm-started solve: those of its
// basis), so a caller whose matrix is costly to form whole (the contact
// model's: hundreds of unknowns, a few dozen basic) forms columns on demand.
class LcpColumns {
 public:
  virtual ~LcpColumns() = default;
  virtual Eigen::Index size() const = 0;
  // Column j (size() entries), valid until the solve returns.
  virtual const double* Column(Eigen::Index j) const = 0;
  // Whether every entry is finite (asked once, before solving).
  virtual bool AllFinite() const = 0;
  // A(idx, idx) into `block` (idx.size() square): the basis of a warm-started
  // solve. The default reads Column(); a matrix with structure (the planar
  // contact model's rank-3 force block) can form just these entries.
  virtual void GatherBasis(const std::vector<Eigen::Index>& idx, Eigen::MatrixXd& block) const;
  // w = A z. The default is MultiplyColumns (below); a structured matrix may
  // sum in another order (then not bit for bit the dense product).
  virtual void Multiply(const Eigen::VectorXd& z, Eigen::VectorXd& w) const;
  // Solves A(idx, idx) x = rhs with the matrix's own structure (the planar
  // contact model: its rank-3 force block bordered by the 3 reduced
  // coordinates, a sparse system). False when it has none or its answer is
  // not accurate enough; the solver then factorises the gathered block.
  virtual bool SolveBasisBlock(const std::vector<Eigen::Index>& idx, const Eigen::VectorXd& rhs,
                               Eigen::VectorXd& x) const;
};

// Never throws; never returns non-finite z or w when ok.
// warm_basis: the basis of a previous solve of a problem of the same size
// (may be null or empty).
LcpResult SolveLcp(const Eigen::MatrixXd& A, const Eigen::VectorXd& b,
                   const std::vector<char>* warm_basis = nullptr, const LcpOptions& options = {});
// The same on a matrix given by columns: the same arithmetic, so the same
// answer to the last bit as the dense call on the same entries.
LcpResult SolveLcp(const LcpColumns& A, const Eigen::VectorXd& b,
                   const std::vector<char>* warm_basis = nullptr, const LcpOptions& options = {});

// The same into `out`, whose vectors keep their storage from one solve to
// the next (a caller solving every time step allocates nothing on a
// warm-started step).
void SolveLcp(const LcpColumns& A, const Eigen::VectorXd& b, const std::vector<char>* warm_basis,
              const LcpOptions& options, LcpResult& out);

// w = A z, summed as Eigen's dense column-major product sums it (columns in
// blocks, each block's terms in column order from zero), skipping columns
// where z is zero (they add exact zeros): bit for bit the dense A * z.
void MultiplyColumns(const LcpColumns& A, const Eigen::VectorXd& z, Eigen::VectorXd& w);

}  // namespace arena::mechanics
