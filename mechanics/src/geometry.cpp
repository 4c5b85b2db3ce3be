// The object as a solid (geometry.hpp): prisms (boxes included) by their
// side planes and caps, cylinders by their radius and caps.
#include "geometry.hpp"

#include "arena/mechanics/polygon.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace arena::mechanics::geometry {

namespace {

double Cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

// Closest point of the segment [a, b] to p (2-D).
Eigen::Vector2d ClosestOnSegment(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                 const Eigen::Vector2d& p) {
  const Eigen::Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double u = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return a + u * ab;
}

}  // namespace

std::optional<PolygonProblem> CheckPolygon(const std::vector<Eigen::Vector2d>& polygon) {
  if (const auto p = polygon::CheckSimple(polygon)) return PolygonProblem{p->vertex, p->reason};
  return std::nullopt;
}

PolygonMoments MomentsOf(const std::vector<Eigen::Vector2d>& polygon) {
  PolygonMoments m;
  double cx = 0, cy = 0, xx = 0, yy = 0, xy = 0;
  const size_t n = polygon.size();
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[(i + 1) % n];
    const double c = Cross2(a, b);
    m.area += c / 2;
    cx += (a.x() + b.x()) * c;
    cy += (a.y() + b.y()) * c;
    xx += (a.x() * a.x() + a.x() * b.x() + b.x() * b.x()) * c;
    yy += (a.y() * a.y() + a.y() * b.y() + b.y() * b.y()) * c;
    xy += (a.x() * b.y() + 2 * a.x() * a.y() + 2 * b.x() * b.y() + b.x() * a.y()) * c;
  }
  if (!(m.area > 0)) return m;
  m.centroid = {cx / (6 * m.area), cy / (6 * m.area)};
  m.xx = xx / 12 - m.area * m.centroid.x() * m.centroid.x();
  m.yy = yy / 12 - m.area * m.centroid.y() * m.centroid.y();
  m.xy = xy / 24 - m.area * m.centroid.x() * m.centroid.y();
  return m;
}

Solid::Solid(const ObjectSpec& object) : shape_(object.shape) {
  if (shape_ == ObjectShape::kCylinder) {
    radius_ = object.radius;
    half_height_ = object.height / 2;
    extent_ = std::max(2 * radius_, object.height);
  } else {
    if (shape_ == ObjectShape::kBox) {
      const double hx = object.size.x() / 2, hy = object.size.y() / 2;
      polygon_ = {{-hx, -hy}, {hx, -hy}, {hx, hy}, {-hx, hy}};
      half_height_ = object.size.z() / 2;
    } else {
      polygon_ = object.polygon;
      half_height_ = object.height / 2;
      convex_ = polygon::IsConvex(polygon_);
      const PolygonMoments m = MomentsOf(polygon_);
      centroid_O_ = {m.centroid.x(), m.centroid.y(), 0};
    }
    double diameter = 0;
    for (size_t i = 0; i < polygon_.size(); ++i) {
      const Eigen::Vector2d& a = polygon_[i];
      const Eigen::Vector2d& b = polygon_[(i + 1) % polygon_.size()];
      const Eigen::Vector2d e = b - a;
      const Eigen::Vector2d nrm = Eigen::Vector2d(e.y(), -e.x()).normalized();
      edge_normals_.push_back(nrm);
      edge_offsets_.push_back(nrm.dot(a));
      for (const auto& v : polygon_) diameter = std::max(diameter, (v - a).norm());
    }
    extent_ = std::max(diameter, 2 * half_height_);
  }
  if (!(extent_ > 0) || !std::isfinite(extent_)) extent_ = 1;
}

Closest Solid::ClosestTo(const Eigen::Vector3d& p) const {
  return ClosestTo(p, Eigen::Vector3d::Zero(), 0.0);
}

Closest Solid::ClosestTo(const Eigen::Vector3d& p, const Eigen::Vector3d& prefer,
                         double tolerance) const {
  Closest out;
  const double tiny = 1e-15 * extent_;
  if (shape_ == ObjectShape::kCylinder) {
    const double r = std::hypot(p.x(), p.y());
    const Eigen::Vector2d radial =
        r > tiny ? Eigen::Vector2d(p.x() / r, p.y() / r) : Eigen::Vector2d(1, 0);
    const double d_side = r - radius_;
    const double d_cap = std::abs(p.z()) - half_height_;
    const double zsign = p.z() >= 0 ? 1.0 : -1.0;
    if (d_side <= 0 && d_cap <= 0) {
      if (d_side > d_cap) {
        out.normal_O = {radial.x(), radial.y(), 0};
        out.point_O = {radius_ * radial.x(), radius_ * radial.y(), p.z()};
        out.distance = d_side;
      } else {
        out.normal_O = {0, 0, zsign};
        out.point_O = {p.x(), p.y(), zsign * half_height_};
        out.distance = d_cap;
      }
      return out;
    }
    const double rc = std::min(r, radius_);
    out.point_O = {rc * radial.x(), rc * radial.y(),
                   std::clamp(p.z(), -half_height_, half_height_)};
    const Eigen::Vector3d diff = p - out.point_O;
    out.distance = diff.norm();
    if (out.distance > tiny) {
      out.normal_O = diff / out.distance;
    } else {
      out.normal_O = d_side > d_cap ? Eigen::Vector3d(radial.x(), radial.y(), 0)
                                    : Eigen::Vector3d(0, 0, zsign);
    }
    return out;
  }
  if (!convex_) return ClosestToNonConvex(p);
  // Prism: the face of least depth inside; outside, the closest point is the
  // polygon's closest point in x-y with z clamped (the prism is a product).
  const Eigen::Vector2d xy(p.x(), p.y());
  double best = -std::numeric_limits<double>::infinity();
  Eigen::Vector3d best_normal = Eigen::Vector3d::UnitZ();
  bool inside_xy = true;
  for (size_t i = 0; i < edge_normals_.size(); ++i) {
    const double d = edge_normals_[i].dot(xy) - edge_offsets_[i];
    if (d > 0) inside_xy = false;
    if (d > best) {
      best = d;
      best_normal = {edge_normals_[i].x(), edge_normals_[i].y(), 0};
    }
  }
  const double d_top = p.z() - half_height_, d_bottom = -p.z() - half_height_;
  if (d_top > best) {
    best = d_top;
    best_normal = Eigen::Vector3d::UnitZ();
  }
  if (d_bottom > best) {
    best = d_bottom;
    best_normal = -Eigen::Vector3d::UnitZ();
  }
  if (best <= 0 && tolerance > 0 && prefer.squaredNorm() > 0) {
    // Among the faces whose planes pass within tolerance of the point, the
    // one nearest the preferred normal (the previous step's face, or the one
    // the pusher closes onto).
    double best_dot = prefer.dot(best_normal);
    double chosen = best;
    auto consider = [&](double d, const Eigen::Vector3d& n) {
      if (d < best - tolerance) return;
      const double dot = prefer.dot(n);
      if (dot > best_dot) {
        best_dot = dot;
        chosen = d;
        best_normal = n;
      }
    };
    for (size_t i = 0; i < edge_normals_.size(); ++i) {
      consider(edge_normals_[i].dot(xy) - edge_offsets_[i],
               {edge_normals_[i].x(), edge_normals_[i].y(), 0});
    }
    consider(d_top, Eigen::Vector3d::UnitZ());
    consider(d_bottom, -Eigen::Vector3d::UnitZ());
    best = chosen;
  }
  if (best <= 0) {
    out.distance = best;
    out.normal_O = best_normal;
    out.point_O = p - best * best_normal;
    return out;
  }
  Eigen::Vector2d c = xy;
  if (!inside_xy) {
    double best2 = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < polygon_.size(); ++i) {
      const Eigen::Vector2d q =
          ClosestOnSegment(polygon_[i], polygon_[(i + 1) % polygon_.size()], xy);
      const double d2 = (q - xy).squaredNorm();
      if (d2 < best2) {
        best2 = d2;
        c = q;
      }
    }
  }
  out.point_O = {c.x(), c.y(), std::clamp(p.z(), -half_height_, half_height_)};
  const Eigen::Vector3d diff = p - out.point_O;
  out.distance = diff.norm();
  out.normal_O = out.distance > tiny ? Eigen::Vector3d(diff / out.distance) : best_normal;
  return out;
}

std::optional<Entry> Solid::EntryOf(const Eigen::Vector3d& p, const Eigen::Vector3d& d,
                                    double tolerance) const {
  double s_in = -std::numeric_limits<double>::infinity();
  double s_out = std::numeric_limits<double>::infinity();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  // One half-space n·x <= offset: narrows [s_in, s_out]; false on a miss.
  auto clip = [&](const Eigen::Vector3d& n, double offset) {
    const double nd = n.dot(d);
    const double np = n.dot(p) - offset;
    if (std::abs(nd) < 1e-12) return np <= tolerance;
    const double s = -np / nd;
    if (nd < 0) {
      if (s > s_in) {
        s_in = s;
        normal = n;
      }
    } else {
      s_out = std::min(s_out, s);
    }
    return true;
  };
  if (!clip(Eigen::Vector3d::UnitZ(), half_height_) ||
      !clip(-Eigen::Vector3d::UnitZ(), half_height_)) {
    return std::nullopt;
  }
  if (shape_ == ObjectShape::kCylinder) {
    const Eigen::Vector2d q(p.x(), p.y()), e(d.x(), d.y());
    const double a = e.squaredNorm();
    const double rt = radius_ + tolerance;
    if (a < 1e-12) {
      if (q.norm() > rt) return std::nullopt;
    } else {
      const double b = 2 * q.dot(e);
      const double c_tol = q.squaredNorm() - rt * rt;
      if (b * b - 4 * a * c_tol < 0) return std::nullopt;
      const double c = q.squaredNorm() - radius_ * radius_;
      const double root = std::sqrt(std::max(b * b - 4 * a * c, 0.0));
      const double s1 = (-b - root) / (2 * a), s2 = (-b + root) / (2 * a);
      if (s1 > s_in) {
        s_in = s1;
        const Eigen::Vector2d r = q + s1 * e;
        const double rn = r.norm();
        normal = rn > 0 ? Eigen::Vector3d(r.x() / rn, r.y() / rn, 0) : Eigen::Vector3d::UnitX();
      }
      s_out = std::min(s_out, s2);
    }
  } else if (!convex_) {
    return EntryOfNonConvex(p, d, tolerance, s_in, s_out, normal);
  } else {
    for (size_t i = 0; i < edge_normals_.size(); ++i) {
      if (!clip({edge_normals_[i].x(), edge_normals_[i].y(), 0}, edge_offsets_[i]))
        return std::nullopt;
    }
  }
  if (!std::isfinite(s_in) || s_in > s_out + tolerance) return std::nullopt;
  Entry out;
  out.s = s_in;
  out.point_O = p + s_in * d;
  out.normal_O = normal;
  return out;
}

// A non-convex prism: inside, the nearer of the side (the outline's closest
// edge point) and the caps; outside, the outline's closest point in x-y with
// z clamped, as for a convex one.
Closest Solid::ClosestToNonConvex(const Eigen::Vector3d& p) const {
  Closest out;
  const Eigen::Vector2d xy(p.x(), p.y());
  const polygon::BoundaryPoint b = polygon::ClosestOnBoundary(polygon_, xy);
  const bool inside_xy = polygon::Contains(polygon_, xy);
  const Eigen::Vector2d edge_n = edge_normals_[b.edge];
  const double d_top = p.z() - half_height_, d_bottom = -p.z() - half_height_;
  const double tiny = 1e-15 * extent_;
  if (inside_xy && d_top <= 0 && d_bottom <= 0) {
    const double d_side = -b.distance;
    if (d_side >= d_top && d_side >= d_bottom) {
      // Outward: from p to the boundary point (a reflex corner has no edge
      // normal of its own), the edge's when p is on it.
      const Eigen::Vector2d to = b.point - xy;
      const Eigen::Vector2d nrm = to.norm() > tiny ? Eigen::Vector2d(to / to.norm()) : edge_n;
      out.normal_O = {nrm.x(), nrm.y(), 0};
      out.point_O = {b.point.x(), b.point.y(), p.z()};
      out.distance = d_side;
    } else {
      const double zs = d_top >= d_bottom ? 1.0 : -1.0;
      out.normal_O = {0, 0, zs};
      out.point_O = {p.x(), p.y(), zs * half_height_};
      out.distance = std::max(d_top, d_bottom);
    }
    return out;
  }
  const Eigen::Vector2d c = inside_xy ? xy : b.point;
  out.point_O = {c.x(), c.y(), std::clamp(p.z(), -half_height_, half_height_)};
  const Eigen::Vector3d diff = p - out.point_O;
  out.distance = diff.norm();
  out.normal_O = out.distance > tiny ? Eigen::Vector3d(diff / out.distance)
                                     : Eigen::Vector3d(edge_n.x(), edge_n.y(), 0);
  return out;
}

// A non-convex prism: the line's x-y trace crosses the outline at sorted
// parameters; between crossings it is alternately outside and inside (the
// midpoint decides). The first inside stretch that overlaps the caps' slab
// [s_in, s_out] (within `tolerance`) is where the line enters.
std::optional<Entry> Solid::EntryOfNonConvex(const Eigen::Vector3d& p, const Eigen::Vector3d& d,
                                             double tolerance, double s_in, double s_out,
                                             Eigen::Vector3d cap_normal) const {
  const Eigen::Vector2d q(p.x(), p.y()), e(d.x(), d.y());
  const size_t n = polygon_.size();
  struct Crossing {
    double s;
    size_t edge;
  };
  std::vector<Crossing> xs;
  const double e2 = e.squaredNorm();
  if (e2 < 1e-24) {
    // Along z: inside the outline (or within tolerance of it) or a miss.
    const polygon::BoundaryPoint b = polygon::ClosestOnBoundary(polygon_, q);
    if (!polygon::Contains(polygon_, q) && b.distance > tolerance) return std::nullopt;
    if (!std::isfinite(s_in) || s_in > s_out + tolerance) return std::nullopt;
    Entry out;
    out.s = s_in;
    out.point_O = p + s_in * d;
    out.normal_O = cap_normal;
    return out;
  }
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& a = polygon_[i];
    const Eigen::Vector2d ab = polygon_[(i + 1) % n] - a;
    const double den = e.x() * ab.y() - e.y() * ab.x();
    if (std::abs(den) < 1e-15 * std::sqrt(e2) * ab.norm()) continue;  // parallel
    const Eigen::Vector2d aq = a - q;
    const double s = (aq.x() * ab.y() - aq.y() * ab.x()) / den;
    const double u = (aq.x() * e.y() - aq.y() * e.x()) / den;
    if (u >= 0 && u <= 1) xs.push_back({s, i});
  }
  std::sort(xs.begin(), xs.end(), [](const Crossing& a, const Crossing& b) { return a.s < b.s; });
  for (size_t k = 0; k + 1 < xs.size(); ++k) {
    const double lo = xs[k].s, hi = xs[k + 1].s;
    if (!(hi > lo)) continue;
    if (!polygon::Contains(polygon_, q + 0.5 * (lo + hi) * e)) continue;
    const double enter = std::max(lo, s_in), leave = std::min(hi, s_out);
    if (enter > leave + tolerance) continue;
    Entry out;
    out.s = enter;
    out.point_O = p + enter * d;
    if (lo >= s_in) {
      const Eigen::Vector2d& nrm = edge_normals_[xs[k].edge];
      out.normal_O = {nrm.x(), nrm.y(), 0};
    } else {
      out.normal_O = cap_normal;
    }
    return out;
  }
  return std::nullopt;
}

Feature Solid::Support(const Eigen::Vector3d& dir, double tolerance) const {
  Feature f;
  if (shape_ == ObjectShape::kCylinder) {
    const Eigen::Vector2d e(dir.x(), dir.y());
    const double en = e.norm();
    const double zs = dir.z() > 0 ? -half_height_ : half_height_;  // the cap that comes first
    const Eigen::Vector2d rim = en > 0 ? Eigen::Vector2d(-e / en) : Eigen::Vector2d(1, 0);
    if (2 * radius_ * en <= tolerance) {
      f.kind = Feature::Kind::kFace;
      for (int j = 0; j < 4; ++j) {
        const double a = j * std::numbers::pi / 2;
        f.points_O.emplace_back(radius_ * std::cos(a), radius_ * std::sin(a), zs);
      }
    } else if (2 * half_height_ * std::abs(dir.z()) <= tolerance) {
      f.kind = Feature::Kind::kEdge;
      f.points_O.emplace_back(radius_ * rim.x(), radius_ * rim.y(), -half_height_);
      f.points_O.emplace_back(radius_ * rim.x(), radius_ * rim.y(), half_height_);
    } else {
      f.kind = Feature::Kind::kVertex;
      f.points_O.emplace_back(radius_ * rim.x(), radius_ * rim.y(), zs);
    }
    return f;
  }
  double lo = std::numeric_limits<double>::infinity();
  for (double z : {-half_height_, half_height_}) {
    for (const auto& v : polygon_) lo = std::min(lo, dir.dot(Eigen::Vector3d(v.x(), v.y(), z)));
  }
  for (double z : {-half_height_, half_height_}) {
    for (const auto& v : polygon_) {
      const Eigen::Vector3d x(v.x(), v.y(), z);
      if (dir.dot(x) <= lo + tolerance) f.points_O.push_back(x);
    }
  }
  f.kind = f.points_O.size() == 1   ? Feature::Kind::kVertex
           : f.points_O.size() == 2 ? Feature::Kind::kEdge
                                    : Feature::Kind::kFace;
  return f;
}

}  // namespace arena::mechanics::geometry
