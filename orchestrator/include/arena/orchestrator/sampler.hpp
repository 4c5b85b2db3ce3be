// Deterministic, index-addressable samplers of the unit hypercube.
//
// Every function is pure: the value for index i depends only on its
// arguments, never on which indices were drawn before. That is what makes a
// campaign resumable from one stored integer (PlanTrial in campaign.hpp).
//
//   uniform          counter-based: SplitMix64 of (seed, dimension, index)
//   latin_hypercube  over n points: dimension d puts point i in stratum
//                    pi_d(i) of n, pi_d a seeded bijection of [0, n) (a
//                    Feistel network with cycle walking, O(1) per point), and
//                    jitters it inside the stratum
//   sobol            Joe-Kuo (new-joe-kuo-6.21201) direction numbers, with
//                    hash-based Owen scrambling (Burley 2020) keyed by seed
//                    and dimension; unscrambled dimension 0 is van der Corput
//   grid             mixed-radix digits of the index (campaign.cpp)
#pragma once

#include <cstdint>

namespace arena::orchestrator {

inline constexpr int kMaxSobolDimensions = 22;

// A 64-bit mix (SplitMix64 finaliser): a bijection with good avalanche.
uint64_t Mix64(uint64_t x);

// Uniform in [0, 1) from a key and a counter (53 random bits).
double UniformFromCounter(uint64_t key, uint64_t counter);

// A seeded bijection of [0, n): permutation of index i. @pre i < n.
uint64_t PermuteIndex(uint64_t i, uint64_t n, uint64_t key);

// Latin hypercube coordinate of point i of n in dimension `dim`.
double LatinHypercubeCoordinate(uint64_t i, uint64_t n, int dim, uint64_t seed);

// Unscrambled Sobol coordinate (32-bit), dim in [0, kMaxSobolDimensions).
double SobolCoordinate(uint32_t index, int dim);

// Owen-scrambled Sobol coordinate: each seed gives a randomised (0,m,s)-net
// that keeps Sobol's stratification.
double ScrambledSobolCoordinate(uint32_t index, int dim, uint64_t seed);

}  // namespace arena::orchestrator
