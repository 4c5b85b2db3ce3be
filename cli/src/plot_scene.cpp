#include "plot_scene.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "arena/mechanics/pusher_motion.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/support.hpp"
#include "svg_chart.hpp"

namespace arena::cli {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;

struct View {
  std::string id, title;
  int h_axis, v_axis;  // scene axes drawn right and up
};

Eigen::Matrix3d Rotation(const mechanics::Pose& p) {
  return (Eigen::AngleAxisd(p.rpy.z(), Vector3d::UnitZ()) *
          Eigen::AngleAxisd(p.rpy.y(), Vector3d::UnitY()) *
          Eigen::AngleAxisd(p.rpy.x(), Vector3d::UnitX()))
      .toRotationMatrix();
}

// The object's surface sampled (corners, rims) in the scene frame.
std::vector<Vector3d> ObjectPoints(const mechanics::ObjectSpec& o) {
  std::vector<Vector3d> local;
  switch (o.shape) {
    case mechanics::ObjectShape::kBox:
      for (int k = 0; k < 8; ++k)
        local.push_back(0.5 * Vector3d((k & 1 ? 1 : -1) * o.size.x(), (k & 2 ? 1 : -1) * o.size.y(),
                                       (k & 4 ? 1 : -1) * o.size.z()));
      break;
    case mechanics::ObjectShape::kCylinder:
      for (int k = 0; k < 48; ++k) {
        const double a = 2 * kPi * k / 48;
        for (double z : {-0.5 * o.height, 0.5 * o.height})
          local.emplace_back(o.radius * std::cos(a), o.radius * std::sin(a), z);
      }
      break;
    default:
      for (const auto& v : o.polygon)
        for (double z : {-0.5 * o.height, 0.5 * o.height}) local.emplace_back(v.x(), v.y(), z);
      break;
  }
  const Eigen::Matrix3d r = Rotation(o.pose);
  std::vector<Vector3d> out;
  for (const auto& p : local) out.push_back(o.pose.position + r * p);
  return out;
}

std::vector<Vector2d> Hull(std::vector<Vector2d> p) {
  std::sort(p.begin(), p.end(), [](const Vector2d& a, const Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  if (p.size() < 3) return p;
  std::vector<Vector2d> h(2 * p.size());
  size_t k = 0;
  auto cross = [](const Vector2d& o, const Vector2d& a, const Vector2d& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
  };
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  h.resize(k - 1);
  return h;
}

// A length in the unit a person reads: mm below 1 m.
std::string Length(double m) {
  return std::abs(m) < 1 ? FormatNumber(m * 1e3, 3) + " mm" : FormatNumber(m, 3) + " m";
}

// Any unit vector perpendicular to n.
Vector3d Perpendicular(const Vector3d& n) {
  const Vector3d a = std::abs(n.x()) < 0.9 ? Vector3d::UnitX() : Vector3d::UnitY();
  return n.cross(a).normalized();
}

// A contact's drawn shape in the scene frame: a point, a segment, a disc rim.
std::vector<Vector3d> ContactShape(const mechanics::ContactSpec& c) {
  std::vector<Vector3d> pts;
  switch (c.type) {
    case mechanics::ContactType::kPoint:
      pts.push_back(c.position);
      break;
    case mechanics::ContactType::kLine:
      pts.push_back(c.position - 0.5 * c.length * c.axis.normalized());
      pts.push_back(c.position + 0.5 * c.length * c.axis.normalized());
      break;
    case mechanics::ContactType::kPatch: {
      const Vector3d u = Perpendicular(c.normal.normalized());
      const Vector3d v = c.normal.normalized().cross(u);
      for (int k = 0; k <= 32; ++k) {
        const double a = 2 * kPi * k / 32;
        pts.push_back(c.position + c.radius * (std::cos(a) * u + std::sin(a) * v));
      }
      break;
    }
  }
  return pts;
}

class Canvas {
 public:
  Canvas(const View& view, double x0, double y0, double w, double h, double scale, Vector2d centre)
      : view_(view), x0_(x0), y0_(y0), w_(w), h_(h), scale_(scale), centre_(std::move(centre)) {}
  Vector2d Project(const Vector3d& p) const { return {p[view_.h_axis], p[view_.v_axis]}; }
  Vector2d Px(const Vector3d& p) const { return Px2(Project(p)); }
  Vector2d Px2(const Vector2d& q) const {
    return {x0_ + w_ / 2 + (q.x() - centre_.x()) * scale_,
            y0_ + h_ / 2 - (q.y() - centre_.y()) * scale_};
  }
  double x0() const { return x0_; }
  double y0() const { return y0_; }
  double w() const { return w_; }
  double h() const { return h_; }
  double scale() const { return scale_; }

 private:
  View view_;
  double x0_, y0_, w_, h_, scale_;
  Vector2d centre_;
};

std::string Arrow(const Vector2d& from, const Vector2d& to, const std::string& color, bool dashed,
                  double width = 2) {
  std::string s = "<line x1=\"" + SvgNum(from.x()) + "\" y1=\"" + SvgNum(from.y()) + "\" x2=\"" +
                  SvgNum(to.x()) + "\" y2=\"" + SvgNum(to.y()) + "\" stroke=\"" + color +
                  "\" stroke-width=\"" + SvgNum(width) + "\"" +
                  (dashed ? " stroke-dasharray=\"6,4\"" : "") + "/>";
  const Vector2d d = to - from;
  if (d.norm() > 1e-9) {
    const Vector2d u = d.normalized(), n(-u.y(), u.x());
    const Vector2d a = to - 9 * u + 4.5 * n, b = to - 9 * u - 4.5 * n;
    s += "<polygon points=\"" + SvgNum(to.x()) + "," + SvgNum(to.y()) + " " + SvgNum(a.x()) + "," +
         SvgNum(a.y()) + " " + SvgNum(b.x()) + "," + SvgNum(b.y()) + "\" fill=\"" + color + "\"/>";
  }
  return s;
}

std::string Text(const Vector2d& at, const std::string& text, const std::string& color,
                 const char* anchor = "middle", int size = 12) {
  return "<text x=\"" + SvgNum(at.x()) + "\" y=\"" + SvgNum(at.y()) + "\" font-size=\"" +
         std::to_string(size) + "\" text-anchor=\"" + anchor + "\" fill=\"" + color + "\">" +
         SvgEscape(text) + "</text>";
}

// The label of a contact: outside the object, beyond its normal's arrow,
// anchored so the text runs away from the object.
std::string Label(const Canvas& c, const Vector3d& position, const Vector3d& normal,
                  const std::string& text, const std::string& color) {
  const Vector2d p = c.Px(position);
  Vector2d dir = c.Px(position - normal) - p;  // away from the object, in px
  if (dir.norm() < 1e-9) return Text(p + Vector2d(0, -14), text, color);
  dir.normalize();
  if (std::abs(dir.x()) > 0.5)
    return Text(p + 32 * dir + Vector2d(0, 4), text, color, dir.x() < 0 ? "end" : "start");
  return Text(p + 32 * dir + Vector2d(0, dir.y() > 0 ? 12 : -4), text, color);
}

std::string DrawContact(const Canvas& c, const mechanics::ContactSpec& s, const std::string& id,
                        const std::string& label, const std::string& color) {
  std::string g = "<g id=\"" + SvgEscape(id) + "\" class=\"contact\" data-type=\"" +
                  mechanics::ToString(s.type) + "\">";
  const auto pts = ContactShape(s);
  if (pts.size() == 1) {
    g += "<circle cx=\"" + SvgNum(c.Px(pts[0]).x()) + "\" cy=\"" + SvgNum(c.Px(pts[0]).y()) +
         "\" r=\"4\" fill=\"" + color + "\"/>";
  } else {
    std::string d;
    for (const auto& p : pts) d += SvgNum(c.Px(p).x()) + "," + SvgNum(c.Px(p).y()) + " ";
    g += "<polyline points=\"" + d + "\" fill=\"none\" stroke=\"" + color +
         "\" stroke-width=\"4\" stroke-linecap=\"round\"/>";
  }
  // The normal: from outside into the object (a finger's closing direction).
  const Vector2d tip = c.Px(s.position);
  Vector2d out = c.Px(s.position - s.normal.normalized()) - tip;
  if (out.norm() > 1e-9)
    g += Arrow(tip + 26 * out.normalized(), tip + 6 * out.normalized(), color, false, 1.5);
  g += Label(c, s.position, s.normal.normalized(), label, color);
  g += "</g>";
  return g;
}

// What SceneSvg draws beyond the scene itself: every point (to fit both
// views at one scale), the push, and the support.
struct SceneDrawing {
  std::vector<Vector3d> all;
  Vector3d push_end = Vector3d::Zero();
  bool moves = false;
  std::vector<Vector3d> path;  // a recorded path, at most ~200 of its samples
  std::vector<Vector3d> footprint, pressure;
  std::vector<double> pressure_w;
  std::string support_text;
};

// Where the push ends: after a constant motion or along a recorded path
// (drawn as recorded).
void AddPush(const mechanics::Scene& scene, SceneDrawing* d) {
  if (!scene.pusher) return;
  d->push_end = mechanics::PusherPoseAt(*scene.pusher, scene.duration).position;
  d->moves = !scene.pusher->controller && (d->push_end - scene.pusher->position).norm() > 0;
  if (d->moves && scene.pusher->path) {
    const auto& rec = *scene.pusher->path;
    const std::size_t step = std::max<std::size_t>(1, rec.position.size() / 200);
    for (std::size_t k = 0; k < rec.position.size(); k += step) d->path.push_back(rec.position[k]);
    if (d->path.back() != rec.position.back()) d->path.push_back(rec.position.back());
  }
  for (const auto& p : ContactShape(*scene.pusher)) d->all.push_back(p);
  if (d->moves) d->all.push_back(d->push_end);
  for (const auto& p : d->path) d->all.push_back(p);
}

// The support: the face the object rests on (its footprint) and the plane.
void AddSupport(const mechanics::Scene& scene, SceneDrawing* d) {
  if (!scene.support) return;
  try {
    const mechanics::SupportPressure sp = mechanics::SupportPressureOf(scene);
    const Eigen::Matrix3d r = Rotation(scene.object.pose);
    for (const auto& q : ObjectPoints(scene.object)) {
      // The object's points on the resting cap (in the object frame z = cap_z).
      const Vector3d local = r.transpose() * (q - scene.object.pose.position);
      if (std::abs(local.z() - sp.cap_z_O) < 1e-9) d->footprint.push_back(q);
    }
    if (!scene.support->pressure_points.empty()) {
      for (std::size_t i = 0; i < sp.points_O.size(); ++i) {
        d->pressure.push_back(scene.object.pose.position + r * sp.points_O[i]);
        d->pressure_w.push_back(sp.weights[i]);
      }
    }
    d->support_text = "support mu " + FormatNumber(scene.support->mu, 3) + ", " +
                      (scene.support->pressure_points.empty()
                           ? std::string("uniform pressure")
                           : std::to_string(d->pressure.size()) + " pressure points");
  } catch (const std::exception& e) {
    d->support_text = std::string("support: ") + e.what();
  }
}

SceneDrawing MakeDrawing(const mechanics::Scene& scene) {
  SceneDrawing d;
  d.all = ObjectPoints(scene.object);
  for (const auto& f : scene.fingers)
    for (const auto& p : ContactShape(f)) d.all.push_back(p);
  AddPush(scene, &d);
  AddSupport(scene, &d);
  return d;
}

// The second title line: the object, the grip, the duration and the push.
std::string SceneCaption(const mechanics::Scene& scene, const SceneDrawing& d) {
  const auto& o = scene.object;
  std::string text = std::string(mechanics::ToString(o.shape)) + " ";
  if (o.shape == mechanics::ObjectShape::kBox)
    text += FormatNumber(o.size.x() * 1e3, 3) + " x " + FormatNumber(o.size.y() * 1e3, 3) + " x " +
            FormatNumber(o.size.z() * 1e3, 3) + " mm";
  else if (o.shape == mechanics::ObjectShape::kCylinder)
    text += "radius " + Length(o.radius) + ", height " + Length(o.height);
  else
    text += std::to_string(o.polygon.size()) + "-gon, height " + Length(o.height);
  text += ", " + FormatNumber(o.mass * 1e3, 3) + " g; grip " + FormatNumber(scene.grip_force, 3) +
          " N per finger; " +
          (scene.duration >= 1 ? FormatNumber(scene.duration, 3) + " s"
                               : FormatNumber(scene.duration * 1e3, 3) + " ms");
  if (scene.pusher) {
    if (scene.pusher->controller)
      text += "; pusher closed-loop (" + scene.pusher->controller->name + ")";
    else
      text += "; push " + Length((d.push_end - scene.pusher->position).norm()) + " at " +
              FormatNumber(mechanics::PusherPeakRates(*scene.pusher).velocity.norm() * 1e3, 3) +
              (scene.pusher->path ? " mm/s at most (recorded path)" : " mm/s");
  }
  return text;
}

std::string ObjectSvg(const Canvas& c, const mechanics::ObjectSpec& o) {
  std::vector<Vector2d> proj;
  for (const auto& p : ObjectPoints(o)) proj.push_back(c.Project(p));
  std::string d;
  for (const auto& q : Hull(proj)) d += SvgNum(c.Px2(q).x()) + "," + SvgNum(c.Px2(q).y()) + " ";
  return "<g id=\"object\"><polygon points=\"" + d +
         "\" fill=\"#e6e6e6\" stroke=\"#555\" stroke-width=\"1.5\"/>" + "<circle cx=\"" +
         SvgNum(c.Px(o.pose.position).x()) + "\" cy=\"" + SvgNum(c.Px(o.pose.position).y()) +
         "\" r=\"2.5\" fill=\"#555\"/></g>";
}

// The support seen edge-on: its plane as a line across the panel, hatched on
// the side away from the object.
std::string SupportEdgeOnSvg(const Canvas& c, const std::vector<Vector2d>& hull,
                             const Vector3d& object_position, const std::string& support_text) {
  Vector2d e0 = hull.front(), e1 = hull.front();  // the two points farthest apart
  for (const auto& p : hull)
    for (const auto& q : hull)
      if ((p - q).norm() > (e0 - e1).norm()) e0 = p, e1 = q;
  const Vector2d a = c.Px2(e0), b = c.Px2(e1);
  const Vector2d u = (b - a).norm() > 1e-9 ? Vector2d((b - a).normalized()) : Vector2d(1, 0);
  Vector2d n(-u.y(), u.x());
  if ((c.Px(object_position) - a).dot(n) > 0) n = -n;  // away from the object
  const Vector2d l0 = a - 0.45 * c.w() * u, l1 = b + 0.45 * c.w() * u;
  const auto inside = [&](const Vector2d& q) {
    return q.x() >= c.x0() && q.x() <= c.x0() + c.w() && q.y() >= c.y0() && q.y() <= c.y0() + c.h();
  };
  Vector2d p0 = l0, p1 = l1;
  for (int k = 0; k < 200 && !inside(p0); ++k) p0 += 0.005 * (l1 - l0);
  for (int k = 0; k < 200 && !inside(p1); ++k) p1 -= 0.005 * (l1 - l0);
  std::string svg = "<line x1=\"" + SvgNum(p0.x()) + "\" y1=\"" + SvgNum(p0.y()) + "\" x2=\"" +
                    SvgNum(p1.x()) + "\" y2=\"" + SvgNum(p1.y()) +
                    "\" stroke=\"#8d6e63\" stroke-width=\"2\"/>";
  const double len = (p1 - p0).norm();
  for (double d = 0; d < len; d += 12) {
    const Vector2d h0 = p0 + d * u, h1 = h0 + 8 * n - 6 * u;
    if (inside(h1))
      svg += "<line x1=\"" + SvgNum(h0.x()) + "\" y1=\"" + SvgNum(h0.y()) + "\" x2=\"" +
             SvgNum(h1.x()) + "\" y2=\"" + SvgNum(h1.y()) +
             "\" stroke=\"#8d6e63\" stroke-width=\"1\"/>";
  }
  svg += Text(p1 + 14 * n + Vector2d(-4, 4), support_text, "#8d6e63", "end", 11);
  return svg;
}

// The support seen from above: the footprint (dashed) and any weighted
// pressure points (area by weight).
std::string FootprintSvg(const Canvas& c, const mechanics::Scene& scene, const SceneDrawing& d,
                         const std::vector<Vector2d>& fp, const std::vector<Vector2d>& hull,
                         const Vector2d& lo, const Vector2d& hi) {
  // A prism's face in its outline's order (it may be non-convex), else the hull.
  const bool prism = scene.object.shape != mechanics::ObjectShape::kBox &&
                     scene.object.shape != mechanics::ObjectShape::kCylinder;
  std::string points;
  for (const auto& q : prism ? fp : hull)
    points += SvgNum(c.Px2(q).x()) + "," + SvgNum(c.Px2(q).y()) + " ";
  std::string svg = "<polygon points=\"" + points +
                    "\" fill=\"none\" stroke=\"#8d6e63\" stroke-width=\"2\" "
                    "stroke-dasharray=\"2,3\"/>";
  double w_max = 0;
  for (double w : d.pressure_w) w_max = std::max(w_max, w);
  for (std::size_t i = 0; i < d.pressure.size(); ++i) {
    const Vector2d q = c.Px(d.pressure[i]);
    svg += "<circle cx=\"" + SvgNum(q.x()) + "\" cy=\"" + SvgNum(q.y()) + "\" r=\"" +
           SvgNum(1.5 + 4.5 * std::sqrt(d.pressure_w[i] / std::max(w_max, 1e-300))) +
           "\" fill=\"#8d6e63\" fill-opacity=\"0.6\"/>";
  }
  svg += Text(c.Px2(Vector2d(0.5 * (lo.x() + hi.x()), lo.y())) + Vector2d(0, 16),
              "footprint on the support", "#8d6e63", "middle", 11);
  return svg;
}

// The support: in a view along the table its plane, seen from above the footprint.
std::string SupportSvg(const Canvas& c, const mechanics::Scene& scene, const SceneDrawing& d) {
  if (d.footprint.empty()) return "";
  std::vector<Vector2d> fp;
  for (const auto& p : d.footprint) fp.push_back(c.Project(p));
  const auto hull = Hull(fp);
  Vector2d lo = Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& q : hull) lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
  const Vector2d span = hi - lo;
  const bool edge_on = span.minCoeff() < 1e-9 * std::max(1.0, span.maxCoeff());
  return "<g id=\"support\">" +
         (edge_on ? SupportEdgeOnSvg(c, hull, scene.object.pose.position, d.support_text)
                  : FootprintSvg(c, scene, d, fp, hull, lo, hi)) +
         "</g>";
}

// The push: a recorded path as recorded, a straight push as an arrow beside
// the pusher, a push along the view direction as a dot-in-circle.
std::string PushMotionSvg(const Canvas& c, const View& v, const mechanics::Scene& scene,
                          const SceneDrawing& d) {
  const Vector2d a = c.Px(scene.pusher->position), b = c.Px(d.push_end);
  const std::string away = Length((d.push_end - scene.pusher->position).norm());
  std::string svg = "<g id=\"push-motion\">";
  Vector2d lo = Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : d.path) lo = lo.cwiseMin(c.Px(p)), hi = hi.cwiseMax(c.Px(p));
  if (!d.path.empty() && (hi - lo).norm() > 3) {
    // The recorded path itself (dashed), its end hollow.
    std::string points;
    for (const auto& p : d.path) points += SvgNum(c.Px(p).x()) + "," + SvgNum(c.Px(p).y()) + " ";
    svg += "<polyline class=\"recorded-path\" points=\"" + points +
           "\" fill=\"none\" stroke=\"#c0392b\" stroke-width=\"2\" "
           "stroke-dasharray=\"6,4\"/>";
    svg += "<circle cx=\"" + SvgNum(b.x()) + "\" cy=\"" + SvgNum(b.y()) +
           "\" r=\"4\" fill=\"none\" stroke=\"#c0392b\"/>";
    const bool right = b.x() > c.x0() + c.w() / 2;  // the label runs into the panel
    svg += Text(b + Vector2d(right ? -8 : 8, v.v_axis == 2 ? -12 : 18),
                "recorded path, ends " + away + " away", "#c0392b", right ? "end" : "start", 11);
  } else if ((b - a).norm() > 3) {
    // Beside the pusher (not over its normal's arrow), with its end drawn hollow.
    const Vector2d u = (b - a).normalized(), side(-u.y() * 14, u.x() * 14);
    svg += Arrow(a + side, b + side, "#c0392b", true);
    svg += "<circle cx=\"" + SvgNum(b.x()) + "\" cy=\"" + SvgNum(b.y()) +
           "\" r=\"4\" fill=\"none\" stroke=\"#c0392b\"/>";
    svg += Text(0.5 * (a + b) + 2.2 * side + Vector2d(0, 4), "push " + away, "#c0392b",
                side.x() >= 0 ? "start" : "end", 11);
  } else {
    // Along the view direction: a dot-in-circle marks motion out of the page.
    svg += "<circle cx=\"" + SvgNum(a.x()) + "\" cy=\"" + SvgNum(a.y()) +
           "\" r=\"9\" fill=\"none\" stroke=\"#c0392b\" stroke-dasharray=\"3,2\"/>";
  }
  svg += "</g>";
  return svg;
}

// Gravity, in the corner it points from, and the scale bar.
std::string GravityAndScaleSvg(const Canvas& c, const View& v, const Vector3d& gravity) {
  std::string svg;
  const Vector2d g(gravity[v.h_axis], gravity[v.v_axis]);
  if (g.norm() > 1e-9) {
    const Vector2d u(g.x() / g.norm(), -g.y() / g.norm());
    const Vector2d at(c.x0() + c.w() - 40, c.y0() + 60);
    svg += "<g id=\"gravity\">" + Arrow(at - 18 * u, at + 18 * u, "#2e7d32", false, 1.5) +
           Text(at + Vector2d(16, 4), "g", "#2e7d32", "start") + "</g>";
  }
  const double bar = ScaleBarLength(c.w() / c.scale());
  const Vector2d b0(c.x0() + 20, c.y0() + c.h() - 20), b1 = b0 + Vector2d(bar * c.scale(), 0);
  svg += "<g id=\"scale-bar\" data-metres=\"" + FormatNumber(bar, 6) + "\"><line x1=\"" +
         SvgNum(b0.x()) + "\" y1=\"" + SvgNum(b0.y()) + "\" x2=\"" + SvgNum(b1.x()) + "\" y2=\"" +
         SvgNum(b1.y()) + "\" stroke=\"#000\" stroke-width=\"3\"/>" +
         Text(0.5 * (b0 + b1) + Vector2d(0, -7), Length(bar), "#000") + "</g>";
  return svg;
}

// One view's panel: frame, object, support, fingers, pusher, gravity, scale.
std::string ViewSvg(const Canvas& c, const View& v, const mechanics::Scene& scene,
                    const SceneDrawing& d) {
  std::string svg = "<g id=\"" + v.id + "\">";
  svg += "<rect x=\"" + SvgNum(c.x0()) + "\" y=\"" + SvgNum(c.y0()) + "\" width=\"" +
         SvgNum(c.w()) + "\" height=\"" + SvgNum(c.h()) + "\" fill=\"none\" stroke=\"#bbb\"/>";
  svg += Text({c.x0() + 8, c.y0() + 18}, v.title, "#333", "start", 12);
  svg += ObjectSvg(c, scene.object);
  svg += SupportSvg(c, scene, d);
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    const auto& f = scene.fingers[i];
    const std::string name = f.name.empty() ? "finger " + std::to_string(i) : f.name;
    svg += DrawContact(c, f, "finger-" + name, name + " (" + mechanics::ToString(f.type) + ")",
                       "#1f5fbf");
  }
  if (scene.pusher) {
    svg += DrawContact(c, *scene.pusher, "pusher",
                       std::string("pusher (") + mechanics::ToString(scene.pusher->type) + ")",
                       "#c0392b");
    if (d.moves) svg += PushMotionSvg(c, v, scene, d);
  }
  svg += GravityAndScaleSvg(c, v, scene.gravity);
  svg += "</g>";
  return svg;
}

}  // namespace

std::string SceneSvg(const mechanics::Scene& scene, const std::string& title) {
  const View views[2] = {{"view-front", "front: x right, z up (looking along +y)", 0, 2},
                         {"view-top", "top: x right, y up (looking down along -z)", 0, 1}};
  const SceneDrawing d = MakeDrawing(scene);
  const double panel_w = 470, panel_h = 430, top = 70, margin = 20;
  double scale = std::numeric_limits<double>::infinity();
  Vector2d centres[2];
  for (int k = 0; k < 2; ++k) {
    Vector2d lo = Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (const auto& p : d.all) {
      const Vector2d q(p[views[k].h_axis], p[views[k].v_axis]);
      lo = lo.cwiseMin(q);
      hi = hi.cwiseMax(q);
    }
    centres[k] = 0.5 * (lo + hi);
    const Vector2d extent = (hi - lo).cwiseMax(1e-3);
    // Room for labels around the drawing: 60 % of the panel for the set-up.
    scale = std::min({scale, 0.6 * panel_w / extent.x(), 0.6 * (panel_h - 60) / extent.y()});
  }
  const double width = 2 * panel_w + 3 * margin, height = top + panel_h + 90;
  std::string svg = "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + SvgNum(width) +
                    "\" height=\"" + SvgNum(height) + "\" viewBox=\"0 0 " + SvgNum(width) + " " +
                    SvgNum(height) + "\" font-family=\"sans-serif\">";
  svg += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>";
  svg += Text({width / 2, 26}, title, "#000", "middle", 16);
  svg += Text({width / 2, 48}, SceneCaption(scene, d), "#333", "middle", 13);
  for (int k = 0; k < 2; ++k) {
    const Canvas c(views[k], margin + k * (panel_w + margin), top, panel_w, panel_h, scale,
                   centres[k]);
    svg += ViewSvg(c, views[k], scene, d);
  }
  svg += Text({width / 2, height - 40},
              "blue: fingers, red: pusher (arrows point into the object; dashed: the pusher's "
              "path over the push), grey: the object at its start pose",
              "#555", "middle", 12);
  if (!d.support_text.empty())
    svg += Text({width / 2, height - 22},
                "brown: the support (" + d.support_text +
                    "): its plane seen edge-on, the object's footprint on it seen from above",
                "#555", "middle", 12);
  svg += "</svg>\n";
  return svg;
}

}  // namespace arena::cli
