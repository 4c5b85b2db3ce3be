// The `mujoco` simulator: the scene rebuilt in MuJoCo 2.2 (soft contact,
// elliptic cones), an engine independent of arena's contact model.
//
// Model (MJCF, built in memory, loaded through MuJoCo's VFS):
//   world = the gripper frame; gravity as the scene's.
//   object: a body with a free joint (damping object_damping: a frictionless
//     pivot otherwise oscillates about its stall angle forever), a box,
//     cylinder or prism geom (a prism: a convex mesh of its polygon's
//     vertices at ±height/2) and the scene's mass and inertia; the body's
//     origin is the centre of mass (a prism's polygon centroid).
//   finger i: a body on a slide joint along its normal, driven by a motor
//     whose force is the grip force (plus the finger's own weight along the
//     normal); with the scene's gripper.coupling "parallel_jaw" the two
//     slides are coupled (each slide axis is its normal, so joint1 = joint2
//     closes them symmetrically about a fixed centre), else independent
//     pads. The gap stays free: the grip force holds.
//   pusher: a body on a free joint with a huge armature whose qpos and qvel
//     are written before every step (a mocap body would have zero velocity
//     to the solver, and contact damping then lags it by ~2·timeconst·v).
//   pads (fingers and pusher): spheres (r 1 mm): one for a point, 5 spread
//     over a line, 6 on the 2R/3 ring of arena's patch model for a patch
//     (they carry its torsion and tilt); a point pusher without a radius a
//     sphere of 0.3 r (PointPusherSphere); every pad's surface touches the
//     object at t = 0.
//   support (a scene's `support`): a plane through the resting face and
//     small sphere feet on an equal-area grid of that face (SupportFeet);
//     a non-convex prism is cut into convex pieces (ObjectPieces); a
//     recorded pusher path drives the pusher (mechanics::PusherPoseAt).
//   contacts: explicit <pair>s only (pad with object), per-pair friction
//     (μ, torsion 0, rolling 0), condim 3, solref/solimp of the settings;
//     margin 1 mm so contacts are found before they touch, acting from
//     1 µm before touch. Pads, margin and impedance are scaled to the scene
//     (ForScene); per-step checks end a run that left MuJoCo's validity
//     with a typed error (TruthLimits).
//
// Truth per 250 Hz sample: the object's pose and twist from qpos/qvel; per
// finger / pusher the sum over its MuJoCo contacts of mj_contactForce in the
// gripper frame (force on the object), the torque about the pad's contact
// point, and the mode: separate without a loaded contact, slide when the
// tangential slip speed at a contact exceeds slip_speed, else stick; by
// default averaged over the steps since the previous sample
// (MujocoSettings::interval_forces).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <mujoco/mujoco.h>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/polygon.hpp"
#include "arena/mechanics/pusher_motion.hpp"
#include "arena/mechanics/support.hpp"
#include "arena/simulators/simulator.hpp"

namespace arena::simulators {
namespace {

// MuJoCo's default error handler calls exit(); ours throws to the caller.
[[noreturn]] void ThrowMujocoError(const char* message) {
  throw std::runtime_error(std::string("MuJoCo error: ") + message);
}
void IgnoreMujocoWarning(const char*) {}  // warnings are read from mjData::warning
void InstallMujocoHandlers() {
  static std::once_flag once;
  std::call_once(once, [] {
    mju_user_error = ThrowMujocoError;
    mju_user_warning = IgnoreMujocoWarning;
  });
}

std::string Vec(const Eigen::Vector3d& v) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g", v.x(), v.y(), v.z());
  return buf;
}
std::string Quat(const Eigen::Quaterniond& q) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g %.17g", q.w(), q.x(), q.y(), q.z());
  return buf;
}
std::string Num(double x) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

// Pad geoms per contact type: a point is one sphere; a line is kLinePads
// spheres spread evenly over it and a patch kPatchPads spheres on the 2R/3
// ring of arena's patch model (which carry its torsion and tilt). With
// PadShapes::kShapes a line is a capsule (converges like the spheres, but
// MuJoCo gives it its two end contacts only) and a patch a box (box-box
// contacts come and go with the step: 0.6 mm under a 4x finer one).
constexpr int kLinePads = 5;
constexpr int kPatchPads = 6;

int PadCount(const mechanics::ContactSpec& c, PadShapes shapes) {
  if (shapes == PadShapes::kShapes) return 1;
  switch (c.type) {
    case mechanics::ContactType::kPoint:
      return 1;
    case mechanics::ContactType::kLine:
      return kLinePads;
    case mechanics::ContactType::kPatch:
      return kPatchPads;
  }
  return 1;
}

// A pad sphere's radius: a point contact with a radius is a sphere of that
// radius (the push dataset's 4.75 mm pusher); other pads use the settings'
// pad radius (scaled to the scene).
double PadRadius(const mechanics::ContactSpec& c, double pad_radius) {
  return c.type == mechanics::ContactType::kPoint && c.radius > 0 ? c.radius : pad_radius;
}

// The pusher's sphere when the scene's pusher is a point (no radius): 0.3 of
// the pad radius. A frictionless push acts along the face's normal through
// the sphere's centre, not through the point the scene puts the pusher at,
// so a face turned by phi under a sphere of radius r is pushed r sin(phi)
// beside it: at the pad radius (1 mm) issue 31's pivot past the stall ended
// at exactly atan(d / (h - v T + r)), 2.15 % under the point's
// atan(d / (h - v T)), `ok`; at 0.3 mm, 0.66 %. A tenth (0.22 %) sank the
// sphere past half its radius (its penetration limit) in a 2 ms-step pivot
// of the model-cache tests. (The fingers sit on the axis the object turns
// about: their pads keep the pad radius.)
constexpr double kPointPusherShare = 0.3;
mechanics::PusherSpec PointPusherSphere(const mechanics::PusherSpec& pusher,
                                        const MujocoSettings& st) {
  mechanics::PusherSpec p = pusher;
  if (p.type == mechanics::ContactType::kPoint && !(p.radius > 0)) {
    p.radius = kPointPusherShare * st.pad_radius;
  }
  return p;
}

// Sphere centres (in the pad body's frame, whose origin is the contact point).
std::vector<Eigen::Vector3d> PadCentres(const mechanics::ContactSpec& c, double pad_radius) {
  const Eigen::Vector3d n = c.normal.normalized();
  const Eigen::Vector3d back = -PadRadius(c, pad_radius) * n;
  std::vector<Eigen::Vector3d> out;
  switch (c.type) {
    case mechanics::ContactType::kPoint:
      out.push_back(back);
      break;
    case mechanics::ContactType::kLine: {
      const Eigen::Vector3d a = c.axis.normalized();
      for (int j = 0; j < kLinePads; ++j) {
        const double s = c.length * (static_cast<double>(j) / (kLinePads - 1) - 0.5);
        out.push_back(back + s * a);
      }
      break;
    }
    case mechanics::ContactType::kPatch: {
      const Eigen::Vector3d t1 = mechanics::FirstTangent(n), t2 = n.cross(t1);
      const double r = 2.0 * c.radius / 3.0;
      for (int j = 0; j < kPatchPads; ++j) {
        const double phi = 2 * M_PI * j / kPatchPads;
        out.push_back(back + r * (std::cos(phi) * t1 + std::sin(phi) * t2));
      }
      break;
    }
  }
  return out;
}

// PadShapes::kShapes: a line is one capsule (MuJoCo gives it up to 2
// contacts on a face, 1 against a cylinder or mesh), a patch one thin box
// whose corners sit on the 2R/3 ring (the spheres' torsion arm).
std::string PadGeoms(const std::string& base, const mechanics::ContactSpec& c,
                     const MujocoSettings& st) {
  std::ostringstream x;
  const double pad_radius = st.pad_radius;
  if (st.pads == PadShapes::kShapes && c.type != mechanics::ContactType::kPoint) {
    const Eigen::Vector3d n = c.normal.normalized();
    const Eigen::Vector3d back = -pad_radius * n;
    if (c.type == mechanics::ContactType::kLine) {
      const Eigen::Vector3d a = 0.5 * c.length * c.axis.normalized();
      x << "      <geom name=\"" << base << "_0\" type=\"capsule\" contype=\"0\" conaffinity=\"0\" "
        << "mass=\"0\" size=\"" << Num(pad_radius) << "\" fromto=\"" << Vec(back - a) << " "
        << Vec(back + a) << "\"/>\n";
    } else {
      const double h = 2.0 * c.radius / 3.0 / std::sqrt(2.0);
      const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), n);
      x << "      <geom name=\"" << base << "_0\" type=\"box\" contype=\"0\" conaffinity=\"0\" "
        << "mass=\"0\" size=\"" << Num(h) << " " << Num(h) << " " << Num(pad_radius) << "\" pos=\""
        << Vec(back) << "\" quat=\"" << Quat(q) << "\"/>\n";
    }
    return x.str();
  }
  const auto centres = PadCentres(c, st.pad_radius);
  for (size_t j = 0; j < centres.size(); ++j) {
    x << "      <geom name=\"" << base << "_" << j
      << "\" type=\"sphere\" contype=\"0\" conaffinity=\"0\" mass=\"0\" size=\""
      << Num(PadRadius(c, pad_radius)) << "\" pos=\"" << Vec(centres[j]) << "\"/>\n";
  }
  return x.str();
}

std::string Pair(const std::string& pad, const mechanics::ContactSpec& c, const MujocoSettings& st,
                 const std::string& object = "object");

// The object's collision geoms: "object", and for a non-convex prism one
// more per convex piece ("object_piece1", ...; ObjectPieces).
std::vector<std::string> ObjectGeomNames(const mechanics::ObjectSpec& o);

// A contact acts once its distance is below margin - gap. With gap = margin
// a pad that touches at t = 0 (distance 0) acts only once it has sunk in: the
// first step then accelerates the fingers and the pusher freely into the
// object (0.5 mm at 100 N or 1 m/s). Acting from a thousandth of the margin
// before touch (1 µm at the defaults) starts every contact loaded.
constexpr double kActiveAtTouch = 1e-3;

std::string Pairs(const std::string& base, const mechanics::ContactSpec& c,
                  const MujocoSettings& st, const mechanics::ObjectSpec& o) {
  std::string all;
  for (const std::string& object : ObjectGeomNames(o)) {
    for (int j = 0; j < PadCount(c, st.pads); ++j) {
      all += "    " + Pair(base + "_" + std::to_string(j), c, st, object) + "\n";
    }
  }
  return all;
}

std::string Pair(const std::string& pad, const mechanics::ContactSpec& c, const MujocoSettings& st,
                 const std::string& object) {
  std::ostringstream x;
  x << "<pair geom1=\"" << pad << "\" geom2=\"" << object << "\" condim=\"3\" friction=\""
    << Num(c.mu) << " " << Num(c.mu) << " 0 0 0\" solref=\"" << Num(st.solref_timeconst) << " "
    << Num(st.solref_damping) << "\" solimp=\"";
  for (int k = 0; k < 5; ++k) x << Num(st.solimp[k]) << (k < 4 ? " " : "");
  x << "\" margin=\"" << Num(st.contact_margin) << "\" gap=\""
    << Num(st.contact_margin * (1 - kActiveAtTouch)) << "\"/>";
  return x.str();
}

// The most contacts MuJoCo 2.2's collision functions return for one pad
// against the object: a sphere 1, a capsule 2 (on a face), a box 8 (box on a
// box); meshes and cylinders go through the convex collider (1).
int MaxPadContacts(const mechanics::ContactSpec& c, PadShapes shapes) {
  if (shapes == PadShapes::kSpheres || c.type == mechanics::ContactType::kPoint) return 1;
  return c.type == mechanics::ContactType::kLine ? 2 : 8;
}

std::vector<Eigen::Vector3d> SupportFeet(const mechanics::Scene& scene);

// <size> for this scene. The solver's stack grows with njmax squared: a fixed
// njmax of 1200 made mj_makeData zero a 58 MB stack (10.7 ms) for every model,
// where a scene of three point pads needs some 40 constraint rows. A run whose
// contacts still overflow these bounds fails loudly (RunSamples).
std::string SizeElement(const mechanics::Scene& scene, PadShapes shapes) {
  int contacts = 0;
  for (const auto& f : scene.fingers) contacts += PadCount(f, shapes) * MaxPadContacts(f, shapes);
  if (scene.pusher)
    contacts += PadCount(*scene.pusher, shapes) * MaxPadContacts(*scene.pusher, shapes);
  // A non-convex prism's pads meet each convex piece; the support one
  // contact per foot.
  contacts *= static_cast<int>(ObjectGeomNames(scene.object).size());
  contacts += static_cast<int>(SupportFeet(scene).size());
  // Rows: up to 4 per condim-3 contact (a pyramidal cone; elliptic uses 3),
  // plus joint limits of the finger slides and the object, with room to spare.
  const int rows = 4 * contacts + 2 * static_cast<int>(scene.fingers.size()) + 16;
  std::ostringstream x;
  x << "  <size nconmax=\"" << contacts + 8 << "\" njmax=\"" << rows << "\"/>\n";
  return x.str();
}

// Signed area and centroid of a polygon (counter-clockwise: area > 0).
double PolygonArea(const std::vector<Eigen::Vector2d>& poly) {
  double a = 0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const auto &p = poly[i], &q = poly[(i + 1) % poly.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return a / 2;
}
Eigen::Vector2d PolygonCentroid(const std::vector<Eigen::Vector2d>& poly) {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (size_t i = 0; i < poly.size(); ++i) {
    const auto &p = poly[i], &q = poly[(i + 1) % poly.size()];
    c += (p + q) * (p.x() * q.y() - q.x() * p.y());
  }
  return c / (6 * PolygonArea(poly));
}

// The centre of mass in the object frame O: the body's origin in MuJoCo
// (the state arena reports is the centre of mass; a prism's polygon need not
// be centred on O's origin).
Eigen::Vector3d CentreOfMassInO(const mechanics::ObjectSpec& o) {
  if (o.shape != mechanics::ObjectShape::kPrism) return Eigen::Vector3d::Zero();
  const Eigen::Vector2d c = PolygonCentroid(o.polygon);
  return {c.x(), c.y(), 0};
}

// A prism's convex pieces: the polygon itself when convex; otherwise the
// triangles of its ear clipping (MuJoCo collides with a mesh's convex hull,
// so a non-convex outline must be cut into convex parts).
std::vector<std::vector<Eigen::Vector2d>> ObjectPieces(const mechanics::ObjectSpec& o) {
  if (o.shape != mechanics::ObjectShape::kPrism) return {};
  if (o.polygon.size() < 3 || mechanics::polygon::IsConvex(o.polygon)) return {o.polygon};
  std::vector<std::vector<Eigen::Vector2d>> pieces;
  for (const auto& t : mechanics::polygon::Triangulate(o.polygon)) {
    pieces.push_back({o.polygon[static_cast<size_t>(t[0])], o.polygon[static_cast<size_t>(t[1])],
                      o.polygon[static_cast<size_t>(t[2])]});
  }
  return pieces;
}

std::vector<std::string> ObjectGeomNames(const mechanics::ObjectSpec& o) {
  std::vector<std::string> names = {"object"};
  const size_t pieces = ObjectPieces(o).size();
  for (size_t i = 1; i < pieces; ++i) names.push_back("object_piece" + std::to_string(i));
  return names;
}

// A prism as meshes: each convex piece at z = ±height/2, relative to the
// centre of mass.
std::string PrismMesh(const mechanics::ObjectSpec& o) {
  const Eigen::Vector3d c = CentreOfMassInO(o);
  const auto pieces = ObjectPieces(o);
  std::string out = "  <asset>\n";
  for (size_t i = 0; i < pieces.size(); ++i) {
    std::string v;
    for (const double z : {-0.5 * o.height, 0.5 * o.height}) {
      for (const auto& p : pieces[i]) {
        if (!v.empty()) v += ' ';
        v += Vec(Eigen::Vector3d(p.x(), p.y(), z) - c);
      }
    }
    out += "    <mesh name=\"object_mesh" + (i == 0 ? std::string() : std::to_string(i)) +
           "\" vertex=\"" + v + "\"/>\n";
  }
  return out + "  </asset>\n";
}

// The support (a scene's `support`): a plane through the object's resting
// face, normal against gravity, and small sphere feet on that face in the
// object body that press on it. MuJoCo's own plane-box or plane-mesh
// contact puts the load on a few corners (up to 4 contacts), a pressure far
// from uniform; feet on an equal-area grid of the face (the cells of side h
// whose centres lie inside the outline) spread it about evenly, each foot's
// share set by MuJoCo's soft contact (equal while the object stays level;
// a push at mid-height shifts it, as on a real table).
constexpr double kFootRadius = 0.0005;  // m
constexpr int kFeetAcross = 10;         // grid cells along the face's longer side

std::vector<Eigen::Vector3d> SupportFeet(const mechanics::Scene& scene) {
  std::vector<Eigen::Vector3d> feet;
  if (!scene.support) return feet;
  const auto& o = scene.object;
  double cap = 0;
  try {
    cap = mechanics::SupportPressureOf(scene, 1).cap_z_O;
  } catch (const std::exception&) {
    return feet;  // CheckScene says why
  }
  std::vector<Eigen::Vector2d> outline;
  if (o.shape == mechanics::ObjectShape::kBox) {
    const double hx = o.size.x() / 2, hy = o.size.y() / 2;
    outline = {{-hx, -hy}, {hx, -hy}, {hx, hy}, {-hx, hy}};
  } else if (o.shape == mechanics::ObjectShape::kPrism) {
    outline = o.polygon;
  }
  Eigen::Vector2d lo, hi;
  if (outline.empty()) {
    lo = Eigen::Vector2d::Constant(-o.radius);
    hi = Eigen::Vector2d::Constant(o.radius);
  } else {
    lo = hi = outline[0];
    for (const auto& v : outline) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  }
  const double h = (hi - lo).maxCoeff() / kFeetAcross;
  const Eigen::Vector3d com = CentreOfMassInO(o);
  // The foot's lowest point on the face: its centre kFootRadius inside.
  const double z = cap - (cap > 0 ? 1 : -1) * kFootRadius;
  for (double x = lo.x() + h / 2; x < hi.x(); x += h) {
    for (double y = lo.y() + h / 2; y < hi.y(); y += h) {
      const Eigen::Vector2d p(x, y);
      const bool inside =
          outline.empty() ? p.norm() <= o.radius : mechanics::polygon::Contains(outline, p);
      if (inside) feet.push_back(Eigen::Vector3d(x, y, z) - com);
    }
  }
  return feet;
}

// The feet as geoms of the object body (positions relative to its centre of mass).
std::string SupportFeetGeoms(const mechanics::Scene& scene) {
  std::ostringstream x;
  const auto feet = SupportFeet(scene);
  for (size_t i = 0; i < feet.size(); ++i) {
    x << "      <geom name=\"foot" << i << "\" type=\"sphere\" size=\"" << Num(kFootRadius)
      << "\" pos=\"" << Vec(feet[i]) << "\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>\n";
  }
  return x.str();
}

// The support plane in the world: through the resting face at t = 0.
std::string SupportPlaneGeom(const mechanics::Scene& scene) {
  if (!scene.support || !(scene.gravity.norm() > 0)) return "";
  const auto& o = scene.object;
  double cap = 0;
  try {
    cap = mechanics::SupportPressureOf(scene, 1).cap_z_O;
  } catch (const std::exception&) {
    return "";
  }
  const Eigen::Matrix3d R = mechanics::RotationFromRpy(o.pose.rpy);
  const Eigen::Vector3d at = o.pose.position + R * Eigen::Vector3d(0, 0, cap);
  const Eigen::Quaterniond q =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), -scene.gravity.normalized());
  return "    <geom name=\"support\" type=\"plane\" size=\"0 0 1\" pos=\"" + Vec(at) +
         "\" quat=\"" + Quat(q) + "\" contype=\"0\" conaffinity=\"0\"/>\n";
}

// One pair per foot with the support's friction.
std::string SupportPairs(const mechanics::Scene& scene, const MujocoSettings& st) {
  std::ostringstream x;
  const size_t feet = SupportFeet(scene).size();
  for (size_t i = 0; i < feet; ++i) {
    x << "    <pair geom1=\"foot" << i << "\" geom2=\"support\" condim=\"3\" friction=\""
      << Num(scene.support->mu) << " " << Num(scene.support->mu) << " 0 0 0\" solref=\""
      << Num(st.solref_timeconst) << " " << Num(st.solref_damping) << "\" solimp=\"";
    for (int k = 0; k < 5; ++k) x << Num(st.solimp[k]) << (k < 4 ? " " : "");
    x << "\" margin=\"" << Num(st.contact_margin) << "\" gap=\"" << Num(st.contact_margin)
      << "\"/>\n";
  }
  return x.str();
}

int StepsPerSample(const MujocoSettings& s) {
  return std::max(1, static_cast<int>(std::lround(1.0 / (mechanics::kSampleRateHz * s.timestep))));
}

void Validate(const MujocoSettings& s) {
  if (!(s.timestep > 0) || s.timestep > 0.004)
    throw SimulatorError("mujoco.timestep", "must be in (0, 0.004] s");
  if (!(s.solref_timeconst > 0)) throw SimulatorError("mujoco.solref", "timeconst must be > 0");
  if (!(s.solref_damping > 0)) throw SimulatorError("mujoco.solref", "damping ratio must be > 0");
  if (!(s.solimp[0] > 0 && s.solimp[0] < 1 && s.solimp[1] > 0 && s.solimp[1] < 1 &&
        s.solimp[2] > 0 && s.solimp[3] > 0 && s.solimp[3] < 1 && s.solimp[4] >= 1))
    throw SimulatorError("mujoco.solimp", "must be 0<dmin,dmax<1, width>0, 0<mid<1, power>=1");
  if (!(s.impratio >= 1) || !std::isfinite(s.impratio))
    throw SimulatorError("mujoco.impratio", "must be >= 1");
  if (s.noslip_iterations < 0 || s.noslip_iterations > 1000)
    throw SimulatorError("mujoco.noslip_iterations", "must be 0..1000");
  if (!(s.tolerance >= 0) || s.tolerance > 1e-2)
    throw SimulatorError("mujoco.tolerance", "must be in [0, 0.01]");
  if (s.iterations < 1 || s.iterations > 10000)
    throw SimulatorError("mujoco.iterations", "must be 1..10000");
  if (!(s.object_damping >= 0) || !std::isfinite(s.object_damping))
    throw SimulatorError("mujoco.object_damping", "must be >= 0");
  if (!(s.finger_mass > 0) || !std::isfinite(s.finger_mass))
    throw SimulatorError("mujoco.finger_mass", "must be > 0");
  if (!(s.slip_speed > 0) || !std::isfinite(s.slip_speed))
    throw SimulatorError("mujoco.slip_speed", "must be > 0");
}

// ---- Scaled to the scene --------------------------------------------------
// MuJoCo's contacts are soft: a pad sinks into the object by an amount set by
// solref/solimp and the load, finds contacts within a margin, and a light
// finger body bounces on a light object. The defaults were tuned on the
// canonical scene (0.2 kg, 3 x 5 x 10 cm, 10 N); ForScene keeps them there and
// scales them where the scene is smaller or more loaded, so that the soft
// contact stays small against the scene (simulators/README.md, "Scaled to the
// scene").
constexpr double kReferenceLength = 0.03;  // m: the canonical box's smallest side
constexpr double kReferenceLoad = 250;     // m/s²: its grip, 10 N x (1/0.05 + 1/0.2) /kg
// Loads up to this many times the canonical one keep the defaults: their
// pads sink well within the penetration limit, and a stiffer contact made
// one pivot-study scene (patch pads, 68 g, 18 N: 2.5x) change 0.24 mm under
// a 4x finer timestep, against 0.0007 mm at the defaults.
constexpr double kLoadHeadroom = 4;
constexpr double kReferencePushLoad = 60;      // m/s²: its push, (2 x 0.5 x 10 + 1.96) N / 0.2 kg
constexpr double kSlowestUnscaledPush = 1e-3;  // m/s: slower pushes creep at the defaults
constexpr double kMostImpedance = 0.9999;      // MuJoCo clamps solimp's d to it (mjMAXIMP)

// The object's smallest dimension (m): a box's shortest side, a cylinder's
// diameter or height, a prism's height or its polygon's equal-area diameter.
double SmallestDimension(const mechanics::ObjectSpec& o) {
  switch (o.shape) {
    case mechanics::ObjectShape::kBox:
      return o.size.minCoeff();
    case mechanics::ObjectShape::kCylinder:
      return std::min(2 * o.radius, o.height);
    case mechanics::ObjectShape::kPrism: {
      double a = 0;
      for (size_t i = 0; i < o.polygon.size(); ++i) {
        const auto &p = o.polygon[i], &q = o.polygon[(i + 1) % o.polygon.size()];
        a += 0.5 * (p.x() * q.y() - q.x() * p.y());
      }
      return std::min(o.height, 2 * std::sqrt(std::abs(a) / M_PI));
    }
  }
  return o.size.minCoeff();
}

// `pusher_pairs`: the impedance of the pusher's contact pairs, which carry
// the push (2 mu N + m g on the object alone) rather than the grip.
MujocoSettings ForScene(const mechanics::Scene& scene, const MujocoSettings& in,
                        bool pusher_pairs = false) {
  MujocoSettings st = in;
  if (!in.scale_to_scene) return st;
  // Lengths: pads, margin and the impedance's width shrink with a small
  // object (a 1 mm pad on a 1 mm object is no point contact).
  const double k_len = std::min(1.0, SmallestDimension(scene.object) / kReferenceLength);
  st.pad_radius *= k_len;
  st.contact_margin *= k_len;
  st.solimp[2] *= k_len;
  // Masses: a finger far heavier than the object it holds bounces it off
  // (the pads are massless in the scene), so it is never heavier than the
  // object; the damping keeps its time constants (translation m/c, rotation
  // I/c with I ~ m L^2). Lighter fingers chatter more on a sliding face, so
  // an object heavier than the finger keeps the finger as set.
  const double k_mass = std::min(1.0, scene.object.mass / in.finger_mass);
  st.finger_mass *= k_mass;
  st.object_damping *= k_mass * k_len * k_len;
  // Load and speed: a soft contact sinks by about (1 - d)/d · a · timeconst²
  // (a: the acceleration its force gives the bodies it separates) and its
  // friction creeps at a speed proportional to (1 - d)/d. The canonical scene
  // (grip a = 10 N x (1/0.05 + 1/0.2) /kg = 250 m/s², push a = 60 m/s²,
  // pusher 1 cm/s) keeps the settings; pairs loaded harder (the fingers'
  // more than kLoadHeadroom times; relative to the size) or pushed slower
  // than 1 mm/s get (1 - d)/d divided by the ratio, then the time constant
  // down to 2 timesteps.
  const double m_o = scene.object.mass, m_f = st.finger_mass;
  const double weight = m_o * scene.gravity.norm();
  double ratio = scene.grip_force * (1 / m_f + 1 / m_o) / (kLoadHeadroom * kReferenceLoad);
  if (pusher_pairs && scene.pusher) {
    // The pusher's contact: the canonical push, (2 x 0.5 x 10 N + 1.96 N) /
    // 0.2 kg = 60 m/s², sinks the pusher as far as the grip sinks a finger.
    double mu_n = 0;
    for (const auto& f : scene.fingers) mu_n += f.mu * scene.grip_force;
    ratio = (mu_n + weight) / m_o / kReferencePushLoad;
  }
  ratio = std::max(1.0, ratio / k_len);
  if (scene.pusher) {
    // A recorded path's velocity field is unused (zero): its fastest segment.
    const double v = mechanics::PusherPeakRates(*scene.pusher).velocity.norm();
    if (v > 0) ratio = std::max(ratio, kSlowestUnscaledPush / v);
  }
  if (ratio > 1) {
    const double timestep = 1.0 / (mechanics::kSampleRateHz * StepsPerSample(st));
    double achieved = ratio;  // the smaller reduction of (1 - d)/d of dmin and dmax
    for (const int k : {0, 1}) {
      const double odds = (1 - in.solimp[k]) / in.solimp[k];
      const double d = std::max(in.solimp[k], std::min(kMostImpedance, 1 / (1 + odds / ratio)));
      achieved = std::min(achieved, odds / ((1 - d) / d));
      st.solimp[k] = d;
    }
    // What the impedance could not give, the time constant does (down to
    // MuJoCo's own floor of two timesteps); penetration goes with its square.
    if (achieved < ratio) {
      st.solref_timeconst =
          std::max(2 * timestep, in.solref_timeconst / std::sqrt(ratio / achieved));
    }
  }
  return st;
}

// Whether two scenes' derived settings build the same model.
bool SameTuning(const MujocoSettings& a, const MujocoSettings& b) {
  return a.finger_mass == b.finger_mass && a.object_damping == b.object_damping &&
         a.pad_radius == b.pad_radius && a.contact_margin == b.contact_margin &&
         std::equal(a.solimp, a.solimp + 5, b.solimp) && a.solref_timeconst == b.solref_timeconst &&
         a.solref_damping == b.solref_damping && a.timestep == b.timestep;
}

// A parallel jaw: the two finger slides travel alike (each along its own
// normal, so the fingers close symmetrically about a centre fixed in the
// hand). As stiff as the contacts: at MuJoCo's default equality solref
// (0.02 s) the fingers drifted 0.1 mm apart within 0.05 s of a 10 N push.
std::string JawEquality(const MujocoSettings& st) {
  std::ostringstream x;
  x << "  <equality>\n    <joint joint1=\"finger0\" joint2=\"finger1\" polycoef=\"0 1 0 0 0\" "
    << "solref=\"" << Num(st.solref_timeconst) << " " << Num(st.solref_damping) << "\" solimp=\"";
  for (int k = 0; k < 5; ++k) x << Num(st.solimp[k]) << (k < 4 ? " " : "");
  x << "\"/>\n  </equality>\n";
  return x.str();
}

// ---- The truth's limits -----------------------------------------------------
// Checked after every step: where MuJoCo's answer stops being the scene's
// physics, the run ends with a typed error saying which limit and by how much
// instead of returning a wrong trajectory as a truth.
class TruthLimits {
 public:
  TruthLimits(const mechanics::Scene& scene, const MujocoSettings& st) : scene_(scene), st_(st) {
    extent_ = scene.object.shape == mechanics::ObjectShape::kBox
                  ? scene.object.size.maxCoeff()
                  : std::max(2 * scene.object.radius, scene.object.height);
    if (scene.object.shape == mechanics::ObjectShape::kPrism) {
      for (const auto& p : scene.object.polygon) extent_ = std::max(extent_, 2 * p.norm());
    }
    grip_axis_ = FixedGripAxis(scene);
  }
  // The largest penetration (m) an active pad contact may have: beyond it the
  // pose is off by more than the truth's accuracy and a sphere pad's contact
  // normal turns with its depth.
  // A pad's own radius, where smaller than the settings' (a point pusher's
  // sphere), sets its limit: sunk past half of it, the face is near its centre.
  double PenetrationLimit(const mjModel* m, int geom) const {
    const mjtNum* size = m->geom_size + 3 * geom;
    const double radius = m->geom_type[geom] == mjGEOM_BOX ? size[2] : size[0];
    return 0.5 * std::min(st_.pad_radius, radius);
  }

  // "" while within the limits; otherwise which limit, when, by how much.
  // `object_geom`, `pad_of_geom`: the run's ids; `start`: the object's
  // centre at t = 0; `pusher_speed`: the pusher's speed now.
  std::string Check(const mjModel* m, const mjData* d, int object_qpos, int object_qvel,
                    int object_geom, const std::vector<int>& pad_of_geom,
                    const std::vector<int>& finger_qpos, const Eigen::Vector3d& start,
                    double pusher_speed) {
    const double t = d->time;
    const double g = scene_.gravity.norm();
    // Penetration of an active pad contact.
    for (int i = 0; i < d->ncon; ++i) {
      const mjContact& c = d->contact[i];
      if (c.exclude != 0 || c.efc_address < 0) continue;
      const int other = c.geom1 == object_geom ? c.geom2 : c.geom2 == object_geom ? c.geom1 : -1;
      if (other < 0 || pad_of_geom[static_cast<size_t>(other)] < 0) continue;
      // A finger's pad rolling over an edge of the gripped face: the grasp
      // is ending (the object leaves the fingers) and the grip axis no longer
      // holds the centre, for the rest of the run.
      const size_t pad = static_cast<size_t>(pad_of_geom[static_cast<size_t>(other)]);
      if (grip_axis_ && pad < scene_.fingers.size() &&
          std::abs(grip_axis_->dot(Eigen::Vector3d(c.frame[0], c.frame[1], c.frame[2]))) <
              std::cos(kOffTheFace)) {
        grip_axis_.reset();
      }
      if (-c.dist > PenetrationLimit(m, other)) {
        return Fail("penetration", t,
                    "a pad sinks " + Num(-c.dist) + " m into the object (limit " +
                        Num(PenetrationLimit(m, other)) +
                        " m, half the pad radius): the soft contact cannot carry this load "
                        "(grip, weight or pusher speed) at this timestep");
      }
    }
    // Ejection: farther than the pusher and a free fall could have carried it.
    const mjtNum* qp = d->qpos + object_qpos;
    const Eigen::Vector3d p(qp[0], qp[1], qp[2]);
    travel_ += pusher_speed * m->opt.timestep;
    const double reach = travel_ + 0.5 * g * t * t + extent_;
    if (!((p - start).norm() <= reach)) {
      return Fail("ejection from the grasp", t,
                  "the object moved " + Num((p - start).norm()) +
                      " m, farther than the pusher's travel, a free fall and its own extent (" +
                      Num(reach) + " m) allow");
    }
    // Energy growth: its centre faster than the pusher (twice its speed: an
    // elastic rebound), a free fall and a small start kick could make it.
    // (Not its spin: a pusher close to the axis a pivot turns about turns it
    // fast, rightly.)
    const mjtNum* qv = d->qvel + object_qvel;
    const double speed = Eigen::Vector3d(qv[0], qv[1], qv[2]).norm();
    const double bound = 2 * pusher_speed + g * t + 0.01 * extent_ / 0.1;
    if (!(speed <= bound)) {
      return Fail("energy growth", t,
                  "the object's centre moves at " + Num(speed) +
                      " m/s, more than the pusher, "
                      "gravity and the start can give it (" +
                      Num(bound) + " m/s)");
    }
    // Drift along the grip axis (see FixedGripAxis): the grasp's closed form
    // keeps the object's centre there; beyond the truth's accuracy (1 % of
    // the push so far plus 1e-3 of the object's extent, the tolerance the
    // extremes table judges positions by) the soft contact's chatter, not
    // the scene, moves it.
    if (grip_axis_) {
      const double drift = std::abs((p - start).dot(*grip_axis_));
      const double allowed = 0.01 * travel_ + 1e-3 * extent_;
      if (!(drift <= allowed)) {
        return Fail("drift along the grip axis", t,
                    "the object's centre moved " + Num(drift) +
                        " m along the grip axis, where nothing in the scene moves it (limit " +
                        Num(allowed) +
                        " m: 1 % of the pusher's travel plus 1e-3 of the object's extent): "
                        "the free fingers' soft contacts chatter and the grasp drifts");
      }
    }
    // The jaw's coupling: both fingers travel alike.
    if (scene_.gripper.coupling == mechanics::GripperCoupling::kParallelJaw &&
        finger_qpos.size() == 2) {
      const double gap = std::abs(d->qpos[finger_qpos[0]] - d->qpos[finger_qpos[1]]);
      if (gap > 0.1 * st_.pad_radius) {
        return Fail("constraint violation", t,
                    "the parallel jaw's fingers travel " + Num(gap) +
                        " m apart (limit a tenth of the pad radius, " + Num(0.1 * st_.pad_radius) +
                        " m)");
      }
    }
    return "";
  }

 private:
  static std::string Fail(const char* limit, double t, const std::string& what) {
    return std::string("MuJoCo outside its limits at t = ") + Num(t) + " s (" + limit +
           "): " + what;
  }
  // The grip axis of a scene in which nothing moves the object along it, or
  // none. Two independent fingers pressing along opposite normals put equal
  // and opposite grip forces on it; a pusher moving perpendicular to it
  // (turning, if at all, about it) and gravity perpendicular to it push
  // across it, so sliding in the grasp and pivoting about the axis between
  // the fingers both leave the centre's coordinate along it unchanged. (MuJoCo
  // measured otherwise: the line finger's normal force chattering 8.7-11.4 N
  // about a 10 N grip, the grasp drifting 0.16-0.54 mm in 0.2 s: bench/README.md,
  // the extremes per simulator.) A jaw, a recorded path or a closed loop
  // (whose direction is not known before the run) is not judged, nor an
  // object whose gripped faces are not square to the axis at the start: a
  // box turned 5 mrad about y re-seats flat on the line finger, turning
  // near the pusher's contact, and its centre rightly moves 0.17 mm along
  // the axis (a cell's placement noise does this: 0.25 mm in a calibration
  // trial also placed off centre and turned about z). Only a box is judged.
  static std::optional<Eigen::Vector3d> FixedGripAxis(const mechanics::Scene& scene) {
    if (scene.gripper.coupling == mechanics::GripperCoupling::kParallelJaw) return std::nullopt;
    if (scene.fingers.size() != 2 || !scene.pusher) return std::nullopt;
    if (scene.object.shape != mechanics::ObjectShape::kBox) return std::nullopt;
    const auto& pusher = *scene.pusher;
    if (pusher.path || pusher.controller) return std::nullopt;
    const Eigen::Vector3d a = scene.fingers[0].normal.normalized();
    const Eigen::Vector3d b = scene.fingers[1].normal.normalized();
    constexpr double kSquare = 1e-9;  // "perpendicular": cosines under this
    if (!(a.dot(b) < -1 + kSquare)) return std::nullopt;
    const Eigen::Vector3d& v = pusher.motion.velocity;
    const Eigen::Vector3d& w = pusher.motion.angular_velocity;
    const Eigen::Vector3d& g = scene.gravity;
    if (!(v.norm() > 0) || std::abs(v.dot(a)) > kSquare * v.norm()) return std::nullopt;
    if (w.cross(a).norm() > kSquare * w.norm()) return std::nullopt;
    if (std::abs(g.dot(a)) > kSquare * g.norm()) return std::nullopt;
    // The box's own axes in the gripper frame: one of them along the grip axis.
    const Eigen::Matrix3d R = mechanics::RotationFromRpy(scene.object.pose.rpy);
    if (!((R.transpose() * a).cwiseAbs().maxCoeff() > 1 - kSquare)) return std::nullopt;
    return a;
  }

  // A pad contact whose normal turns more than this (rad) from the grip axis
  // is past the face's edge (a chattering grasp turns it under 0.1 mrad).
  static constexpr double kOffTheFace = 0.01;
  const mechanics::Scene& scene_;
  const MujocoSettings& st_;
  double extent_ = 0;
  double travel_ = 0;
  std::optional<Eigen::Vector3d> grip_axis_;
};

// A push too short for the soft contact to resolve. The pusher's contact
// acts from a = margin x kActiveAtTouch before touch (1 µm at the defaults),
// so at t = 0 it sets the object a little ahead of the pusher, which then
// has to travel up to a before it loads the object again. A run whose whole
// travel (its peak speed x duration, an upper bound) is under 4a spends more
// than a quarter of it unloaded, and the object's motion is the contact's
// start transient, not the push (the 1e-6 m/s row of the extremes table:
// 0.2 µm of travel, pusher force 0 N in a jaw where 11.96 N is right, the
// grasp drifting 0.78 mm with free pads). Refused before the first step;
// closed-loop runs (commanded speeds) and a pusher at rest are not judged.
std::string PushBelowResolution(const mechanics::Scene& scene, const MujocoSettings& settings,
                                bool commanded) {
  if (commanded || !scene.pusher || scene.pusher->controller) return "";
  const double travel = mechanics::PusherPeakRates(*scene.pusher).velocity.norm() * scene.duration;
  const double a = ForScene(scene, settings, true).contact_margin * kActiveAtTouch;
  if (!(travel > 0) || travel >= 4 * a) return "";
  return "MuJoCo outside its limits at t = 0 s (push below the contact's resolution): the "
         "pusher travels at most " +
         Num(travel) + " m over the run, less than 4 x the " + Num(a) +
         " m before touch at which its soft contact acts (limit " + Num(4 * a) +
         " m): the object would follow the contact's start transient, not the push";
}

// A push slower than the fingers' soft friction creeps. In a contact's
// friction rows MuJoCo solves J qacc + R f = -B v, so a steady slip v carries
// a friction force of at most B v / R, and the full mu N needs a slip of at
// least v_full = R mu N / B. Where a finger's v_full (at the grip, t = 0)
// exceeds the pusher's speed, the finger cannot slide with Coulomb's mu N at
// the speed the push drives it, nor tell a slide from a stick: the unscaled
// 1e-4 m/s push carried 4.5 N of the 11.96 N of 2 mu N + m g, `ok`. Scaled to
// the scene (ForScene raises the impedance for slow pushes) v_full stays
// below the push. Judged once, before the first step, on a pusher at its
// set velocity: not a closed loop (a controller slows down near its target,
// where the fingers stick) nor a recorded path; elliptic cones only (their
// friction rows follow the normal row).
std::string FrictionCreep(const mjModel* m, const mjData* d, const mechanics::Scene& scene,
                          const std::vector<int>& pad_of_geom, const std::vector<char>& is_object,
                          bool commanded) {
  if (commanded || !scene.pusher || scene.pusher->path || scene.pusher->controller) return "";
  if (m->opt.cone != mjCONE_ELLIPTIC) return "";
  const double speed = scene.pusher->motion.velocity.norm();
  if (!(speed > 0)) return "";
  for (int i = 0; i < d->ncon; ++i) {
    const mjContact& c = d->contact[i];
    if (c.exclude != 0 || c.efc_address < 0 || c.dim < 3) continue;
    const bool object1 = is_object[static_cast<size_t>(c.geom1)] != 0;
    const int other = object1 ? c.geom2 : c.geom1;
    if (!object1 && is_object[static_cast<size_t>(c.geom2)] == 0) continue;
    const int pad = pad_of_geom[static_cast<size_t>(other)];
    if (pad < 0 || static_cast<size_t>(pad) >= scene.fingers.size()) continue;
    const int row = c.efc_address;
    const double normal = d->efc_force[row], damping = d->efc_KBIP[4 * (row + 1) + 1];
    if (!(normal > 0) || !(damping > 0)) continue;
    const double full = d->efc_R[row + 1] * c.friction[0] * normal / damping;
    if (full <= speed) continue;
    return "MuJoCo outside its limits at t = 0 s (friction creep): finger " + std::to_string(pad) +
           "'s soft friction builds its full mu N only at a slip of " + Num(full) +
           " m/s, faster than the pusher's " + Num(speed) +
           " m/s: it creeps where Coulomb friction would slide or stick";
  }
  return "";
}

// Owns a model and its data; frees them on every path.
struct MjHandles {
  mjModel* m = nullptr;
  mjData* d = nullptr;
  ~MjHandles() { Reset(); }
  void Reset() {
    if (d) mj_deleteData(d);
    if (m) mj_deleteModel(m);
    d = nullptr;
    m = nullptr;
  }
};

mjModel* LoadFromText(const std::string& xml, std::string* error) {
  auto vfs = std::make_unique<mjVFS>();  // ~2 MB: never on the stack
  mj_defaultVFS(vfs.get());
  const char* name = "scene.xml";
  if (mj_makeEmptyFileVFS(vfs.get(), name, static_cast<int>(xml.size())) != 0) {
    *error = "MuJoCo VFS: cannot make the model file";
    return nullptr;
  }
  const int i = mj_findFileVFS(vfs.get(), name);
  std::memcpy(vfs->filedata[i], xml.data(), xml.size());
  char err[1024] = "";
  mjModel* m = mj_loadXML(name, vfs.get(), err, sizeof err);
  mj_deleteVFS(vfs.get());
  if (!m) *error = std::string("MuJoCo rejected the model: ") + err;
  return m;
}

}  // namespace

// Idle compiled models by key (the MJCF without its <option> line, plus the
// gravity that line carries), least recently used first.
class MujocoModelCache {
 public:
  explicit MujocoModelCache(std::size_t models) : keep_(models) {}
  ~MujocoModelCache() {
    for (auto& e : idle_) Free(e);
  }
  struct Entry {
    std::string key;
    mjModel* m = nullptr;
    mjData* d = nullptr;
  };
  // An idle entry for `key`, or an empty one (the caller builds it).
  Entry Take(const std::string& key) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = idle_.begin(); it != idle_.end(); ++it) {
      if (it->key == key) {
        Entry e = std::move(*it);
        idle_.erase(it);
        return e;
      }
    }
    return Entry{key, nullptr, nullptr};
  }
  void Give(Entry e) {
    if (!e.m || !e.d || keep_ == 0) {
      Free(e);
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    idle_.push_back(std::move(e));
    while (idle_.size() > keep_) {
      Free(idle_.front());
      idle_.erase(idle_.begin());
    }
  }

 private:
  static void Free(Entry& e) {
    if (e.d) mj_deleteData(e.d);
    if (e.m) mj_deleteModel(e.m);
    e.d = nullptr;
    e.m = nullptr;
  }
  std::size_t keep_;
  std::mutex mutex_;
  std::vector<Entry> idle_;
};

namespace {

// The cache key of a model: its MJCF without the <option> line (whose knobs
// are written into the model before each run), plus the gravity that line
// also carries.
std::string CacheKey(const std::string& xml, const mechanics::Scene& scene) {
  const auto start = xml.find("  <option ");
  const auto end = start == std::string::npos ? start : xml.find('\n', start);
  if (end == std::string::npos) return xml;
  return xml.substr(0, start) + xml.substr(end + 1) + "gravity " + Vec(scene.gravity);
}

// The <option> knobs of the settings, as the MJCF's option line sets them.
void WriteOptions(mjModel* m, const mechanics::Scene& scene, const MujocoSettings& st) {
  m->opt.timestep = 1.0 / (mechanics::kSampleRateHz * StepsPerSample(st));
  for (int k = 0; k < 3; ++k) m->opt.gravity[k] = scene.gravity[k];
  m->opt.cone = st.elliptic ? mjCONE_ELLIPTIC : mjCONE_PYRAMIDAL;
  m->opt.impratio = st.impratio;
  m->opt.noslip_iterations = st.noslip_iterations;
  m->opt.tolerance = st.tolerance;
  m->opt.iterations = st.iterations;
}

class MujocoSimulator final : public Simulator {
 public:
  MujocoSimulator(const MujocoSettings& s, std::shared_ptr<MujocoModelCache> cache)
      : settings_(s), cache_(std::move(cache)) {
    Validate(s);
    InstallMujocoHandlers();
  }
  std::string name() const override { return "mujoco"; }
  TruthKind truth() const override { return TruthKind::kIndependent; }
  std::string settings_json() const override {
    const auto& s = settings_;
    return nlohmann::json(
               {{"engine", std::string("MuJoCo ") + mj_versionString()},
                {"timestep", 1.0 / (mechanics::kSampleRateHz * StepsPerSample(s))},
                {"cone", s.elliptic ? "elliptic" : "pyramidal"},
                {"solref", {s.solref_timeconst, s.solref_damping}},
                {"solimp", {s.solimp[0], s.solimp[1], s.solimp[2], s.solimp[3], s.solimp[4]}},
                {"impratio", s.impratio},
                {"noslip_iterations", s.noslip_iterations},
                {"tolerance", s.tolerance},
                {"iterations", s.iterations},
                {"object_damping", s.object_damping},
                {"finger_mass", s.finger_mass},
                {"slip_speed", s.slip_speed},
                {"pads", s.pads == PadShapes::kSpheres ? "spheres" : "shapes"},
                {"forces", s.interval_forces ? "interval" : "instant"},
                {"scale_to_scene", s.scale_to_scene}})
        .dump();
  }
  std::string CheckScene(const mechanics::Scene& scene) const override {
    const auto& o = scene.object;
    if (o.shape == mechanics::ObjectShape::kPrism &&
        (o.polygon.size() < 3 || !(PolygonArea(o.polygon) > 0)))
      return "object.polygon: the mujoco simulator needs a counter-clockwise polygon of area > 0";
    if (scene.support) {
      if (!scene.support->pressure_points.empty())
        return "support.pressure.points: the mujoco simulator spreads the support's load by its "
               "own soft contacts on feet over the face (uniform pressure); weighted points are "
               "arena's model only";
      if (SupportFeet(scene).empty())
        return "support: the object rests on no z cap (its z axis must be along gravity)";
    }
    return "";
  }
  mechanics::SimulationResult Simulate(const mechanics::Scene& scene) const override {
    return SimulateWith(scene, nullptr);
  }
  // Closed loop (issue 19): the pusher is driven kinematically anyway, so a
  // command only changes its velocity from the sample it answers on.
  bool closed_loop() const override { return true; }
  mechanics::SimulationResult SimulateClosedLoop(
      const mechanics::Scene& scene,
      const mechanics::PusherCommandSource& commands) const override {
    return SimulateWith(scene, &commands);
  }
  std::unique_ptr<PreparedScene> Prepare(const mechanics::Scene& scene) const override;

 private:
  mechanics::SimulationResult SimulateWith(const mechanics::Scene& scene,
                                           const mechanics::PusherCommandSource* commands) const;
  MujocoSettings settings_;
  std::shared_ptr<MujocoModelCache> cache_;
};

// Per-run state: ids into the model and the scene's kinematics.
struct Run {
  const mechanics::Scene& scene;
  const MujocoSettings& st;
  mjModel* m;
  mjData* d;
  int object_body = -1, object_qpos = -1, object_qvel = -1;
  int pusher_body = -1, pusher_qpos = -1, pusher_qvel = -1;
  std::vector<int> finger_qpos, finger_qvel;
  std::vector<int> pad_of_geom;  // geom id -> finger index (then the pusher), -1: none
  size_t n_pads = 0;
  int object_geom = -1;
  std::vector<char> is_object;  // geom id -> one of the object's collision geoms
  // Closed loop: the pusher's velocity in force since pusher_t0, when it was
  // at pusher_base (commanded is false: the scene's constant motion).
  bool commanded = false;
  Eigen::Vector3d pusher_base = Eigen::Vector3d::Zero(), pusher_v = Eigen::Vector3d::Zero();
  double pusher_t0 = 0;

  const Eigen::Vector3d& PusherVelocity() const {
    return commanded ? pusher_v : scene.pusher->motion.velocity;
  }
  // The fastest a point of the pusher's pad near the object moves (m/s).
  double PusherSpeed() const {
    const double reach = std::max(scene.pusher->length, 2 * scene.pusher->radius);
    if (scene.pusher->path) {
      // A recorded path (velocity field unused, zero): its peak rates, once.
      if (path_speed < 0) {
        const mechanics::PusherTwist peak = mechanics::PusherPeakRates(*scene.pusher);
        path_speed = peak.velocity.norm() + peak.angular_velocity.norm() * reach;
      }
      return path_speed;
    }
    return PusherVelocity().norm() + scene.pusher->motion.angular_velocity.norm() * reach;
  }
  mutable double path_speed = -1;  // PusherSpeed of a path pusher, < 0 until computed
  // A command from time t on (the pusher stays where it is then). The
  // velocity in force again changes nothing, to the last bit.
  void CommandPusher(double t, const Eigen::Vector3d& velocity) {
    if (velocity == PusherVelocity()) return;
    Eigen::Quaterniond q;
    PusherAt(t, &pusher_base, &q);
    pusher_t0 = t;
    pusher_v = velocity;
    commanded = true;
  }

  // Pusher contact point and orientation at time t (constant twist about the
  // contact point, or its recorded path).
  void PusherAt(double t, Eigen::Vector3d* p, Eigen::Quaterniond* q) const {
    const auto& ps = *scene.pusher;
    if (ps.path) {
      const mechanics::PusherPose pose = mechanics::PusherPoseAt(ps, t);
      *p = pose.position;
      *q = Eigen::Quaterniond(pose.rotation);
      return;
    }
    *p = commanded ? Eigen::Vector3d(pusher_base + pusher_v * (t - pusher_t0))
                   : Eigen::Vector3d(ps.position + ps.motion.velocity * t);
    const Eigen::Vector3d w = ps.motion.angular_velocity;
    *q = w.norm() > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(w.norm() * t, w.normalized()))
                      : Eigen::Quaterniond::Identity();
  }
  void DrivePusher(double t) {
    if (pusher_body < 0) return;
    Eigen::Vector3d p;
    Eigen::Quaterniond q;
    PusherAt(t, &p, &q);
    mjtNum* qp = d->qpos + pusher_qpos;
    for (int k = 0; k < 3; ++k) qp[k] = p[k];
    qp[3] = q.w(), qp[4] = q.x(), qp[5] = q.y(), qp[6] = q.z();
    const mechanics::PusherTwist twist = PathTwist(t);
    const Eigen::Vector3d w_local = q.conjugate() * twist.angular_velocity;
    mjtNum* qv = d->qvel + pusher_qvel;
    for (int k = 0; k < 3; ++k) qv[k] = twist.velocity[k], qv[3 + k] = w_local[k];
  }

  // The pusher's twist over the step from t: its constant motion (or the
  // command in force), or its recorded path's mean motion over the step.
  mechanics::PusherTwist PathTwist(double t) const {
    if (scene.pusher->path) return mechanics::PusherTwistOver(*scene.pusher, t, m->opt.timestep);
    return {PusherVelocity(), scene.pusher->motion.angular_velocity};
  }
  // Velocity of the pad carrying contact index `who` at world point p.
  Eigen::Vector3d PadVelocity(size_t who, const Eigen::Vector3d& p, double t) const {
    if (who < scene.fingers.size())
      return d->qvel[finger_qvel[who]] * scene.fingers[who].normal.normalized();
    Eigen::Vector3d c;
    Eigen::Quaterniond q;
    PusherAt(t, &c, &q);
    const mechanics::PusherTwist twist = PathTwist(t);
    return twist.velocity + twist.angular_velocity.cross(p - c);
  }
  // The pad's contact point now (where its surface met the object at t = 0).
  Eigen::Vector3d PadPoint(size_t who, double t) const {
    if (who < scene.fingers.size()) {
      const auto& f = scene.fingers[who];
      return f.position + d->qpos[finger_qpos[who]] * f.normal.normalized();
    }
    Eigen::Vector3d c;
    Eigen::Quaterniond q;
    PusherAt(t, &c, &q);
    return c;
  }
  // The axis a pad's force is split along: the normal the scene gives it, as
  // every reader of a sample puts it back together (assessment::
  // ContactNormals). A turning pusher's own normal was used before, so the
  // store rebuilt a force that was not the one measured.
  Eigen::Vector3d PadNormal(size_t who) const {
    if (who < scene.fingers.size()) return scene.fingers[who].normal.normalized();
    return scene.pusher->normal.normalized();
  }

  // What each pad (fingers, then the pusher) did to the object in one solve.
  struct PadReading {
    std::vector<Eigen::Vector3d> force, torque;  // on the object, gripper frame
    std::vector<int> touching, sliding;          // solves in which it touched / slid
    int solves = 0;
    explicit PadReading(size_t n)
        : force(n, Eigen::Vector3d::Zero()),
          torque(n, Eigen::Vector3d::Zero()),
          touching(n, 0),
          sliding(n, 0) {}
  };

  // Adds the contacts of the last solve (d->contact and d->efc_force, as
  // mj_step or mj_forward left them) to `r`.
  void Read(PadReading* r) const {
    const mjtNum* qp = d->qpos + object_qpos;
    const mjtNum* qv = d->qvel + object_qvel;
    const Eigen::Vector3d position(qp[0], qp[1], qp[2]);
    const Eigen::Quaterniond orientation =
        Eigen::Quaterniond(qp[3], qp[4], qp[5], qp[6]).normalized();
    const Eigen::Vector3d velocity(qv[0], qv[1], qv[2]);
    const Eigen::Vector3d angular_velocity = orientation * Eigen::Vector3d(qv[3], qv[4], qv[5]);
    std::vector<bool> touching(n_pads, false), sliding(n_pads, false);
    for (int i = 0; i < d->ncon; ++i) {
      const mjContact& c = d->contact[i];
      if (c.exclude != 0 || c.efc_address < 0) continue;  // found in the margin, not active
      const bool object1 = is_object[static_cast<size_t>(c.geom1)] != 0;
      const bool object2 = is_object[static_cast<size_t>(c.geom2)] != 0;
      const int other = object1 ? c.geom2 : object2 ? c.geom1 : -1;
      if (other < 0 || pad_of_geom[static_cast<size_t>(other)] < 0) continue;
      const size_t who = static_cast<size_t>(pad_of_geom[static_cast<size_t>(other)]);
      mjtNum f6[6];
      mj_contactForce(m, d, i, f6);
      // Contact frame rows: normal (from geom1 to geom2), tangents. The force is
      // geom1's on geom2; our pairs put the pad first, so it is the pad's on the object.
      Eigen::Vector3d f_W = Eigen::Vector3d::Zero(), tau_W = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d axis(c.frame[3 * k], c.frame[3 * k + 1], c.frame[3 * k + 2]);
        f_W += f6[k] * axis;
        tau_W += f6[3 + k] * axis;
      }
      if (object1) f_W = -f_W, tau_W = -tau_W;
      const Eigen::Vector3d p(c.pos[0], c.pos[1], c.pos[2]);
      const Eigen::Vector3d ref = PadPoint(who, d->time);
      r->force[who] += f_W;
      r->torque[who] += tau_W + (p - ref).cross(f_W);
      if (f_W.norm() > 0) touching[who] = true;
      const Eigen::Vector3d n(c.frame[0], c.frame[1], c.frame[2]);
      Eigen::Vector3d u =
          velocity + angular_velocity.cross(p - position) - PadVelocity(who, p, d->time);
      u -= u.dot(n) * n;
      if (u.norm() > st.slip_speed) sliding[who] = true;
    }
    for (size_t k = 0; k < n_pads; ++k) {
      r->touching[k] += touching[k] ? 1 : 0;
      r->sliding[k] += touching[k] && sliding[k] ? 1 : 0;
    }
    ++r->solves;
  }

  // The sample now: pose and twist of the state; forces the mean of `r`'s
  // solves; a pad separate when it touched in none, sliding when it slid in
  // at least half of those in which it touched.
  mechanics::TrajectorySample Sample(const PadReading& r) const {
    mechanics::TrajectorySample s;
    s.t = d->time;
    const mjtNum* qp = d->qpos + object_qpos;
    const mjtNum* qv = d->qvel + object_qvel;
    s.position = Eigen::Vector3d(qp[0], qp[1], qp[2]);
    s.orientation = Eigen::Quaterniond(qp[3], qp[4], qp[5], qp[6]).normalized();
    s.velocity = Eigen::Vector3d(qv[0], qv[1], qv[2]);
    s.angular_velocity = s.orientation * Eigen::Vector3d(qv[3], qv[4], qv[5]);
    const double per_solve = 1.0 / std::max(1, r.solves);
    for (size_t k = 0; k < n_pads; ++k) {
      mechanics::ContactState cs;
      const Eigen::Vector3d n = PadNormal(k);
      const Eigen::Vector3d f = r.force[k] * per_solve;
      cs.normal_force = f.dot(n);
      cs.tangential_force = f - cs.normal_force * n;
      cs.torque = r.torque[k] * per_solve;
      cs.mode = r.touching[k] == 0                  ? mechanics::ContactMode::kSeparate
                : 2 * r.sliding[k] >= r.touching[k] ? mechanics::ContactMode::kSlide
                                                    : mechanics::ContactMode::kStick;
      s.contacts.push_back(cs);
    }
    if (scene.pusher) {
      Eigen::Quaterniond q;
      PusherAt(s.t, &s.pusher_position, &q);
      s.pusher_force = r.force.back() * per_solve;
    }
    return s;
  }
};

bool Finite(const mechanics::TrajectorySample& s) {
  if (!s.position.allFinite() || !s.orientation.coeffs().allFinite() || !s.velocity.allFinite() ||
      !s.angular_velocity.allFinite() || !s.pusher_force.allFinite())
    return false;
  for (const auto& c : s.contacts)
    if (!std::isfinite(c.normal_force) || !c.tangential_force.allFinite() || !c.torque.allFinite())
      return false;
  return true;
}

// A closed loop's command, checked before it is put in force: empty when usable.
std::string CheckCommand(const mechanics::Scene& scene, const mechanics::PusherMotion& command) {
  if (!command.velocity.allFinite() || !command.angular_velocity.allFinite())
    return "pusher command: not finite";
  if (command.angular_velocity != scene.pusher->motion.angular_velocity)
    return "pusher command: angular velocity differs from the scene's (the pusher turns at a "
           "constant rate only)";
  return "";
}

// RunLoaded's phases, in the order it runs them.

// A run refused or stopped by a failure: one failure, at `failed_step`.
void Fail(mechanics::SimulationResult* result, int failed_step, std::string why) {
  result->status = mechanics::SimulationStatus::kSolverFailure;
  result->failed_step = failed_step;
  result->solver.failures = 1;
  result->error = std::move(why);
}

// Set-up: finds the object's, the fingers' and the pusher's bodies, joints
// and pad geoms in the loaded model.
void BindRun(Run* run) {
  const mechanics::Scene& scene = run->scene;
  const mjModel* m = run->m;
  run->pad_of_geom.assign(static_cast<size_t>(m->ngeom), -1);
  run->n_pads = scene.fingers.size() + (scene.pusher ? 1 : 0);
  run->object_body = mj_name2id(m, mjOBJ_BODY, "object");
  run->object_geom = mj_name2id(m, mjOBJ_GEOM, "object");
  run->is_object.assign(static_cast<size_t>(m->ngeom), 0);
  for (const std::string& name : ObjectGeomNames(scene.object))
    run->is_object[static_cast<size_t>(mj_name2id(m, mjOBJ_GEOM, name.c_str()))] = 1;
  const int oj = m->body_jntadr[run->object_body];
  run->object_qpos = m->jnt_qposadr[oj];
  run->object_qvel = m->jnt_dofadr[oj];
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    const std::string k = std::to_string(i);
    const int j = mj_name2id(m, mjOBJ_JOINT, ("finger" + k).c_str());
    run->finger_qpos.push_back(m->jnt_qposadr[j]);
    run->finger_qvel.push_back(m->jnt_dofadr[j]);
    for (int j = 0; j < PadCount(scene.fingers[i], run->st.pads); ++j) {
      const int g = mj_name2id(m, mjOBJ_GEOM, ("pad" + k + "_" + std::to_string(j)).c_str());
      run->pad_of_geom[static_cast<size_t>(g)] = static_cast<int>(i);
    }
  }
  if (scene.pusher) {
    run->pusher_body = mj_name2id(m, mjOBJ_BODY, "pusher");
    const int j = m->body_jntadr[run->pusher_body];
    run->pusher_qpos = m->jnt_qposadr[j];
    run->pusher_qvel = m->jnt_dofadr[j];
    for (int j = 0; j < PadCount(*scene.pusher, run->st.pads); ++j) {
      const int g = mj_name2id(m, mjOBJ_GEOM, ("pusher_pad_" + std::to_string(j)).c_str());
      run->pad_of_geom[static_cast<size_t>(g)] = static_cast<int>(scene.fingers.size());
    }
  }
  // Grip force along each finger's normal, plus the finger's weight along it.
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    const double weight =
        run->st.finger_mass * scene.gravity.dot(scene.fingers[i].normal.normalized());
    run->d->ctrl[i] = scene.grip_force - weight;
  }
}

// The steps from one sample to the next (sample k > 0), each checked against
// the truth's limits; `interval` collects their forces when the settings
// ask for them. Returns the limit crossed (the steps stop there), else empty.
// Leaves pusher and time exactly on the sample instant, forces of that state.
std::string StepToSample(Run& run, TruthLimits& limits, long k, int per_sample,
                         const Eigen::Vector3d& start, Run::PadReading* interval,
                         mechanics::SimulationResult* result) {
  mjModel* m = run.m;
  mjData* d = run.d;
  std::string beyond;
  for (int j = 0; j < per_sample && beyond.empty(); ++j) {
    run.DrivePusher(d->time);
    mj_step(m, d);
    ++result->solver.steps;
    // After mj_step, d->contact and d->efc_force are the step's own solve.
    if (run.st.interval_forces) run.Read(interval);
    beyond = limits.Check(m, d, run.object_qpos, run.object_qvel, run.object_geom, run.pad_of_geom,
                          run.finger_qpos, start, run.pusher_body < 0 ? 0.0 : run.PusherSpeed());
  }
  d->time = static_cast<double>(k) / mechanics::kSampleRateHz;
  run.DrivePusher(d->time);
  mj_forward(m, d);
  return beyond;
}

// Why sample `s` must not pass for a truth: a limit crossed (`beyond`, it
// comes first: it says why), a divergence, or contacts MuJoCo dropped (it
// drops those that do not fit its buffers and goes on). Empty: none.
std::string SampleFailure(const mechanics::TrajectorySample& s, const std::string& beyond,
                          const mjModel* m, const mjData* d) {
  if (!beyond.empty()) return beyond;  // (the samples end before this one)
  if (!Finite(s) || d->warning[mjWARN_BADQACC].number > 0)
    return "MuJoCo diverged at t = " + Num(s.t) + " s (non-finite state or acceleration)";
  if (d->warning[mjWARN_CONTACTFULL].number > 0 || d->warning[mjWARN_CNSTRFULL].number > 0) {
    return "MuJoCo's contact buffers overflowed by t = " + Num(s.t) + " s (nconmax " +
           std::to_string(m->nconmax) + ", njmax " + std::to_string(m->njmax) +
           "): contacts were dropped";
  }
  return "";
}

// Closed loop: asks `commands` for the pusher's velocity after the samples
// so far and puts it in force. False when the run ends here (stopped by the
// source, or a command refused: `result` says which).
bool FollowCommand(Run& run, const mechanics::PusherCommandSource& commands,
                   mechanics::SimulationResult* result) {
  std::string why;
  const std::optional<mechanics::PusherMotion> command = commands(result->samples, &why);
  if (!command) {
    result->stopped = why.empty() ? "stopped by the command source" : why;
    return false;
  }
  if (std::string bad = CheckCommand(run.scene, *command); !bad.empty()) {
    result->status = mechanics::SimulationStatus::kInvalidScene;
    result->error = bad;
    return false;
  }
  run.CommandPusher(run.d->time, command->velocity);
  return true;
}

// Steps a loaded model through `scene`: the model built from `scene`, or
// from a scene that differs only in friction, grip force and mass with those
// patched in (MujocoPrepared). `d` is fresh (made or reset). Throws what
// MuJoCo throws; fills `result` (status kSolverFailure on a divergence).
// Closed loop: `commands` answers every sample with the pusher's velocity
// from then on (mechanics::Simulate(scene, commands) has the same contract).
void RunLoaded(const mechanics::Scene& scene, const MujocoSettings& settings, mjModel* m, mjData* d,
               mechanics::SimulationResult* result,
               const mechanics::PusherCommandSource* commands = nullptr) {
  const MujocoSettings st = ForScene(scene, settings);
  if (std::string why = PushBelowResolution(scene, settings, commands != nullptr); !why.empty()) {
    Fail(result, 0, std::move(why));
    return;
  }
  const int per_sample = StepsPerSample(st);
  Run run{scene, st, m, d, -1, -1, -1, -1, -1, -1, {}, {}, {}, 0, -1, {}};
  BindRun(&run);
  const long n_samples =
      static_cast<long>(std::floor(scene.duration * mechanics::kSampleRateHz + 1e-9)) + 1;
  result->samples.reserve(static_cast<size_t>(n_samples));
  run.DrivePusher(0);
  mj_forward(m, d);
  if (std::string why =
          FrictionCreep(m, d, scene, run.pad_of_geom, run.is_object, commands != nullptr);
      !why.empty()) {
    Fail(result, 0, std::move(why));
    return;
  }
  TruthLimits limits(scene, st);
  const Eigen::Vector3d start(d->qpos[run.object_qpos], d->qpos[run.object_qpos + 1],
                              d->qpos[run.object_qpos + 2]);
  for (long k = 0; k < n_samples; ++k) {
    Run::PadReading interval(run.n_pads);  // the steps since the last sample
    const std::string beyond =
        k > 0 ? StepToSample(run, limits, k, per_sample, start, &interval, result) : "";
    if (interval.solves == 0) run.Read(&interval);  // t = 0, or instant forces
    mechanics::TrajectorySample s = run.Sample(interval);
    s.t = static_cast<double>(k) / mechanics::kSampleRateHz;
    if (std::string failure = SampleFailure(s, beyond, m, d); !failure.empty()) {
      Fail(result, result->solver.steps, std::move(failure));
      return;
    }
    result->samples.push_back(std::move(s));
    if (!commands || !scene.pusher) continue;
    if (!FollowCommand(run, *commands, result)) return;
  }
}

// A result with the run's time step and time, for Simulate and MujocoPrepared.
class Timed {
 public:
  explicit Timed(const MujocoSettings& st) : start_(std::chrono::steady_clock::now()) {
    result.model.dof = 6;
    result.model.dt = 1.0 / (mechanics::kSampleRateHz * StepsPerSample(st));
  }
  mechanics::SimulationResult Finish() {
    result.wall_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    return std::move(result);
  }
  mechanics::SimulationResult result;

 private:
  std::chrono::steady_clock::time_point start_;
};

mechanics::SimulationResult MujocoSimulator::SimulateWith(
    const mechanics::Scene& scene, const mechanics::PusherCommandSource* commands) const {
  Timed run(settings_);
  auto& result = run.result;
  if (std::string why = CheckScene(scene); !why.empty()) {
    result.status = mechanics::SimulationStatus::kInvalidScene;
    result.error = why;
    return run.Finish();
  }
  MjHandles h;
  // With a cache, the model and data come from it and go back after the run
  // (on every path: the data is reset before its next use).
  struct Lease {
    MujocoModelCache* cache = nullptr;
    MujocoModelCache::Entry entry;
    MjHandles* h = nullptr;
    ~Lease() {
      if (!cache) return;
      entry.m = h->m;
      entry.d = h->d;
      h->m = nullptr;
      h->d = nullptr;
      cache->Give(std::move(entry));
    }
  } lease;
  try {
    std::string error;
    const std::string xml = MujocoModelXml(scene, settings_);
    if (cache_) {
      lease.entry = cache_->Take(CacheKey(xml, scene));
      lease.cache = cache_.get();
      lease.h = &h;
      h.m = lease.entry.m;
      h.d = lease.entry.d;
    }
    if (!h.m) h.m = LoadFromText(xml, &error);
    if (!h.m) {
      result.status = mechanics::SimulationStatus::kInvalidScene;
      result.error = error;
      return run.Finish();
    }
    if (cache_) {
      WriteOptions(h.m, scene, settings_);
      if (h.d) mj_resetData(h.m, h.d);
    }
    if (!h.d) h.d = mj_makeData(h.m);
    RunLoaded(scene, settings_, h.m, h.d, &result, commands);
  } catch (const std::exception& e) {
    result.status = mechanics::SimulationStatus::kSolverFailure;
    result.error = e.what();
    result.samples.clear();
  }
  return run.Finish();
}

// The scene's model compiled once; a variant's friction (pair_friction of
// every pad's pair), object mass and inertia (body_mass, body_inertia, then
// mj_setConst for what the compiler derives from them: subtree masses,
// inverse weights, mean inertia) are patched in. The grip force is a control
// input set every run anyway. Whether a variant differs only in these is
// decided by writing its MJCF with the base's values put back: the same text
// means the same model.
class MujocoPrepared final : public PreparedScene {
 public:
  MujocoPrepared(const MujocoSimulator& simulator, const MujocoSettings& settings,
                 const mechanics::Scene& base)
      : simulator_(simulator), settings_(settings), base_(base) {
    if (!simulator.CheckScene(base).empty()) return;  // every run then says why
    try {
      xml_ = MujocoModelXml(base, settings);
      std::string error;
      h_.m = LoadFromText(xml_, &error);
      if (!h_.m) return;
      h_.d = mj_makeData(h_.m);
      object_body_ = mj_name2id(h_.m, mjOBJ_BODY, "object");
      for (int k = 0; k < 3; ++k) base_inertia_[k] = h_.m->body_inertia[3 * object_body_ + k];
      // Which scene contact each pair's pad belongs to (fingers, then the
      // pusher). The compiler may order a pair's geoms either way round.
      const int object_geom = mj_name2id(h_.m, mjOBJ_GEOM, "object");
      for (int p = 0; p < h_.m->npair; ++p) {
        const int g =
            h_.m->pair_geom1[p] == object_geom ? h_.m->pair_geom2[p] : h_.m->pair_geom1[p];
        const char* pad = mj_id2name(h_.m, mjOBJ_GEOM, g);
        const std::string name = pad ? pad : "";
        // The pair's pad: a finger's "padK_j", the pusher's, or a support foot.
        const char* other = mj_id2name(
            h_.m, mjOBJ_GEOM, g == h_.m->pair_geom1[p] ? h_.m->pair_geom2[p] : h_.m->pair_geom1[p]);
        const std::string first = name.rfind("object", 0) == 0 && other ? other : name;
        int who = static_cast<int>(base.fingers.size());
        if (first.rfind("pad", 0) == 0) who = std::stoi(first.substr(3, first.find('_') - 3));
        if (first.rfind("foot", 0) == 0 || first == "support") who = kSupportOwner;
        pair_owner_.push_back(who);
      }
    } catch (const std::exception&) {
      h_.Reset();  // every run then builds its own (and says what failed)
    }
  }

  mechanics::SimulationResult Simulate(const mechanics::Scene& variant) override {
    if (!h_.m || !Patchable(variant)) {
      ++rebuilt_;
      return simulator_.Simulate(variant);
    }
    ++reused_;
    Timed run(settings_);
    try {
      for (int p = 0; p < h_.m->npair; ++p) {
        const int owner = pair_owner_[static_cast<size_t>(p)];
        const auto who = static_cast<size_t>(owner);
        const double mu = owner == kSupportOwner         ? variant.support->mu
                          : who < variant.fingers.size() ? variant.fingers[who].mu
                                                         : variant.pusher->mu;
        h_.m->pair_friction[5 * p] = h_.m->pair_friction[5 * p + 1] = std::max(mu, mjMINMU);
      }
      const double k = variant.object.mass / base_.object.mass;
      h_.m->body_mass[object_body_] = variant.object.mass;
      for (int a = 0; a < 3; ++a) h_.m->body_inertia[3 * object_body_ + a] = k * base_inertia_[a];
      mj_setConst(h_.m, h_.d);
      mj_resetData(h_.m, h_.d);
      RunLoaded(variant, settings_, h_.m, h_.d, &run.result);
    } catch (const std::exception& e) {
      run.result.status = mechanics::SimulationStatus::kSolverFailure;
      run.result.error = e.what();
      run.result.samples.clear();
    }
    return run.Finish();
  }
  long reused() const override { return reused_; }
  long rebuilt() const override { return rebuilt_; }

 private:
  bool Patchable(const mechanics::Scene& v) const {
    if (v.fingers.size() != base_.fingers.size() ||
        v.pusher.has_value() != base_.pusher.has_value())
      return false;
    if (!(v.object.mass > 0) || !std::isfinite(v.object.mass)) return false;
    // Inertia scaled with the mass (ApplyScales does so); anything else is another body.
    const Eigen::Matrix3d iv = mechanics::ObjectInertia(v.object);
    const Eigen::Matrix3d ib = mechanics::ObjectInertia(base_.object);
    const double k = v.object.mass / base_.object.mass;
    if ((iv - k * ib).norm() > 1e-12 * std::max(iv.norm(), 1e-300)) return false;
    // What ForScene derives from the mass, grip and friction must be the base's too.
    if (!SameTuning(ForScene(v, settings_), ForScene(base_, settings_))) return false;
    mechanics::Scene same = v;
    for (size_t i = 0; i < same.fingers.size(); ++i) same.fingers[i].mu = base_.fingers[i].mu;
    if (same.pusher) same.pusher->mu = base_.pusher->mu;
    if (same.support.has_value() != base_.support.has_value()) return false;
    if (same.support) same.support->mu = base_.support->mu;
    same.object.mass = base_.object.mass;
    same.object.inertia = base_.object.inertia;
    try {
      return MujocoModelXml(same, settings_) == xml_;
    } catch (const std::exception&) {
      return false;
    }
  }

  const MujocoSimulator& simulator_;
  MujocoSettings settings_;
  mechanics::Scene base_;
  std::string xml_;
  MjHandles h_;
  int object_body_ = -1;
  double base_inertia_[3] = {0, 0, 0};
  static constexpr int kSupportOwner = -1;  // a pair of a support foot
  std::vector<int> pair_owner_;
  long reused_ = 0, rebuilt_ = 0;
};

std::unique_ptr<PreparedScene> MujocoSimulator::Prepare(const mechanics::Scene& scene) const {
  return std::make_unique<MujocoPrepared>(*this, settings_, scene);
}

}  // namespace

std::string MujocoModelXml(const mechanics::Scene& scene, const MujocoSettings& settings) {
  const MujocoSettings st = ForScene(scene, settings);
  const auto& o = scene.object;
  std::ostringstream x;
  const int per_sample = StepsPerSample(st);
  x << "<mujoco model=\"arena-scene\">\n"
    << "  <compiler angle=\"radian\" autolimits=\"true\"/>\n"
    << "  <option timestep=\"" << Num(1.0 / (mechanics::kSampleRateHz * per_sample))
    << "\" gravity=\"" << Vec(scene.gravity) << "\" cone=\""
    << (st.elliptic ? "elliptic" : "pyramidal") << "\" impratio=\"" << Num(st.impratio)
    << "\" noslip_iterations=\"" << st.noslip_iterations << "\" solver=\"Newton\" tolerance=\""
    << Num(st.tolerance) << "\" iterations=\"" << st.iterations << "\" integrator=\"Euler\"/>\n"
    << SizeElement(scene, st.pads);
  if (o.shape == mechanics::ObjectShape::kPrism) x << PrismMesh(o);
  x << "  <worldbody>\n";
  // Object.
  const Eigen::Quaterniond q_WO(mechanics::RotationFromRpy(o.pose.rpy));
  const Eigen::Matrix3d I = mechanics::ObjectInertia(o);
  const Eigen::Vector3d com = o.pose.position + q_WO * CentreOfMassInO(o);
  x << "    <body name=\"object\" pos=\"" << Vec(com) << "\" quat=\"" << Quat(q_WO) << "\">\n"
    << "      <joint name=\"object\" type=\"free\" damping=\"" << Num(st.object_damping) << "\"/>\n"
    << "      <inertial pos=\"0 0 0\" mass=\"" << Num(o.mass) << "\" fullinertia=\"" << Num(I(0, 0))
    << " " << Num(I(1, 1)) << " " << Num(I(2, 2)) << " " << Num(I(0, 1)) << " " << Num(I(0, 2))
    << " " << Num(I(1, 2)) << "\"/>\n";
  switch (o.shape) {
    case mechanics::ObjectShape::kBox:
      x << "      <geom name=\"object\" type=\"box\" size=\"" << Vec(0.5 * o.size)
        << "\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>\n";
      break;
    case mechanics::ObjectShape::kCylinder:
      x << "      <geom name=\"object\" type=\"cylinder\" size=\"" << Num(o.radius) << " "
        << Num(0.5 * o.height) << "\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>\n";
      break;
    case mechanics::ObjectShape::kPrism: {
      if (o.polygon.size() < 3 || !(PolygonArea(o.polygon) > 0))
        throw SimulatorError("object.polygon", "needs a counter-clockwise polygon of area > 0");
      const auto names = ObjectGeomNames(o);
      for (size_t i = 0; i < names.size(); ++i) {
        x << "      <geom name=\"" << names[i] << "\" type=\"mesh\" mesh=\"object_mesh"
          << (i == 0 ? std::string() : std::to_string(i))
          << "\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>\n";
      }
      break;
    }
  }
  x << SupportFeetGeoms(scene) << "    </body>\n" << SupportPlaneGeom(scene);
  // Fingers: the body origin is the contact point; the slide axis the normal.
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    const auto& f = scene.fingers[i];
    const std::string k = std::to_string(i);
    x << "    <body name=\"finger" << k << "\" pos=\"" << Vec(f.position) << "\">\n"
      << "      <joint name=\"finger" << k << "\" type=\"slide\" axis=\""
      << Vec(f.normal.normalized()) << "\"/>\n"
      << "      <inertial pos=\"0 0 0\" mass=\"" << Num(st.finger_mass)
      << "\" diaginertia=\"1e-6 1e-6 1e-6\"/>\n"
      << PadGeoms("pad" + k, f, st) << "    </body>\n";
  }
  if (scene.pusher) {
    const mechanics::PusherSpec p = PointPusherSphere(*scene.pusher, st);
    x << "    <body name=\"pusher\" pos=\"" << Vec(p.position) << "\">\n"
      << "      <joint name=\"pusher\" type=\"free\" armature=\"1e6\"/>\n"
      << "      <inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"1e-3 1e-3 1e-3\"/>\n"
      << PadGeoms("pusher_pad", p, st) << "    </body>\n";
  }
  x << "  </worldbody>\n  <contact>\n";
  for (size_t i = 0; i < scene.fingers.size(); ++i)
    x << Pairs("pad" + std::to_string(i), scene.fingers[i], st, o);
  if (scene.pusher) x << Pairs("pusher_pad", *scene.pusher, ForScene(scene, settings, true), o);
  if (scene.support) x << SupportPairs(scene, st);
  x << "  </contact>\n";
  if (scene.gripper.coupling == mechanics::GripperCoupling::kParallelJaw) {
    x << JawEquality(st);
  }
  x << "  <actuator>\n";
  for (size_t i = 0; i < scene.fingers.size(); ++i)
    x << "    <motor joint=\"finger" << i << "\" gear=\"1\"/>\n";
  x << "  </actuator>\n</mujoco>\n";
  return x.str();
}

std::unique_ptr<Simulator> MakeMujocoSimulator(const MujocoSettings& settings) {
  return std::make_unique<MujocoSimulator>(settings, nullptr);
}

std::unique_ptr<Simulator> MakeMujocoSimulator(const MujocoSettings& settings,
                                               std::shared_ptr<MujocoModelCache> cache) {
  return std::make_unique<MujocoSimulator>(settings, std::move(cache));
}

std::shared_ptr<MujocoModelCache> MakeMujocoModelCache(std::size_t models) {
  return std::make_shared<MujocoModelCache>(models);
}

}  // namespace arena::simulators
