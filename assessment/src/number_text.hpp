// How the room writes a number into a reason a person reads (private).
#pragma once

#include <cstdio>
#include <string>

namespace arena::assessment::internal {

// Four significant digits ("%.4g"): 0.0002, 1.235e+04.
inline std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

}  // namespace arena::assessment::internal
