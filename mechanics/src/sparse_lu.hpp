// A small sparse LU for systems that repeat their sparsity pattern step
// after step: the planar contact model's warm-started basis, bordered with
// its 3 reduced coordinates (model.cpp, StepMatrix::SolveBasisBlock).
//
// The elimination order is chosen once per pattern (Markowitz counts with
// threshold partial pivoting on the values of the step that planned it) and
// replayed on later values with the fill it predicted; a few plans are kept,
// since a grasp's basis flips between a handful of patterns (stick, slip).
// A replayed pivot that has become small against its column is a new plan;
// a matrix no plan can factorise is refused (Solve returns false) and the
// caller solves it densely.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace arena::mechanics {

class SmallSparseLu {
 public:
  static constexpr int kMaxSize = 64;

  // Starts a matrix of n x n (n <= kMaxSize) with no entries.
  void Clear(int n);
  // Adds value at (row, col), both below the n of Clear() (and so below
  // kMaxSize: Factor() refuses a larger n); the position is structural even when the
  // value is zero (a grasp-map entry that vanishes at one pose), so the
  // pattern, and the plan, stay the same from step to step.
  void Add(int row, int col, double value) {
    bits_[static_cast<std::size_t>(row)] |= std::uint64_t{1} << col;
    entries_.push_back(Entry{row, col, value});
  }
  // Factorises the matrix given since Clear(). False when no elimination
  // order gives pivots that pass the threshold (singular or nearly so).
  bool Factor();
  // x = M⁻¹ rhs with the factors (n entries each; x may not alias rhs).
  void Solve(const double* rhs, double* x) const;
  // r = rhs - M x, from the entries as given.
  void Residual(const double* rhs, const double* x, double* r) const;
  int size() const { return n_; }

 private:
  struct Entry {
    int row = 0, col = 0;
    double value = 0;
  };
  using Pattern = std::array<std::uint64_t, kMaxSize>;
  // One elimination step: pivot (row, col), the rows below it with an entry
  // in its column (rows[r0, r1)) and its row's columns not yet eliminated
  // (cols[c0, c1)).
  struct Elimination {
    int row = 0, col = 0, r0 = 0, r1 = 0, c0 = 0, c1 = 0;
  };
  struct Plan {
    int n = 0;
    Pattern pattern{};
    std::vector<Elimination> steps;
    std::vector<int> rows, cols;
    std::vector<int> filled;  // every position of the factors, r * kMaxSize + c
    std::uint64_t last_used = 0;
  };
  bool BuildPlan(Plan& plan) const;
  bool Replay(const Plan& plan);

  static constexpr std::size_t kPlans = 6;
  int n_ = 0;
  Pattern bits_{};
  std::vector<Entry> entries_;
  std::vector<Plan> plans_;
  const Plan* active_ = nullptr;
  std::size_t last_ = 0;  // the plan used last
  std::uint64_t clock_ = 0;
  std::array<double, kMaxSize * kMaxSize> a_{};  // factors, row-major, stride kMaxSize
};

}  // namespace arena::mechanics
