// Index-addressable samplers (see sampler.hpp for the design).
#include "arena/orchestrator/sampler.hpp"

#include <array>
#include <bit>
#include <cmath>
#include <stdexcept>
#include <string>

namespace arena::orchestrator {

uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

double UniformFromCounter(uint64_t key, uint64_t counter) {
  const uint64_t bits = Mix64(Mix64(key) ^ Mix64(counter ^ 0x243f6a8885a308d3ULL));
  return static_cast<double>(bits >> 11) * 0x1.0p-53;
}

uint64_t PermuteIndex(uint64_t i, uint64_t n, uint64_t key) {
  if (i >= n)
    throw std::out_of_range("PermuteIndex: index " + std::to_string(i) + " >= n " +
                            std::to_string(n));
  if (n <= 1) return 0;
  // A balanced Feistel network is a bijection of [0, 4^half); walking the
  // cycle until we land below n restricts it to a bijection of [0, n).
  const int bits = 64 - std::countl_zero(n - 1);
  const int half = (bits + 1) / 2;
  const uint64_t mask = (uint64_t{1} << half) - 1;
  uint64_t x = i;
  do {
    uint64_t left = x >> half;
    uint64_t right = x & mask;
    for (uint64_t round = 0; round < 4; ++round) {
      const uint64_t f = Mix64(right ^ Mix64(key + round)) & mask;
      const uint64_t next_right = left ^ f;
      left = right;
      right = next_right;
    }
    x = (left << half) | right;
  } while (x >= n);
  return x;
}

double LatinHypercubeCoordinate(uint64_t i, uint64_t n, int dim, uint64_t seed) {
  const uint64_t dim_key = Mix64(seed ^ Mix64(0x1a7e000ULL + static_cast<uint64_t>(dim)));
  const uint64_t stratum = PermuteIndex(i, n, dim_key);
  const double jitter = UniformFromCounter(dim_key ^ 0x6a09e667f3bcc908ULL, i);
  const double u = (static_cast<double>(stratum) + jitter) / static_cast<double>(n);
  return u < 1.0 ? u : std::nextafter(1.0, 0.0);
}

namespace {

// Joe & Kuo (2008), new-joe-kuo-6.21201, dimensions 2..22 (our dims 1..21):
// degree s, coefficients a, initial direction numbers m_1..m_s.
struct SobolPolynomial {
  int s;
  uint32_t a;
  std::array<uint32_t, 7> m;
};
constexpr std::array<SobolPolynomial, kMaxSobolDimensions - 1> kJoeKuo = {{
    {1, 0, {1}},
    {2, 1, {1, 3}},
    {3, 1, {1, 3, 1}},
    {3, 2, {1, 1, 1}},
    {4, 1, {1, 1, 3, 3}},
    {4, 4, {1, 3, 5, 13}},
    {5, 2, {1, 1, 5, 5, 17}},
    {5, 4, {1, 1, 5, 5, 5}},
    {5, 7, {1, 1, 7, 11, 19}},
    {5, 11, {1, 1, 5, 1, 1}},
    {5, 13, {1, 1, 1, 3, 11}},
    {5, 14, {1, 3, 5, 5, 31}},
    {6, 1, {1, 3, 3, 9, 7, 49}},
    {6, 13, {1, 1, 1, 15, 21, 21}},
    {6, 16, {1, 3, 1, 13, 27, 49}},
    {6, 19, {1, 1, 1, 15, 7, 5}},
    {6, 22, {1, 3, 1, 15, 13, 25}},
    {6, 25, {1, 1, 5, 5, 19, 61}},
    {7, 1, {1, 3, 7, 11, 23, 15, 103}},
    {7, 4, {1, 3, 7, 13, 13, 15, 69}},
    {7, 7, {1, 1, 3, 13, 7, 35, 63}},
}};

using Directions = std::array<uint32_t, 32>;  // v[k]: bit k of the index

std::array<Directions, kMaxSobolDimensions> MakeDirections() {
  std::array<Directions, kMaxSobolDimensions> out{};
  for (int k = 0; k < 32; ++k) out[0][k] = uint32_t{1} << (31 - k);  // van der Corput
  for (int d = 1; d < kMaxSobolDimensions; ++d) {
    const SobolPolynomial& p = kJoeKuo[d - 1];
    Directions& v = out[d];
    for (int k = 0; k < p.s && k < 32; ++k) v[k] = p.m[k] << (31 - k);
    for (int k = p.s; k < 32; ++k) {
      uint32_t x = v[k - p.s] ^ (v[k - p.s] >> p.s);
      for (int j = 1; j < p.s; ++j) {
        if ((p.a >> (p.s - 1 - j)) & 1u) x ^= v[k - j];
      }
      v[k] = x;
    }
  }
  return out;
}

const std::array<Directions, kMaxSobolDimensions>& SobolDirections() {
  static const auto directions = MakeDirections();  // thread-safe static init
  return directions;
}

uint32_t SobolBits(uint32_t index, int dim) {
  if (dim < 0 || dim >= kMaxSobolDimensions) {
    throw std::out_of_range("SobolCoordinate: dimension " + std::to_string(dim) + " not in [0, " +
                            std::to_string(kMaxSobolDimensions) + ")");
  }
  const Directions& v = SobolDirections()[dim];
  uint32_t x = 0;
  for (int k = 0; index != 0; ++k, index >>= 1) {
    if (index & 1u) x ^= v[k];
  }
  return x;
}

uint32_t ReverseBits(uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
  return (x >> 16) | (x << 16);
}

// Burley, "Practical Hash-based Owen Scrambling" (JCGT 2020): on the
// bit-reversed value, a permutation where each bit depends only on lower
// bits is a nested uniform (Owen) scramble of the original.
uint32_t OwenScramble(uint32_t x, uint32_t seed) {
  x = ReverseBits(x);
  x += seed;
  x ^= x * 0x6c50b47cu;
  x ^= x * 0xb82f1e52u;
  x ^= x * 0xc7afe638u;
  x ^= x * 0x8d22f6e6u;
  return ReverseBits(x);
}

}  // namespace

double SobolCoordinate(uint32_t index, int dim) { return SobolBits(index, dim) * 0x1.0p-32; }

double ScrambledSobolCoordinate(uint32_t index, int dim, uint64_t seed) {
  const uint32_t key =
      static_cast<uint32_t>(Mix64(seed ^ Mix64(0x50b01ULL + static_cast<uint64_t>(dim))));
  return OwenScramble(SobolBits(index, dim), key) * 0x1.0p-32;
}

}  // namespace arena::orchestrator
