// The cell's two clocks (private): the wall clock stamps what it sends, the
// steady clock times its deadlines and leases.
#pragma once

#include <chrono>
#include <cstdint>

namespace arena::executors::internal {

// Nanoseconds since the Unix epoch: the stamp a message carries.
inline std::uint64_t UnixNanos() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

// `s` seconds on the steady clock (StreamClock, CommandIntake::Clock).
inline std::chrono::steady_clock::duration Seconds(double s) {
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(s));
}

}  // namespace arena::executors::internal
