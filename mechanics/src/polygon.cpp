// Simple polygons (polygon.hpp): orientation, containment, closest boundary
// point, ear clipping and the simplicity check.
#include "arena/mechanics/polygon.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace arena::mechanics::polygon {

namespace {

double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

// > 0 when c lies left of the line a -> b.
double Orient(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return Cross(b - a, c - a);
}

// Whether the closed segments [a, b] and [c, d] share a point; `tol` is an
// area (length²) below which an orientation counts as collinear.
bool SegmentsMeet(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c,
                  const Eigen::Vector2d& d, double tol) {
  const double o1 = Orient(a, b, c), o2 = Orient(a, b, d);
  const double o3 = Orient(c, d, a), o4 = Orient(c, d, b);
  auto sgn = [tol](double o) { return o > tol ? 1 : (o < -tol ? -1 : 0); };
  const int s1 = sgn(o1), s2 = sgn(o2), s3 = sgn(o3), s4 = sgn(o4);
  if (s1 * s2 < 0 && s3 * s4 < 0) return true;
  // Collinear cases: a point of one segment on the other.
  auto on = [](const Eigen::Vector2d& p, const Eigen::Vector2d& q, const Eigen::Vector2d& r) {
    return std::min(p.x(), q.x()) <= r.x() && r.x() <= std::max(p.x(), q.x()) &&
           std::min(p.y(), q.y()) <= r.y() && r.y() <= std::max(p.y(), q.y());
  };
  if (s1 == 0 && on(a, b, c)) return true;
  if (s2 == 0 && on(a, b, d)) return true;
  if (s3 == 0 && on(c, d, a)) return true;
  if (s4 == 0 && on(c, d, b)) return true;
  return false;
}

}  // namespace

double SignedArea(const Polygon& poly) {
  double twice = 0;
  for (size_t i = 0; i < poly.size(); ++i) twice += Cross(poly[i], poly[(i + 1) % poly.size()]);
  return twice / 2;
}

bool IsConvex(const Polygon& poly) {
  const size_t n = poly.size();
  if (n < 3) return false;
  for (size_t i = 0; i < n; ++i) {
    if (!(Orient(poly[(i + n - 1) % n], poly[i], poly[(i + 1) % n]) > 0)) return false;
  }
  return true;
}

bool Contains(const Polygon& poly, const Eigen::Vector2d& p) {
  const size_t n = poly.size();
  bool inside = false;
  for (size_t i = 0, j = n - 1; i < n; j = i++) {
    const Eigen::Vector2d& a = poly[i];
    const Eigen::Vector2d& b = poly[j];
    if ((a.y() > p.y()) != (b.y() > p.y())) {
      const double x = a.x() + (p.y() - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
      if (p.x() < x) inside = !inside;
    }
  }
  if (inside) return true;
  // On the boundary counts as inside.
  const BoundaryPoint b = ClosestOnBoundary(poly, p);
  double scale = 0;
  for (const auto& v : poly) scale = std::max(scale, v.cwiseAbs().maxCoeff());
  return b.distance <= 1e-12 * std::max(scale, 1e-300);
}

BoundaryPoint ClosestOnBoundary(const Polygon& poly, const Eigen::Vector2d& p) {
  BoundaryPoint best;
  best.distance = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d& a = poly[i];
    const Eigen::Vector2d ab = poly[(i + 1) % poly.size()] - a;
    const double len2 = ab.squaredNorm();
    const double u = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
    const Eigen::Vector2d q = a + u * ab;
    const double d = (q - p).norm();
    if (d < best.distance) {
      best.distance = d;
      best.point = q;
      best.edge = i;
    }
  }
  return best;
}

std::vector<std::array<int, 3>> Triangulate(const Polygon& poly) {
  std::vector<std::array<int, 3>> out;
  std::vector<int> idx(poly.size());
  for (size_t i = 0; i < poly.size(); ++i) idx[i] = static_cast<int>(i);
  auto P = [&](int i) -> const Eigen::Vector2d& { return poly[static_cast<size_t>(i)]; };
  while (idx.size() > 3) {
    const size_t m = idx.size();
    size_t ear = m;
    double best_turn = -std::numeric_limits<double>::infinity();
    size_t best = 0;
    for (size_t k = 0; k < m && ear == m; ++k) {
      const int a = idx[(k + m - 1) % m], b = idx[k], c = idx[(k + 1) % m];
      const double turn = Orient(P(a), P(b), P(c));
      if (turn > best_turn) {
        best_turn = turn;
        best = k;
      }
      if (!(turn > 0)) continue;  // a reflex (or flat) vertex is no ear
      bool empty = true;
      for (size_t r = 0; r < m && empty; ++r) {
        const int v = idx[r];
        if (v == a || v == b || v == c) continue;
        // Inside or on the candidate triangle: not an ear.
        if (Orient(P(a), P(b), P(v)) >= 0 && Orient(P(b), P(c), P(v)) >= 0 &&
            Orient(P(c), P(a), P(v)) >= 0)
          empty = false;
      }
      if (empty) ear = k;
    }
    // Rounding can hide every ear of a nearly flat outline: clip the most
    // convex vertex then (a simple polygon always has an ear).
    if (ear == m) ear = best;
    out.push_back({idx[(ear + m - 1) % m], idx[ear], idx[(ear + 1) % m]});
    idx.erase(idx.begin() + static_cast<std::ptrdiff_t>(ear));
  }
  if (idx.size() == 3) out.push_back({idx[0], idx[1], idx[2]});
  return out;
}

std::optional<Problem> CheckSimple(const Polygon& poly) {
  const size_t n = poly.size();
  if (n < 3) return Problem{n == 0 ? 0 : n - 1, "a polygon needs at least 3 vertices"};
  double scale = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!poly[i].allFinite()) return Problem{i, "must be finite"};
    scale = std::max(scale, poly[i].cwiseAbs().maxCoeff());
  }
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d e = poly[(i + 1) % n] - poly[i];
    if (!(e.norm() > 1e-9 * scale)) {
      return Problem{i, "coincides with the next vertex (degenerate polygon)"};
    }
  }
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d e0 = poly[i] - poly[(i + n - 1) % n];
    const Eigen::Vector2d e1 = poly[(i + 1) % n] - poly[i];
    if (std::abs(Cross(e0, e1)) <= 1e-9 * e0.norm() * e1.norm()) {
      return Problem{i, e0.dot(e1) > 0 ? "lies on the line of its neighbours (degenerate polygon)"
                                       : "doubles back on its edge (degenerate polygon)"};
    }
  }
  // Simple: no two edges meet but neighbours at their shared vertex.
  const double tol = 1e-18 * scale * scale;
  for (size_t j = 2; j < n; ++j) {
    for (size_t i = 0; i + 1 < j; ++i) {
      if (i == 0 && j == n - 1) continue;  // neighbours across the closing vertex
      if (SegmentsMeet(poly[i], poly[i + 1], poly[j], poly[(j + 1) % n], tol)) {
        return Problem{j, "its edge meets the edge from vertex " + std::to_string(i) +
                              ": the polygon must be simple (not self-intersecting)"};
      }
    }
  }
  if (!(SignedArea(poly) > 0)) {
    return Problem{0, "the polygon runs clockwise: its vertices must be counter-clockwise"};
  }
  return std::nullopt;
}

}  // namespace arena::mechanics::polygon
