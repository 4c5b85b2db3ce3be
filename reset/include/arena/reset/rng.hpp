// Deterministic random streams: every stream is derived from (seed, trial id,
// purpose), never from time, so the same trial, seed and profile reproduce
// bit for bit on any platform (own generator and own normal transform; the
// standard library's distributions differ between implementations).
#pragma once

#include <cmath>
#include <cstdint>

namespace arena::reset {

// What a stream is for; a new purpose gets a new value, never a reused one.
enum class StreamPurpose : std::uint64_t {
  kPoseNoise = 1,
  kForceTorqueNoise = 2,
  kDrops = 3,
  kActuation = 4,
  kFriction = 5,
  kReset = 6,      // a reset's slips (which attempt fails, during which primitive)
  kPlacement = 7,  // where a reset's placements end and what verification sees (keyed
                   // by the prepared trial's seed alone, trial id 0: reset.hpp)
};

class Rng {
 public:
  Rng(std::uint64_t seed, std::uint64_t trial_id, StreamPurpose purpose) {
    std::uint64_t x = seed;
    x = Mix(x ^ Mix(trial_id + 0x9e3779b97f4a7c15ULL));
    x = Mix(x ^ Mix(static_cast<std::uint64_t>(purpose) * 0xbf58476d1ce4e5b9ULL));
    for (auto& s : state_) s = x = Mix(x + 0x9e3779b97f4a7c15ULL);
  }

  // xoshiro256** step.
  std::uint64_t Next() {
    const std::uint64_t result = Rotl(state_[1] * 5, 7) * 9;
    const std::uint64_t t = state_[1] << 17;
    state_[2] ^= state_[0];
    state_[3] ^= state_[1];
    state_[1] ^= state_[2];
    state_[0] ^= state_[3];
    state_[2] ^= t;
    state_[3] = Rotl(state_[3], 45);
    return result;
  }
  // Uniform in [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }
  // Standard normal (Box-Muller, both values used).
  double Normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = Uniform();
    while (u1 <= 0.0) u1 = Uniform();
    const double u2 = Uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * M_PI * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * M_PI * u2);
  }
  double Normal(double std_dev) { return std_dev == 0.0 ? 0.0 : std_dev * Normal(); }

 private:
  static std::uint64_t Rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  static std::uint64_t Mix(std::uint64_t z) {  // SplitMix64 finaliser
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  std::uint64_t state_[4] = {};
  double spare_ = 0;
  bool has_spare_ = false;
};

}  // namespace arena::reset
