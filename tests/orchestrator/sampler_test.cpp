// Properties of the index-addressable samplers: bijections, Latin hypercube
// stratification, Sobol's net structure (with and without scrambling),
// uniformity, and independence from the order of drawing.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "arena/orchestrator/sampler.hpp"

namespace arena::orchestrator {
namespace {

TEST(Sampler, PermuteIndexIsABijection) {
  for (uint64_t n : {1ULL, 2ULL, 3ULL, 7ULL, 64ULL, 100ULL, 1000ULL, 4097ULL}) {
    for (uint64_t key : {0ULL, 1ULL, 0xdeadbeefULL}) {
      std::vector<bool> seen(n, false);
      for (uint64_t i = 0; i < n; ++i) {
        const uint64_t p = PermuteIndex(i, n, key);
        ASSERT_LT(p, n);
        ASSERT_FALSE(seen[p]) << "n=" << n << " i=" << i;
        seen[p] = true;
      }
    }
  }
  EXPECT_THROW(PermuteIndex(5, 5, 0), std::out_of_range);
}

TEST(Sampler, PermuteIndexDependsOnKey) {
  int same = 0;
  for (uint64_t i = 0; i < 1000; ++i) same += PermuteIndex(i, 1000, 1) == PermuteIndex(i, 1000, 2);
  EXPECT_LT(same, 20);
}

TEST(Sampler, LatinHypercubeHasOnePointPerStratumInEveryDimension) {
  for (uint64_t n : {1ULL, 5ULL, 64ULL, 1000ULL}) {
    for (int dim = 0; dim < 6; ++dim) {
      std::vector<int> count(n, 0);
      for (uint64_t i = 0; i < n; ++i) {
        const double u = LatinHypercubeCoordinate(i, n, dim, 42);
        ASSERT_GE(u, 0.0);
        ASSERT_LT(u, 1.0);
        ++count[static_cast<size_t>(u * static_cast<double>(n))];
      }
      EXPECT_TRUE(std::all_of(count.begin(), count.end(), [](int c) { return c == 1; }))
          << "n=" << n << " dim=" << dim;
    }
  }
}

TEST(Sampler, LatinHypercubeDimensionsAreNotAligned) {
  const uint64_t n = 256;
  int same = 0;
  for (uint64_t i = 0; i < n; ++i) {
    same += std::floor(LatinHypercubeCoordinate(i, n, 0, 7) * n) ==
            std::floor(LatinHypercubeCoordinate(i, n, 1, 7) * n);
  }
  EXPECT_LT(same, 10);
}

TEST(Sampler, SobolFirstDimensionIsVanDerCorput) {
  const double expected[] = {0, 0.5, 0.25, 0.75, 0.125, 0.625, 0.375, 0.875, 0.0625, 0.5625};
  for (uint32_t i = 0; i < 10; ++i) EXPECT_EQ(SobolCoordinate(i, 0), expected[i]) << i;
  // Radical inverse in base 2 in general.
  for (uint32_t i = 0; i < 5000; i += 37) {
    double v = 0, f = 0.5;
    for (uint32_t j = i; j != 0; j >>= 1, f /= 2) v += (j & 1u) * f;
    EXPECT_EQ(SobolCoordinate(i, 0), v) << i;
  }
}

// Natural (not Gray-code) order: point i is the XOR of the direction numbers
// of i's set bits. For dimension 1 (x^2 + x + 1): v = 1/2, 3/4, 5/8, 15/16.
TEST(Sampler, SobolSecondDimensionMatchesTheKnownSequence) {
  const double expected[] = {0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875};
  for (uint32_t i = 0; i < 8; ++i) EXPECT_EQ(SobolCoordinate(i, 1), expected[i]) << i;
}

// The first 2^m points of a Sobol sequence put exactly 2^(m-k) points in each
// dyadic interval of length 2^-k, in every dimension; Owen scrambling keeps it.
void ExpectStratified(bool scrambled) {
  const int m = 10;
  const uint32_t n = 1u << m;
  for (int dim = 0; dim < kMaxSobolDimensions; ++dim) {
    for (int k : {1, 4, m}) {
      std::vector<int> count(1u << k, 0);
      for (uint32_t i = 0; i < n; ++i) {
        const double u = scrambled ? ScrambledSobolCoordinate(i, dim, 99) : SobolCoordinate(i, dim);
        ASSERT_GE(u, 0.0);
        ASSERT_LT(u, 1.0);
        ++count[static_cast<size_t>(u * (1u << k))];
      }
      const int per = static_cast<int>(n >> k);
      EXPECT_TRUE(std::all_of(count.begin(), count.end(), [per](int c) { return c == per; }))
          << "dim=" << dim << " k=" << k;
    }
  }
}

TEST(Sampler, SobolIsStratifiedInEveryDimension) { ExpectStratified(false); }
TEST(Sampler, ScrambledSobolKeepsTheStratification) { ExpectStratified(true); }

// Dimensions 0 and 1 of Sobol form a (0, m, 2)-net: every dyadic box of area
// 2^-m holds exactly one of the first 2^m points.
TEST(Sampler, SobolFirstTwoDimensionsFormA0m2Net) {
  const int m = 8;
  const uint32_t n = 1u << m;
  for (bool scrambled : {false, true}) {
    for (int a = 0; a <= m; ++a) {
      std::vector<int> count(n, 0);
      for (uint32_t i = 0; i < n; ++i) {
        const double x = scrambled ? ScrambledSobolCoordinate(i, 0, 5) : SobolCoordinate(i, 0);
        const double y = scrambled ? ScrambledSobolCoordinate(i, 1, 5) : SobolCoordinate(i, 1);
        const auto bx = static_cast<uint32_t>(x * (1u << a));
        const auto by = static_cast<uint32_t>(y * (1u << (m - a)));
        ++count[(bx << (m - a)) | by];
      }
      EXPECT_TRUE(std::all_of(count.begin(), count.end(), [](int c) { return c == 1; }))
          << "a=" << a << " scrambled=" << scrambled;
    }
  }
}

// Low discrepancy, loosely: the mean of a smooth function converges much
// faster than Monte Carlo's 1/sqrt(n).
TEST(Sampler, SobolIntegratesBetterThanRandom) {
  const uint32_t n = 4096;
  double sobol = 0, random = 0;
  for (uint32_t i = 0; i < n; ++i) {
    double fs = 1, fr = 1;
    for (int d = 0; d < 5; ++d) {
      fs *= 2 * ScrambledSobolCoordinate(i, d, 3);
      fr *= 2 * UniformFromCounter(3 + static_cast<uint64_t>(d), i);
    }
    sobol += fs;  // integral of prod(2 u_d) over the cube is 1
    random += fr;
  }
  EXPECT_LT(std::abs(sobol / n - 1), 0.01);
  EXPECT_LT(std::abs(sobol / n - 1), std::abs(random / n - 1) + 1e-3);
}

TEST(Sampler, ScrambledSobolDependsOnSeed) {
  EXPECT_NE(ScrambledSobolCoordinate(1, 0, 1), ScrambledSobolCoordinate(1, 0, 2));
  EXPECT_EQ(ScrambledSobolCoordinate(1, 3, 1), ScrambledSobolCoordinate(1, 3, 1));
}

TEST(Sampler, UniformCounterIsUniformAndOrderFree) {
  const int n = 20000;
  std::vector<int> bins(10, 0);
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double u = UniformFromCounter(77, static_cast<uint64_t>(i));
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    sum += u;
    ++bins[static_cast<size_t>(u * 10)];
  }
  EXPECT_NEAR(sum / n, 0.5, 0.01);
  for (int b : bins) EXPECT_NEAR(b, n / 10, 200);
  // The value at a counter does not depend on what was drawn before.
  EXPECT_EQ(UniformFromCounter(77, 12345), UniformFromCounter(77, 12345));
}

}  // namespace
}  // namespace arena::orchestrator
