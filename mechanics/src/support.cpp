// The support's pressure points and their Coulomb friction (support.hpp).
#include "arena/mechanics/support.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/polygon.hpp"

namespace arena::mechanics {

namespace {

// Uniform pressure over a simple polygon: ear-clipped triangles, each split
// into k² equal triangles whose centroids carry their areas.
void PolygonQuadrature(const polygon::Polygon& poly, int target, double z, SupportPressure* out) {
  const double area = polygon::SignedArea(poly);
  const double h = std::sqrt(area / std::max(target, 1));
  for (const auto& tri : polygon::Triangulate(poly)) {
    const Eigen::Vector2d& a = poly[static_cast<size_t>(tri[0])];
    const Eigen::Vector2d& b = poly[static_cast<size_t>(tri[1])];
    const Eigen::Vector2d& c = poly[static_cast<size_t>(tri[2])];
    const Eigen::Vector2d ab = b - a, ac = c - a;
    const double at = 0.5 * std::abs(ab.x() * ac.y() - ab.y() * ac.x());
    if (!(at > 0)) continue;
    const int k = std::max(1, static_cast<int>(std::ceil(std::sqrt(at) / h)));
    const double wsub = at / (k * k);
    const Eigen::Vector2d du = ab / k, dv = ac / k;
    for (int i = 0; i < k; ++i) {
      for (int j = 0; i + j < k; ++j) {
        const Eigen::Vector2d o = a + i * du + j * dv;
        // Upward triangle (i, j), (i+1, j), (i, j+1): centroid o + (du + dv)/3.
        const Eigen::Vector2d up = o + (du + dv) / 3.0;
        out->points_O.emplace_back(up.x(), up.y(), z);
        out->weights.push_back(wsub);
        if (i + j + 1 < k) {
          // Downward (i+1, j), (i, j+1), (i+1, j+1): centroid o + 2(du + dv)/3.
          const Eigen::Vector2d down = o + 2.0 * (du + dv) / 3.0;
          out->points_O.emplace_back(down.x(), down.y(), z);
          out->weights.push_back(wsub);
        }
      }
    }
  }
}

// Uniform pressure over a disk: equal-area rings, each at its annulus's
// mean radius, with points spaced about as far apart as the rings.
void DiskQuadrature(double radius, int target, double z, SupportPressure* out) {
  const int rings =
      std::max(1, static_cast<int>(std::lround(std::sqrt(target / std::numbers::pi))));
  for (int i = 0; i < rings; ++i) {
    const double ri = radius * std::sqrt(static_cast<double>(i) / rings);
    const double ro = radius * std::sqrt(static_cast<double>(i + 1) / rings);
    const double rho = 2.0 / 3.0 * (ro * ro * ro - ri * ri * ri) / (ro * ro - ri * ri);
    const int m =
        std::max(3, static_cast<int>(std::lround(2 * std::numbers::pi * rho / (radius / rings))));
    for (int j = 0; j < m; ++j) {
      // Rings alternate their phase so that no ray holds every ring's point.
      const double a = 2 * std::numbers::pi * (j + 0.5 * (i % 2)) / m;
      out->points_O.emplace_back(rho * std::cos(a), rho * std::sin(a), z);
      out->weights.push_back(1.0 / (rings * m));
    }
  }
}

}  // namespace

SupportPressure SupportPressureOf(const Scene& scene, int target) {
  SupportPressure out;
  const ObjectSpec& o = scene.object;
  const double g = scene.gravity.norm();
  const Eigen::Vector3d z_G = RotationFromRpy(o.pose.rpy).col(2);
  if (!scene.support || !(g > 0) || std::abs(z_G.dot(scene.gravity / g)) < 1 - 1e-9) {
    throw std::invalid_argument(
        "support: the object rests on no z cap (its z axis must be along gravity)");
  }
  const double half = (o.shape == ObjectShape::kBox ? o.size.z() : o.height) / 2;
  // The cap that faces along gravity: z_G · g > 0 means O's +z points down.
  out.cap_z_O = z_G.dot(scene.gravity) > 0 ? half : -half;
  const auto& given = scene.support->pressure_points;
  if (!given.empty()) {
    for (const auto& p : given) {
      if (!(p.z() > 0)) continue;
      out.points_O.emplace_back(p.x(), p.y(), out.cap_z_O);
      out.weights.push_back(p.z());
    }
  } else if (o.shape == ObjectShape::kCylinder) {
    DiskQuadrature(o.radius, target, out.cap_z_O, &out);
  } else if (o.shape == ObjectShape::kBox) {
    const double hx = o.size.x() / 2, hy = o.size.y() / 2;
    PolygonQuadrature({{-hx, -hy}, {hx, -hy}, {hx, hy}, {-hx, hy}}, target, out.cap_z_O, &out);
  } else {
    PolygonQuadrature(o.polygon, target, out.cap_z_O, &out);
  }
  double total = 0;
  for (double w : out.weights) total += w;
  if (!(total > 0)) throw std::invalid_argument("support.pressure.points: weights are all zero");
  for (double& w : out.weights) w /= total;
  return out;
}

Eigen::Vector3d SupportFriction(const std::vector<Eigen::Vector2d>& r, const std::vector<double>& w,
                                double mu_N, const Eigen::Vector2d& v, double omega) {
  double fx = 0, fy = 0, tau = 0;
  for (size_t i = 0; i < r.size(); ++i) {
    const double ux = v.x() - omega * r[i].y();
    const double uy = v.y() + omega * r[i].x();
    const double speed = std::hypot(ux, uy);
    if (!(speed > 0)) continue;
    const double k = -mu_N * w[i] / speed;
    const double px = k * ux, py = k * uy;
    fx += px;
    fy += py;
    tau += r[i].x() * py - r[i].y() * px;
  }
  return {fx, fy, tau};
}

}  // namespace arena::mechanics
