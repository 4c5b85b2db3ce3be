// Putting a recording's streams on one clock (recording.hpp: Resample).
#include <algorithm>
#include <cmath>
#include <numeric>

#include "arena/recordings/recording.hpp"

namespace arena::recordings {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct Sorted {
  std::vector<double> t;
  std::vector<std::array<double, 3>> v;
  int out_of_order = 0;  // stamps earlier than the one recorded before them
};

Sorted Sort(const Stream& s, const std::string& file, bool angle) {
  if (s.t.size() != s.values.size())
    throw ImportError(file, s.name + ": " + std::to_string(s.t.size()) + " stamps but " +
                                std::to_string(s.values.size()) + " rows");
  if (s.t.size() < 2) throw ImportError(file, s.name + ": fewer than 2 samples");
  Sorted out;
  for (std::size_t i = 0; i < s.t.size(); ++i) {
    if (!std::isfinite(s.t[i]))
      throw ImportError(file, s.name + ": time stamp " + std::to_string(i) + " is not finite");
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(s.values[i][c]))
        throw ImportError(file, s.name + ": row " + std::to_string(i) + " value " +
                                    std::to_string(c + 1) + " is NaN or infinite");
    if (i > 0 && s.t[i] < s.t[i - 1]) ++out.out_of_order;
  }
  std::vector<std::size_t> order(s.t.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return s.t[a] < s.t[b]; });
  for (std::size_t k = 0; k < order.size(); ++k) {
    out.t.push_back(s.t[order[k]]);
    out.v.push_back(s.values[order[k]]);
    if (k > 0 && !(out.t[k] > out.t[k - 1])) {
      // Sorting leaves time never going backwards; two rows at one instant
      // with different values cannot both be true, and which one is cannot be known.
      if (out.v[k] == out.v[k - 1]) {  // the same row twice: keep one
        out.t.pop_back();
        out.v.pop_back();
        continue;
      }
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.6f", out.t[k]);
      throw ImportError(
          file, s.name + ": two different rows at time " + buf + " (time does not advance)");
    }
  }
  if (angle) {  // theta continuous: no jump of 2 pi between neighbours
    for (std::size_t k = 1; k < out.v.size(); ++k) {
      double d = out.v[k][2] - out.v[k - 1][2];
      d -= 2 * kPi * std::round(d / (2 * kPi));
      out.v[k][2] = out.v[k - 1][2] + d;
    }
  }
  return out;
}

// Linear interpolation at the increasing times `at`; `at` lies within s.t.
std::vector<std::array<double, 3>> Interpolate(const Sorted& s, const std::vector<double>& at,
                                               double t0) {
  std::vector<std::array<double, 3>> out;
  out.reserve(at.size());
  std::size_t j = 0;
  for (double tr : at) {
    const double t = t0 + tr;
    while (j + 2 < s.t.size() && s.t[j + 1] < t) ++j;
    const double w = std::clamp((t - s.t[j]) / (s.t[j + 1] - s.t[j]), 0.0, 1.0);
    std::array<double, 3> v;
    for (int c = 0; c < 3; ++c) v[c] = s.v[j][c] + w * (s.v[j + 1][c] - s.v[j][c]);
    out.push_back(v);
  }
  return out;
}

}  // namespace

Resampled Resample(const Recording& r, double rate_hz) {
  if (!(rate_hz > 0)) throw ImportError(r.source, "the sample rate must be > 0");
  const Sorted object = Sort(r.object_pose, r.source, true);
  const Sorted pusher = Sort(r.pusher_pose, r.source, true);
  const bool has_force = !r.force.t.empty();
  const Sorted force = has_force ? Sort(r.force, r.source, false) : Sorted{};
  double start = std::max(object.t.front(), pusher.t.front());
  double end = std::min(object.t.back(), pusher.t.back());
  if (has_force) {
    start = std::max(start, force.t.front());
    end = std::min(end, force.t.back());
  }
  if (!(end - start >= 1.0 / rate_hz))
    throw ImportError(r.source, "the streams do not overlap in time (common span " +
                                    std::to_string(end - start) + " s)");
  Resampled out;
  out.rate_hz = rate_hz;
  out.t0 = start;
  const auto n = static_cast<std::size_t>(std::floor((end - start) * rate_hz + 1e-9)) + 1;
  for (std::size_t k = 0; k < n; ++k) out.t.push_back(static_cast<double>(k) / rate_hz);
  out.object = Interpolate(object, out.t, start);
  out.pusher = Interpolate(pusher, out.t, start);
  if (has_force) out.force = Interpolate(force, out.t, start);
  out.object_out_of_order = object.out_of_order;
  out.pusher_out_of_order = pusher.out_of_order;
  out.force_out_of_order = force.out_of_order;
  return out;
}

double SignedDistance(const std::vector<std::array<double, 2>>& poly, double x, double y) {
  double best = INFINITY;
  bool inside = false;
  const std::size_t n = poly.size();
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    const auto& a = poly[j];
    const auto& b = poly[i];
    const double ex = b[0] - a[0], ey = b[1] - a[1];
    const double len2 = ex * ex + ey * ey;
    const double u =
        len2 > 0 ? std::clamp(((x - a[0]) * ex + (y - a[1]) * ey) / len2, 0.0, 1.0) : 0;
    best = std::min(best, std::hypot(x - a[0] - u * ex, y - a[1] - u * ey));
    // even-odd rule: a horizontal ray to +x crosses edge (a, b)
    if ((a[1] > y) != (b[1] > y) && x < a[0] + (y - a[1]) / (b[1] - a[1]) * ex) inside = !inside;
  }
  return inside ? -best : best;
}

std::array<double, 2> NearestPoint(const std::vector<std::array<double, 2>>& poly, double x,
                                   double y) {
  double best = INFINITY;
  std::array<double, 2> out{poly[0][0], poly[0][1]};
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const auto& a = poly[j];
    const auto& b = poly[i];
    const double ex = b[0] - a[0], ey = b[1] - a[1];
    const double len2 = ex * ex + ey * ey;
    const double u =
        len2 > 0 ? std::clamp(((x - a[0]) * ex + (y - a[1]) * ey) / len2, 0.0, 1.0) : 0.0;
    const double px = a[0] + u * ex, py = a[1] + u * ey;
    const double d = std::hypot(x - px, y - py);
    if (d < best) {
      best = d;
      out = {px, py};
    }
  }
  return out;
}

}  // namespace arena::recordings
