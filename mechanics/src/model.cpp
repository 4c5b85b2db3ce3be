// The contact model: geometry helpers, planarity, and one time step as a
// nondimensional mixed LCP (model.hpp explains the formulation).
#include "arena/mechanics/model.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numbers>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "arena/mechanics/lcp.hpp"
#include "arena/mechanics/pusher_motion.hpp"
#include "geometry.hpp"
#include "model_tester.hpp"
#include "sparse_lu.hpp"
#include "support_stage.hpp"

namespace arena::mechanics {

std::vector<Eigen::Vector3d> ConeEdges(const Eigen::Vector3d& normal, int facets) {
  const Eigen::Vector3d n = normal.normalized();
  const Eigen::Vector3d t1 = FirstTangent(n);
  const Eigen::Vector3d t2 = n.cross(t1);
  std::vector<Eigen::Vector3d> edges;
  edges.reserve(static_cast<size_t>(std::max(facets, 0)));
  for (int j = 0; j < facets; ++j) {
    const double a = 2.0 * std::numbers::pi * j / facets;
    edges.push_back(std::cos(a) * t1 + std::sin(a) * t2);
  }
  return edges;
}

std::vector<Eigen::Vector3d> ConstituentOffsets(const ContactSpec& contact, int points) {
  const int k = contact.type == ContactType::kPoint ? 1 : std::max(points, 1);
  std::vector<Eigen::Vector3d> out;
  if (k == 1) {
    out.emplace_back(Eigen::Vector3d::Zero());
    return out;
  }
  if (contact.type == ContactType::kLine) {
    const Eigen::Vector3d axis = contact.axis.normalized();
    for (int j = 0; j < k; ++j) {
      out.push_back(axis * contact.length * (static_cast<double>(j) / (k - 1) - 0.5));
    }
    return out;
  }
  // Patch: a ring of radius 2R/3 in the contact plane, starting along t1.
  const Eigen::Vector3d n = contact.normal.normalized();
  const Eigen::Vector3d t1 = FirstTangent(n);
  const Eigen::Vector3d t2 = n.cross(t1);
  const double rho = 2.0 * contact.radius / 3.0;
  for (int j = 0; j < k; ++j) {
    const double a = 2.0 * std::numbers::pi * j / k;
    out.push_back(rho * (std::cos(a) * t1 + std::sin(a) * t2));
  }
  return out;
}

Eigen::Matrix3d ObjectInertia(const ObjectSpec& object) {
  if (object.inertia) return *object.inertia;
  const double m = object.mass;
  Eigen::Matrix3d I = Eigen::Matrix3d::Zero();
  if (object.shape == ObjectShape::kBox) {
    const Eigen::Vector3d s2 = object.size.cwiseProduct(object.size);
    I.diagonal() << m * (s2.y() + s2.z()) / 12.0, m * (s2.x() + s2.z()) / 12.0,
        m * (s2.x() + s2.y()) / 12.0;
  } else if (object.shape == ObjectShape::kPrism) {
    // Uniform density over the polygon's area times the height; moments
    // about the centroid (geometry::MomentsOf).
    const geometry::PolygonMoments pm = geometry::MomentsOf(object.polygon);
    const double h2 = object.height * object.height;
    const double k = pm.area > 0 ? m / pm.area : 0.0;
    I(0, 0) = k * pm.yy + m * h2 / 12.0;
    I(1, 1) = k * pm.xx + m * h2 / 12.0;
    I(2, 2) = k * (pm.xx + pm.yy);
    I(0, 1) = I(1, 0) = -k * pm.xy;
  } else {
    const double r2 = object.radius * object.radius;
    const double h2 = object.height * object.height;
    I.diagonal() << m * (3 * r2 + h2) / 12.0, m * (3 * r2 + h2) / 12.0, m * r2 / 2.0;
  }
  return I;
}

namespace {

constexpr double kPlaneTolerance = 1e-9;
// Tracked contacts: a primitive within this fraction of the object's extent
// of the surface touches it (and a pad's support feature counts points this
// close to the first one as one face or edge).
constexpr double kGapTolerance = 1e-4;
// Fixed contacts: a frozen finger point farther than this fraction of the
// object's extent from its surface has left the grasp geometry (the 1 % that
// scene validation allows at the start).
constexpr double kGraspTolerance = 1e-2;
// Reduced-coordinate quantities (3 or 6 rows) without heap allocation.
using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 6, 6>;
using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6, 1>;
// A step whose physical residuals (relative to the force scale) exceed this
// is a solver failure, not a result.
constexpr double kAcceptedResidual = 1e-8;
// Default elastic pads: sinking under the grip force, as a fraction of the
// object's extent.
constexpr double kPadSink = 1e-4;
// Aligned cones: a slip this far (rad) from opposing its friction turns the
// cone and the step is solved again, at most kAlignSolves times.
constexpr double kAlignAngle = 1e-3;
constexpr int kAlignSolves = 12;
constexpr double kAlignFirst = 0.5;
// ... and the slip within this (rad) of opposing the friction; a cone just
// turned onto its friction's direction turns by kAlignProbe next, for the
// slope of the miss.
constexpr double kAlignMiss = 3e-3;
constexpr double kAlignProbe = 4e-3;
// Aligned cones: a slip below this share of the velocity scale has no
// direction worth aligning a cone or a slip damper to (rounding): SlideOf.
constexpr double kAlignSlip = 1e-6;
// Quasi-static steps: solved again until the inertial force is below this
// fraction of the force scale, at most kQuasiStaticSolves more times.
constexpr double kQuasiStatic = 1e-6;
constexpr int kQuasiStaticSolves = 50;
// A quasi-static step's answers converging with a factor ρ (the ratio of two
// successive changes) above this are extrapolated to their limit; within
// kNoBalance of 1 they do not converge: no balanced answer (BalanceStep).
constexpr double kExtrapolateFrom = 0.5;
constexpr double kNoBalance = 1e-6;
// A balanced twist may differ from the step's start by at most this many
// times the pusher's speed (plus what the contact forces' impulse gives over
// dt) at the object's extent (BalanceIsAcceptable): a pusher pressing at an
// arm a tenth of the object's extent from the turn's axis turns its far end
// ten times as fast as it moves; an extrapolation that throws the object out
// of its grasp reached 1e4 times it.
constexpr double kReachFactor = 10;
// Solves of one step before an inaccurate answer is reported as a failure.
constexpr int kAccuracyAttempts = 4;
// A point pad follows the object along its closing direction c and sees the
// face's normal n: its travel is the gap over n·c, and its friction rows
// remove (d·c)/(n·c) n. Below this grazing factor (84° between them) the
// division would amplify the gap and every rounding in it by more than 10,
// and the pad's force (along n) would push nearly across the jaw: the step
// is refused with a typed error naming the finger (GrazingFinger).
constexpr double kGrazingFactor = 0.1;
// The planar reduction: a contact normal farther than this (rad) from the
// plane is refused (SetEdges).
constexpr double kOutOfPlane = 1e-6;

double LengthScale(const ObjectSpec& object) {
  double L = object.shape == ObjectShape::kBox        ? object.size.maxCoeff()
             : object.shape == ObjectShape::kCylinder ? std::max(2 * object.radius, object.height)
                                                      : geometry::Solid(object).extent();
  return L > 0 && std::isfinite(L) ? L : 1.0;
}

// The centre of mass in the gripper frame at t = 0 (a prism's polygon need
// not be centred on the object frame's origin).
Eigen::Vector3d CentreOfMass(const ObjectSpec& object) {
  if (object.shape != ObjectShape::kPrism) return object.pose.position;
  return object.pose.position +
         RotationFromRpy(object.pose.rpy) * geometry::Solid(object).centroid_O();
}

// A tracked point pusher that starts on the object's surface presses the
// face the model's geometry gives it (PlaceOnSolid: on an edge or a vertex,
// the face nearest the one it closes onto), not `pusher.normal`: on an
// edge whose bisector the pusher pushes along, its normal lies in the
// bisecting plane and the face's does not. Planar about that plane, the
// first step was refused ("a contact normal leaves the plane") even under
// "auto", which must then run the full model. Empty when the face's normal
// lies in the plane (or the pusher starts off the surface or inside it,
// where the first step seats it and SetEdges keeps guarding).
std::string CheckTrackedPusherNormal(const Scene& scene, const Eigen::Vector3d& p) {
  const PusherSpec& s = *scene.pusher;
  if (scene.model.contacts != ContactTracking::kTracked || s.type != ContactType::kPoint) return {};
  const geometry::Solid solid(scene.object);
  const double tolerance = kGapTolerance * LengthScale(scene.object);
  const Eigen::Matrix3d R = RotationFromRpy(scene.object.pose.rpy);
  const Eigen::Vector3d closing = s.normal.normalized();
  const Eigen::Vector3d centre_O =
      R.transpose() * (s.position - s.radius * closing - scene.object.pose.position);
  const geometry::Closest cl = solid.ClosestTo(centre_O, -(R.transpose() * closing), tolerance);
  if (std::abs(cl.distance - s.radius) > tolerance) return {};
  const Eigen::Vector3d n = -(R * cl.normal_O);
  if (std::abs(n.dot(p)) <= kPlaneTolerance) return {};
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "pusher: starts on an edge or a vertex of the object, where it presses the face "
                "with normal (%.3g, %.3g, %.3g), not pusher.normal, and that face's normal "
                "leaves the plane",
                n.x() + 0.0, n.y() + 0.0, n.z() + 0.0);  // + 0.0: no "-0"
  return buf;
}

// Checks one candidate plane normal; returns the first failed condition
// (empty when the scene is planar about p) and counts passed conditions.
std::string CheckPlane(const Scene& scene, const Eigen::Vector3d& p, int& passed) {
  const double L = LengthScale(scene.object);
  const Eigen::Vector3d c = CentreOfMass(scene.object);
  const Eigen::Matrix3d R = RotationFromRpy(scene.object.pose.rpy);
  const Eigen::Matrix3d I = R * ObjectInertia(scene.object) * R.transpose();
  passed = 0;
  const double gn = scene.gravity.norm();
  if (scene.support) {
    // The support carries the weight: gravity and the support's normal
    // load are both along the plane normal (free pushing: the table's) and
    // leave the planar equations; the support's friction lies in the plane.
    if (scene.gravity.cross(p).norm() > kPlaneTolerance * gn)
      return "support: gravity is not normal to the plane";
  } else if (gn > 0 && std::abs(scene.gravity.dot(p)) > kPlaneTolerance * gn) {
    return "gravity leaves the plane";
  }
  ++passed;
  const Eigen::Vector3d Ip = I * p;
  if ((Ip - p.dot(Ip) * p).norm() > kPlaneTolerance * I.norm()) {
    return "the plane normal is not a principal axis of the object's inertia";
  }
  ++passed;
  auto check_contact = [&](const ContactSpec& s, const std::string& name) -> std::string {
    const Eigen::Vector3d n = s.normal.normalized();
    if (std::abs(std::abs(n.dot(p)) - 1) <= kPlaneTolerance) {
      // E.g. a grip axis normal to the plane the object moves in: the
      // reduction's contacts press in its plane with two in-plane friction
      // directions; a pad pressing across it would need a 2-D friction cone.
      return name + ": normal along the plane normal (presses across the plane; the planar " +
             "model's contacts press in it)";
    }
    if (std::abs(n.dot(p)) > kPlaneTolerance) return name + ": normal leaves the plane";
    if (std::abs((s.position - c).dot(p)) > kPlaneTolerance * L)
      return name + ": position leaves the plane";
    if (s.type == ContactType::kLine && std::abs(s.axis.normalized().dot(p)) > kPlaneTolerance) {
      return name + ": line axis leaves the plane";
    }
    if (s.type == ContactType::kPatch && scene.model.points > 1)
      return name + ": a patch spreads out of the plane";
    if (s.mu > 0) {
      // The full cone must have edges along ±(p × n) and be symmetric about the plane.
      const int g = scene.model.facets;
      const Eigen::Vector3d tau = p.cross(n).normalized();
      const Eigen::Vector3d t1 = FirstTangent(n);
      const double a = std::atan2(tau.dot(n.cross(t1)), tau.dot(t1));
      const double k = a * g / (2 * std::numbers::pi);
      if (g % 2 != 0 || std::abs(k - std::round(k)) > 1e-9) {
        return name + ": friction cone has no edge along the plane (facets " + std::to_string(g) +
               ")";
      }
    }
    ++passed;
    return {};
  };
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    const std::string e = check_contact(
        scene.fingers[i], "fingers[" + std::to_string(i) + "] '" + scene.fingers[i].name + "'");
    if (!e.empty()) return e;
  }
  if (scene.pusher) {
    const PusherSpec& s = *scene.pusher;
    const std::string e = check_contact(s, "pusher");
    if (!e.empty()) return e;
    if (const std::string t = CheckTrackedPusherNormal(scene, p); !t.empty()) return t;
    const double v = s.motion.velocity.norm();
    if (std::abs(s.motion.velocity.dot(p)) > kPlaneTolerance * v)
      return "pusher velocity leaves the plane";
    Eigen::Vector3d w = s.motion.angular_velocity;
    if (w.cross(p).norm() > kPlaneTolerance * w.norm()) return "pusher turns out of the plane";
    if (s.path) {
      for (size_t k = 0; k < s.path->position.size(); ++k) {
        if (std::abs((s.path->position[k] - s.position).dot(p)) > kPlaneTolerance * L)
          return "pusher path leaves the plane (position[" + std::to_string(k) + "])";
        if (s.path->rpy.empty()) continue;
        const Eigen::AngleAxisd turn(RotationFromRpy(s.path->rpy[k]) *
                                     RotationFromRpy(s.path->rpy[0]).transpose());
        const Eigen::Vector3d axis = turn.angle() * turn.axis();
        if (axis.cross(p).norm() > kPlaneTolerance * std::max(axis.norm(), 1.0))
          return "pusher path turns out of the plane (rpy[" + std::to_string(k) + "])";
        if (axis.norm() > w.norm()) w = axis;
      }
    }
    if (w.norm() > 0 && s.mu > 0) {
      // A turning normal changes its tangent basis; only planes normal to a
      // gripper axis with facets a multiple of 4 keep in-plane edges throughout.
      const bool axis = p.cwiseAbs().maxCoeff() > 1 - 1e-12;
      if (!axis || scene.model.facets % 4 != 0) {
        return "turning pusher needs a plane normal to a gripper axis and facets a multiple of 4";
      }
    }
    ++passed;
  }
  return {};
}

}  // namespace

PlaneCheck FindPlane(const Scene& scene) {
  std::vector<Eigen::Vector3d> candidates = {Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitY(),
                                             Eigen::Vector3d::UnitX()};
  if (scene.pusher && scene.pusher->motion.angular_velocity.norm() > 0) {
    candidates.insert(candidates.begin(), scene.pusher->motion.angular_velocity.normalized());
  }
  if (scene.support && scene.gravity.norm() > 0) {
    candidates.insert(candidates.begin(), scene.gravity.normalized());
  }
  const Eigen::Matrix3d R = RotationFromRpy(scene.object.pose.rpy);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(R * ObjectInertia(scene.object) *
                                                     R.transpose());
  for (int i = 0; i < 3; ++i) candidates.push_back(eig.eigenvectors().col(i));
  std::vector<Eigen::Vector3d> dirs;  // directions that must lie in the plane
  for (const auto& f : scene.fingers) dirs.push_back(f.normal);
  if (scene.pusher) dirs.push_back(scene.pusher->normal);
  dirs.push_back(scene.gravity);
  for (size_t i = 0; i < dirs.size(); ++i) {
    for (size_t j = i + 1; j < dirs.size(); ++j) {
      const Eigen::Vector3d c = dirs[i].cross(dirs[j]);
      if (c.norm() > 1e-6 * dirs[i].norm() * dirs[j].norm()) {
        candidates.push_back(c.normalized());
        i = dirs.size();
        break;
      }
    }
  }
  PlaneCheck out;
  int best = -1;
  std::string across;  // a plane refused only for a contact pressing across it
  auto about = [](const Eigen::Vector3d& p) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "about the plane normal (%.3g, %.3g, %.3g): ", p.x(), p.y(),
                  p.z());
    return std::string(buf);
  };
  for (const Eigen::Vector3d& candidate : candidates) {
    const Eigen::Vector3d p = candidate.normalized();
    int passed = 0;
    const std::string e = CheckPlane(scene, p, passed);
    if (e.empty()) {
      out.planar = true;
      out.normal = p;
      out.reason.clear();
      return out;
    }
    if (passed > best) {
      best = passed;
      out.reason = about(p) + e;
    }
    if (across.empty() && e.find("presses across the plane") != std::string::npos)
      across = about(p) + e;
  }
  // The plane the motion lies in is often the one a pair of fingers presses
  // across (the grip axis its normal): say so too, not only the nearest miss.
  if (!across.empty() && out.reason != across) out.reason += "; " + across;
  return out;
}

// ---------------------------------------------------------------------------

namespace {

struct Point {
  Eigen::Vector3d offset0 = Eigen::Vector3d::Zero();  // from the contact position at t = 0
  int lambda = -1;  // LCP index of λ_n; -1 for a point finger (λ_n = grip force)
  int beta0 = -1;   // first friction index (edges of them); -1 without friction
  int xi = -1;      // LCP index of ξ
  double gap = 0;   // fixed: pusher and elastic pads, integrated; tracked: from the geometry (m)
  // This step's geometry.
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Vector3d body_velocity = Eigen::Vector3d::Zero();  // of the contacting body (pusher)
  // Tracked geometry only: whether the point has rows this step (a finger
  // point whose closing line misses the object has none), its normal into
  // the object and friction directions.
  bool active = true;
  Eigen::Vector3d n = Eigen::Vector3d::UnitX();
  std::vector<Eigen::Vector3d> edges;
  // Planar reduction: a line's point strictly between its two end points
  // (`interior`) is given no rows while both ends have rows on one flat
  // face (`redundant`, MarkRedundantPoints).
  bool interior = false;
  bool redundant = false;
  // The relative velocity at the point after this step's solve, kept by the
  // residual checks for the contact states (valid when urel_step is the
  // step's number).
  Eigen::Vector3d urel = Eigen::Vector3d::Zero();
  long urel_step = -1;
  // Aligned cone (tracked, 6 DOF): the direction opposite its last
  // friction on the object (its last slip, object relative to the body it
  // touches, where the friction had none; zero before any), which the
  // cone's first edge opposes (SetEdges). The friction, not the slip: where
  // the balance fixes the friction, the slip of a settled step can still be
  // kAlignMiss off it, and a step started on that slip began on a face.
  Eigen::Vector3d slip = Eigen::Vector3d::Zero();
  // Tracked point on the solid's closest point (PlaceOnSolid): the outward
  // normal of the face it pressed last step, in the object frame (zero
  // before any), which it keeps while it stays within tolerance of it.
  Eigen::Vector3d face_O = Eigen::Vector3d::Zero();
  // Aligned cone, within one step (AlignCones): the angle of the friction
  // edge of the last solve (from FirstTangent(n) towards n × it) and how
  // far the slip's opposite was from it, for the secant update.
  long align_step = -1;
  double align_theta = 0, align_miss = 0;
  // Quasi-static, aligned: the slip damper's coefficient (N s/m,
  // SetSlipDampers), 0 when the point did not slide in the last solve, and
  // the edge it acts across: the one its friction sat on, edges[0] once
  // the cone has turned onto the slip, else the edge with the largest share
  // (a slide along another edge of the basis, e.g. ±t2, never turns it).
  double damp_c = 0;
  int damp_edge = 0;
  // ... whether the last solve's friction was on a face, when the edge
  // was last put on the friction's direction (and that direction), and the
  // last step it was pinned there (see AlignCones).
  bool align_face = false;
  long align_jump_step = -1;
  long align_pinned_step = -10;
  double align_jump_psi = 0;
};

// AlignCones: a sliding point's friction edge angle θ in its tangent basis
// (t1, t2) and how far the slip's opposite is from it.
struct AlignMiss {
  Point* pt;
  Eigen::Vector3d t1, t2;
  double theta, miss;
  bool face = false;
  bool pinned = false;
  double psi = 0;
};

struct Contact {
  ContactSpec spec;
  bool pusher = false;
  bool active = false;       // has rows (a finger with zero grip force has none)
  double known_normal = -1;  // point finger: its normal force (N), else -1
  int y_plus = -1, y_minus = -1;
  // Parallel jaw (gripper.coupling): both fingers close at one rate, the
  // second shares the first's closing unknowns y± (AssemblePadRows).
  bool jaw = false, jaw_follower = false;
  double pad = 0;  // finger: how far its pad has followed the object along n (m)
  std::vector<Point> points;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitX();  // fixed: the normal; tracked: closing
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> edges;  // friction directions this step (fixed geometry)
  bool touching = true;                // tracked: some point within the gap tolerance
  bool any_active = true;              // tracked: some point has rows
};

// A contact's force is reported as its component along the normal the scene
// gives it (gripper frame) and the rest: the decomposition every reader of a
// sample undoes with the scene's normals (assessment::ContactNormals: the
// store, export, scoring) and the MuJoCo backend makes. Summed over its
// points' own normals, a tracked contact on a tilted face (or a pusher that
// turns) gave a force vector that was not the one applied: 26 degrees off on
// a pivoting push at 31 degrees. Where the normals agree it is left as
// summed, to the last bit.
void ReportAlongSceneNormal(const Contact& ct, bool tracked, const Eigen::Vector3d& force,
                            ContactState* st) {
  const Eigen::Vector3d& n = ct.spec.normal;  // unit since Setup()
  constexpr double kSame2 = 1e-24;            // rounding of the same direction, squared
  bool along_n = (ct.normal - n).squaredNorm() <= kSame2;
  if (tracked) {
    along_n = true;
    for (const Point& pt : ct.points) along_n = along_n && (pt.n - n).squaredNorm() <= kSame2;
  }
  if (along_n) return;
  st->normal_force = force.dot(n);
  st->tangential_force = force - st->normal_force * n;
}

// Whether every entry is finite: x · 0 is 0 for finite x and NaN otherwise,
// a sum without branches (Eigen's allFinite() compares x - x element-wise).
template <typename Dense>
bool AllFiniteEntries(const Dense& m) {
  double zero = 0;
  const double* a = m.data();
  for (Eigen::Index i = 0; i < m.size(); ++i) zero += a[i] * 0.0;
  return zero == 0;
}

// One step's LCP matrix, formed by columns when the solver asks for them.
// The force block is mass · Jrowsᵀ K (rank ≤ 6, but n² entries: at 32 facets
// and 9-point lines n ≈ 650, and the step used to spend most of its time
// zeroing and multiplying it whole) while a warm-started solve reads only
// its basic columns (a few dozen). Every other entry is one of a few per
// column, assigned after the force block (Set), in the order assigned.
// Small problems are formed whole at Reset() with the dense expression the
// step always used (then Set writes into it), large ones column by column
// with the arithmetic of Eigen's matrix product on them (a sum over the 3 or
// 6 reduced coordinates in order from zero, times the mass): the same
// entries to the last bit.
class StepMatrix final : public LcpColumns {
 public:
  void Reset(int n, int nf, double mass, const Eigen::MatrixXd& Jrows, const Eigen::MatrixXd& K) {
    n_ = n;
    nf_ = nf;
    mass_ = mass;
    K_ = &K;
    entries_.clear();
    diagonal_.assign(static_cast<size_t>(nf), 0.0);
    cache_.resize(n_, n_);
    // Planar (3 reduced coordinates): never formed whole. A warm-started
    // step reads only its basis block and w = A z, both cheap from the
    // factors (GatherBasis, Multiply); Lemke's columns are formed on demand.
    low_rank_ = Jrows.rows() == 3;
    J_ = &Jrows;
    dense_ = nf_ < kLazyForces && !low_rank_;
    sorted_ready_ = dense_;
    finite_ = std::isfinite(mass) && AllFiniteEntries(Jrows) && AllFiniteEntries(K);
    if (dense_) {
      // Eigen picks a coefficient-wise product for small sizes, whose sums
      // run in another order: the dense formation keeps it.
      cache_.setZero();
      cache_.topLeftCorner(nf_, nf_).noalias() = mass * Jrows.transpose() * K;
      ready_.assign(static_cast<size_t>(n_), 1);
    } else {
      jt_ready_ = false;  // Column() transposes when Lemke first asks
      ready_.assign(static_cast<size_t>(n_), 0);
    }
  }
  // Adds to a diagonal entry of the force block (after Reset, before
  // Finish): an elastic pad's compliance on its points' normal rows.
  void AddToForceDiagonal(int k, double value) {
    finite_ = finite_ && std::isfinite(value);
    if (dense_) {
      cache_(k, k) += value;
    } else {
      diagonal_[static_cast<size_t>(k)] += value;
    }
  }
  void Set(int row, int col, double value) {
    finite_ = finite_ && std::isfinite(value);
    if (dense_) {
      cache_(row, col) = value;
    } else {
      entries_.push_back(Entry{row, col, value});
    }
  }
  // After the last Set. The entries are sorted by column when a column or
  // the gathered basis block is first read (a warm step solved bordered
  // never reads them by column).
  void Finish() { sorted_ready_ = dense_; }
  void SortEntries() const {
    if (sorted_ready_) return;
    sorted_ready_ = true;
    first_.assign(static_cast<size_t>(n_) + 1, 0);
    for (const Entry& e : entries_) ++first_[static_cast<size_t>(e.col) + 1];
    for (int j = 0; j < n_; ++j)
      first_[static_cast<size_t>(j) + 1] += first_[static_cast<size_t>(j)];
    sorted_.resize(entries_.size());
    fill_.assign(first_.begin(), first_.end() - 1);
    for (const Entry& e : entries_)
      sorted_[static_cast<size_t>(fill_[static_cast<size_t>(e.col)]++)] = e;
  }
  Eigen::Index size() const override { return n_; }
  const double* Column(Eigen::Index j) const override {
    double* col = cache_.data() + j * n_;
    if (ready_[static_cast<size_t>(j)]) return col;
    SortEntries();
    if (!jt_ready_ && j < nf_) {
      JT_ = J_->transpose();
      jt_ready_ = true;
    }
    Eigen::Map<Eigen::VectorXd> c(col, n_);
    if (j < nf_) {
      // gebp: per entry, acc = 0; acc += a_k b_k over k in order; then
      // 0 + acc · mass (the destination was zeroed, alpha = mass).
      auto top = c.head(nf_);
      top.setZero();
      for (Eigen::Index k = 0; k < JT_.cols(); ++k) top += JT_.col(k) * (*K_)(k, j);
      for (Eigen::Index i = 0; i < nf_; ++i) col[i] = 0.0 + col[i] * mass_;
      col[j] += diagonal_[static_cast<size_t>(j)];
      c.tail(n_ - nf_).setZero();
    } else {
      c.setZero();
    }
    for (int e = first_[static_cast<size_t>(j)]; e < first_[static_cast<size_t>(j) + 1]; ++e) {
      col[sorted_[static_cast<size_t>(e)].row] = sorted_[static_cast<size_t>(e)].value;
    }
    ready_[static_cast<size_t>(j)] = 1;
    return col;
  }
  // From the factors (entries are sums of products of them; an overflow
  // there would show in the solution, which the solver checks too) and the
  // values set: no n² scan.
  bool AllFinite() const override { return finite_; }
  // The planar basis block: force entries mass · J_i · K_j over the 3
  // reduced coordinates, then the entries set (as Column() writes them).
  void GatherBasis(const std::vector<Eigen::Index>& idx, Eigen::MatrixXd& block) const override {
    if (!low_rank_) {
      LcpColumns::GatherBasis(idx, block);
      return;
    }
    SortEntries();
    const auto m = static_cast<Eigen::Index>(idx.size());
    block.resize(m, m);
    PlaceBasis(idx);
    const double* J = J_->data();
    const double* Kd = K_->data();
    for (Eigen::Index c = 0; c < m; ++c) {
      const Eigen::Index j = idx[static_cast<size_t>(c)];
      double* out = block.data() + c * m;
      if (j < nf_) {
        const double k0 = Kd[3 * j], k1 = Kd[3 * j + 1], k2 = Kd[3 * j + 2];
        for (Eigen::Index r = 0; r < m; ++r) {
          const Eigen::Index i = idx[static_cast<size_t>(r)];
          out[r] = i < nf_ ? mass_ * (J[3 * i] * k0 + J[3 * i + 1] * k1 + J[3 * i + 2] * k2) : 0.0;
        }
        out[c] += diagonal_[static_cast<size_t>(j)];
      } else {
        std::fill(out, out + m, 0.0);
      }
      for (int e = first_[static_cast<size_t>(j)]; e < first_[static_cast<size_t>(j) + 1]; ++e) {
        const Entry& entry = sorted_[static_cast<size_t>(e)];
        const int r = position_[static_cast<size_t>(entry.row)];
        if (r >= 0) out[r] = entry.value;
      }
    }
    PlaceBasis(idx, false);
  }
  // Planar w = A z: mass · J (K z) over the force rows, plus the entries set
  // (they sit where the force block is zero: rows and columns of unknowns
  // without rows, whose grasp-map columns are zero).
  void Multiply(const Eigen::VectorXd& z, Eigen::VectorXd& w) const override {
    if (!low_rank_) {
      LcpColumns::Multiply(z, w);
      return;
    }
    w.setZero(n_);
    const double* J = J_->data();
    const double* Kd = K_->data();
    double y0 = 0, y1 = 0, y2 = 0;
    for (int j = 0; j < nf_; ++j) {
      const double zj = z[j];
      if (zj == 0) continue;
      y0 += Kd[3 * j] * zj;
      y1 += Kd[3 * j + 1] * zj;
      y2 += Kd[3 * j + 2] * zj;
    }
    y0 *= mass_;
    y1 *= mass_;
    y2 *= mass_;
    for (int i = 0; i < nf_; ++i)
      w[i] = J[3 * i] * y0 + J[3 * i + 1] * y1 + J[3 * i + 2] * y2 +
             diagonal_[static_cast<size_t>(i)] * z[i];
    for (const Entry& e : entries_) {
      const double zc = z[e.col];
      if (zc != 0) w[e.row] += e.value * zc;
    }
  }
  // The planar basis solved bordered. With y = mass · K_B z_B, the change of
  // the 3 reduced coordinates' velocity that the basic forces make,
  // A(idx, idx) z = rhs reads
  //   J_i · y + d_i z_i + (entries set in row i) = rhs_i   (each basic row i)
  //   mass · K_B z_B - y = 0                               (3 border rows)
  // a sparse system (3 grasp-map entries per force row, the few constants
  // per row of the friction cone and the pads, 3 dense border rows), where
  // the dense LU factorises all m² entries of the rank-3 force block. Its
  // elimination order is cached per pattern (SmallSparseLu). The answer is
  // checked against A(idx, idx) itself: one refinement when its residual is
  // above 1e-14 of the data, refused (the dense LU answers) above 1e-11.
  bool SolveBasisBlock(const std::vector<Eigen::Index>& idx, const Eigen::VectorXd& rhs,
                       Eigen::VectorXd& x) const override {
    if (!low_rank_) return false;
    const auto m = static_cast<int>(idx.size());
    const int size = m + 3;
    if (size > SmallSparseLu::kMaxSize) return false;
    PlaceBasis(idx);
    const double* J = J_->data();
    const double* Kd = K_->data();
    lu_.Clear(size);
    for (int r = 0; r < m; ++r) {
      const Eigen::Index i = idx[static_cast<size_t>(r)];
      if (i >= nf_) continue;
      for (int k = 0; k < 3; ++k) lu_.Add(r, m + k, J[3 * i + k]);
      for (int k = 0; k < 3; ++k) lu_.Add(m + k, r, mass_ * Kd[3 * i + k]);
      const double d = diagonal_[static_cast<size_t>(i)];
      if (d != 0) lu_.Add(r, r, d);
    }
    for (int k = 0; k < 3; ++k) lu_.Add(m + k, m + k, -1.0);
    for (const Entry& e : entries_) {
      const int r = position_[static_cast<size_t>(e.row)];
      const int c = position_[static_cast<size_t>(e.col)];
      if (r >= 0 && c >= 0) lu_.Add(r, c, e.value);
    }
    // The bordered residual res = rhs - M u gives A(idx, idx)'s own: with
    // mass · K z = y - res_border, row i's is res_i + J_i · res_border.
    std::array<double, SmallSparseLu::kMaxSize> b, u, res, du;
    auto worst_residual = [&] {
      lu_.Residual(b.data(), u.data(), res.data());
      const double r0 = res[static_cast<size_t>(m)], r1 = res[static_cast<size_t>(m) + 1],
                   r2 = res[static_cast<size_t>(m) + 2];
      double worst = 0;
      for (int row = 0; row < m; ++row) {
        const Eigen::Index i = idx[static_cast<size_t>(row)];
        double v = res[static_cast<size_t>(row)];
        if (i < nf_) v += J[3 * i] * r0 + J[3 * i + 1] * r1 + J[3 * i + 2] * r2;
        worst = std::max(worst, std::abs(v));
      }
      return worst;
    };
    bool ok = lu_.Factor();
    if (ok) {
      std::copy(rhs.data(), rhs.data() + m, b.begin());
      std::fill(b.begin() + m, b.begin() + size, 0.0);
      lu_.Solve(b.data(), u.data());
      const double scale = 1.0 + rhs.lpNorm<Eigen::Infinity>();
      double worst = worst_residual();
      if (!(worst <= 1e-14 * scale)) {
        lu_.Solve(res.data(), du.data());
        for (int c = 0; c < size; ++c) u[static_cast<size_t>(c)] += du[static_cast<size_t>(c)];
        worst = worst_residual();
      }
      ok = std::isfinite(worst) && worst <= 1e-11 * scale;
      if (ok) x = Eigen::Map<const Eigen::VectorXd>(u.data(), m);
    }
    PlaceBasis(idx, false);
    return ok;
  }
  // The whole matrix (for an observer or a dump).
  const Eigen::MatrixXd& Dense() const {
    for (int j = 0; j < n_; ++j) Column(j);
    return cache_;
  }

 private:
  // From this many force unknowns on, columns are formed on demand (Eigen's
  // product uses its blocked kernel there, whose sums Column() repeats).
  static constexpr int kLazyForces = 16;
  struct Entry {
    int row = 0, col = 0;
    double value = 0;
  };
  int n_ = 0, nf_ = 0;
  bool dense_ = true;
  bool low_rank_ = false;  // planar: GatherBasis and Multiply from the factors
  const Eigen::MatrixXd* J_ = nullptr;
  // A row's place in the basis being read, else -1: set by PlaceBasis(idx),
  // cleared by PlaceBasis(idx, false).
  mutable std::vector<int> position_;
  void PlaceBasis(const std::vector<Eigen::Index>& idx, bool place = true) const {
    position_.resize(static_cast<size_t>(n_), -1);
    for (size_t r = 0; r < idx.size(); ++r)
      position_[static_cast<size_t>(idx[r])] = place ? static_cast<int>(r) : -1;
  }
  bool finite_ = true;
  double mass_ = 0;
  const Eigen::MatrixXd* K_ = nullptr;
  mutable Eigen::MatrixXd JT_;
  mutable bool jt_ready_ = false;
  std::vector<Entry> entries_;
  mutable std::vector<Entry> sorted_;
  mutable bool sorted_ready_ = true;
  std::vector<double> diagonal_;  // lazy and planar: added to the force block's diagonal
  mutable std::vector<int> first_, fill_;
  mutable Eigen::MatrixXd cache_;
  mutable std::vector<char> ready_;
  mutable SmallSparseLu lu_;  // planar: the bordered basis (SolveBasisBlock)
};

// One step's quantities, passed from phase to phase (the phases are below,
// after Step()). Kept between steps only so that its buffers are reused;
// nothing in it is read before the phase that writes it in the same step.
// The inverse of a symmetric positive definite reduced matrix; six
// coordinates (every 6-DOF step) on fixed sizes, which Eigen unrolls (the
// general triangular solves of the dynamic size were about 5 % of a
// quasi-static step).
SmallMatrix InverseOfSpd(const SmallMatrix& M) {
  if (M.rows() == 6) {
    const Eigen::Matrix<double, 6, 6> F = M;
    return F.llt().solve(Eigen::Matrix<double, 6, 6>::Identity());
  }
  return M.llt().solve(SmallMatrix::Identity(M.rows(), M.cols()));
}

struct StepScratch {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // the object's rotation (kPlaceContacts)
  SmallMatrix Mr, Minv;                             // reduced mass matrix (kMassMatrix)
  SmallVector vr;                                   // twist at the step's start, reduced
  SmallVector Q;                                    // known wrench, reduced (kFreeMotion)
  SmallVector vfree;                                // twist under the known wrench alone
  Eigen::MatrixXd Jc, Jv, K;  // grasp maps (forces, velocity rows) and M⁻¹ Jc (kGraspMap)
  StepMatrix A;               // the LCP w = A z + b (kContactRows, kConeRows, kPadRows)
  Eigen::VectorXd b;
  LcpResult solution;      // the last solve (its vectors reused) (kSolve)
  Eigen::VectorXd forces;  // N, per force unknown
  SmallVector Jf;          // contact wrench, reduced
  SmallVector vr_new;      // the new twist, reduced
  SmallMatrix D;           // the slip dampers, reduced (ApplySlipDampers); empty when none
  SmallVector Db;          // ... and their known part (the pusher's own motion)
  Eigen::Vector3d v_new = Eigen::Vector3d::Zero(), w_new = Eigen::Vector3d::Zero();
  Residuals res;
};

}  // namespace

struct ContactModel::Impl {
  Scene scene;
  ContactModel::LcpObserver lcp_observer;
  SimulationStatus status = SimulationStatus::kOk;
  std::string error;
  ModelInfo info;

  bool planar = false;
  Eigen::Vector3d plane_normal = Eigen::Vector3d::UnitY();
  Eigen::Matrix<double, 6, Eigen::Dynamic> P;                             // reduced -> full twist
  Eigen::Matrix<double, 3, 6> Pt3 = Eigen::Matrix<double, 3, 6>::Zero();  // planar: Pᵀ
  Eigen::Vector3d plane_e1 = Eigen::Vector3d::UnitX(), plane_e2 = Eigen::Vector3d::UnitZ();
  int nd = 6;
  int edges_per_point = 0;

  double mass = 0, L = 1, Fs = 1, Vs = 1, dt = 0;
  // A contact slides (ContactState::mode) when its slip exceeds this (m/s):
  // SetupScales.
  double slip_floor = 0;
  Eigen::Matrix3d inertia_body = Eigen::Matrix3d::Identity();
  std::vector<Contact> contacts;
  int nf = 0;                        // force unknowns (λ, β) come first in the LCP
  int n = 0;                         // LCP size
  std::vector<int> force_point;      // per force unknown: contact index
  std::vector<int> force_point_sub;  // per force unknown: point index
  std::vector<int> force_dir;        // per force unknown: -1 normal, else edge index

  // State.
  double t = 0;
  long steps_taken = 0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  Eigen::Vector3d w = Eigen::Vector3d::Zero();
  std::vector<ContactState> states;
  Eigen::Vector3d pusher_force = Eigen::Vector3d::Zero();
  std::vector<char> basis;

  // The support (support_stage.hpp): its friction directions are the last
  // force unknowns [support_beta0, nf), its ξ the last unknown.
  SupportStage support;
  int support_beta0 = -1, support_xi = -1;
  Eigen::Matrix<double, 3, Eigen::Dynamic> support_D;
  Eigen::Vector3d support_twist = Eigen::Vector3d::Zero();  // last step's reduced twist
  // Force unknowns of the contacts (the support's come after them).
  int ContactForceUnknowns() const { return support_beta0 >= 0 ? support_beta0 : nf; }

  // Tracked geometry.
  bool tracked = false;
  bool aligned = false;       // aligned cones in use: tracked, 6 DOF, model.cone aligned
  bool quasi_static = false;  // model.inertia quasi_static
  // Quasi-static, tracked: the step's start (pose, time, pads) while its
  // geometry is placed at the end the iterate reaches (PlaceAtStepEnd).
  struct StepStart {
    Eigen::Vector3d c, v, w;
    Eigen::Quaterniond q;
    std::vector<double> pads;
  };
  std::optional<StepStart> step_start;
  // ... and each tracked point's face (Point::face_O) there, contact by
  // contact, point by point: every iterate is placed from these
  // (RestoreStartFaces). Outside StepStart so its storage is kept.
  std::vector<Eigen::Vector3d> start_faces;
  // ... and each point's slip there (Point::slip, which its aligned cone's
  // first edge opposes): a step solved again from its start (a carried
  // step after a balance that failed) starts from the cones it started
  // with, not the ones the failed balance turned.
  std::vector<Eigen::Vector3d> start_slips;
  // Quasi-static, tracked: the reduced twist of the last step taken, from
  // which the next step's end is predicted (PredictStepEnd).
  SmallVector last_vr;
  double place_lead = 0;     // s: the pusher placed this far after t (PlaceAtStepEnd)
  bool at_step_end = false;  // PlaceContacts: gaps taken at the iterate's end (PlaceAtStepEnd)
  // BalanceAligned: the balance's solves keep the cones they started with.
  bool balancing_held_cones = false;
  bool slip_dampers = false;       // aligned and quasi-static: SetSlipDampers
  bool last_step_carried = false;  // BalanceStep: the last step found no acceptable balance
  // model.inertia "auto" decided quasi-static: the run turns carried for
  // good at a step whose push needs the object's momentum (CarryOnPush).
  bool inertia_auto = false;
  // AlignCones: d(miss)/dθ of the last secant (0: none yet) and scratch.
  double align_slope = 0;
  std::vector<AlignMiss> align_misses;
  std::unique_ptr<geometry::Solid> solid;
  Eigen::Vector3d com_O = Eigen::Vector3d::Zero();        // centre of mass in the object frame
  double gap_tolerance = 0;                               // m: within it a primitive touches
  Eigen::Matrix3d pose_R = Eigen::Matrix3d::Identity();   // this step's object rotation
  Eigen::Vector3d pose_origin = Eigen::Vector3d::Zero();  // and object-frame origin
  std::vector<double> cone_cos, cone_sin;                 // facets' angles from t1

  // Work space.
  StepScratch scratch;

  void Setup();
  bool SetupReduction();
  void SetupScales();
  void SetupContacts();
  double DefaultPadStiffness() const;
  void SetupUnknowns();
  void SeatContacts();
  void Geometry();
  void TrackedGeometry();
  void MarkRedundantPoints();
  // An elastic pad's compliance per constituent point over dt², 1/(k_point
  // dt²) (1/(kg)): times the mass, the point's normal-row diagonal.
  double PadCompliance(const Contact& ct) const {
    const double k_point = ct.spec.stiffness / static_cast<double>(ct.points.size());
    return 1.0 / (k_point * dt * dt);
  }
  void PlaceOnSolid(Contact& ct, Point& pt, const Eigen::Vector3d& q, const Eigen::Vector3d& base,
                    const Eigen::Vector3d& closing, const Eigen::Vector3d& vp,
                    const Eigen::Vector3d& wp);
  bool PlacePatch(Contact& ct, const Eigen::Vector3d& base, const Eigen::Vector3d& closing,
                  const Eigen::Vector3d& vp, const Eigen::Vector3d& wp);
  void SetEdges(Point& pt);
  // Column k of a grasp map: the wrench of a unit force along d at arm
  // (from the centre of mass), in reduced coordinates. Planar: (e1 · d,
  // e2 · d, p · (arm × d)), the last as d · (p × arm) with p × arm given
  // (the same for every direction at one point).
  void SetGraspColumn(Eigen::MatrixXd& J, int k, const Eigen::Vector3d& d,
                      const Eigen::Vector3d& arm, const Eigen::Vector3d& p_cross_arm) const {
    double* out = J.data() + static_cast<Eigen::Index>(k) * nd;
    if (planar) {
      out[0] = plane_e1.dot(d);
      out[1] = plane_e2.dot(d);
      out[2] = p_cross_arm.dot(d);
    } else {
      const Eigen::Vector3d moment = arm.cross(d);
      for (int i = 0; i < 3; ++i) {
        out[i] = d[i];
        out[3 + i] = moment[i];
      }
    }
  }
  Eigen::Vector3d ObjectOrigin() const { return c - q.toRotationMatrix() * com_O; }

  // Per point: its normal and friction directions (tracked: its own; fixed:
  // the contact's), whether it is live (tracked: touches this step), and
  // whether it has LCP rows this step (a redundant one has a unit diagonal,
  // like a tracked point without rows; it still counts as touching).
  const Eigen::Vector3d& NormalOf(const Contact& ct, const Point& pt) const {
    return tracked ? pt.n : ct.normal;
  }
  const Eigen::Vector3d& EdgeOf(const Contact& ct, const Point& pt, int e) const {
    return tracked ? pt.edges[static_cast<size_t>(e)] : ct.edges[static_cast<size_t>(e)];
  }
  bool Live(const Point& pt) const { return !tracked || pt.active; }
  bool HasRows(const Point& pt) const { return Live(pt) && !pt.redundant; }

  // The step, phase by phase (model_tester.hpp lists them).
  StepReport Step();
  bool BeginStep(StepReport& rep);
  bool RunPhase(StepPhase phase, StepReport& rep);
  void PlaceContacts(StepScratch& s);
  void FormMassMatrix(StepScratch& s);
  bool FormFreeMotion(StepScratch& s, StepReport& rep);
  void FormGraspMap(StepScratch& s);
  void AssembleContactRows(StepScratch& s);
  void AssembleConeRows(StepScratch& s);
  void AssemblePadRows(StepScratch& s);
  void AssembleJawRows(StepScratch& s);
  // This step's refusal of its geometry (a point pad on a grazing face,
  // TrackedGeometry; a normal out of the planar model's plane, SetEdges).
  std::string refused;
  void AssembleSupportRows(StepScratch& s);
  void SetupSupport();
  void SupportResiduals(StepScratch& s);
  bool Solve(StepScratch& s, StepReport& rep);
  void RecoverMotion(StepScratch& s);
  double CheckResiduals(StepScratch& s);
  bool CheckValues(StepScratch& s, StepReport& rep);
  bool Refuse(StepReport& rep, const std::string& why);  // kNonFinite
  bool AlignCones(StepScratch& s);
  void SetSlipDampers(const StepScratch& s);
  bool TurnCones(StepScratch& s);
  bool DampersSettled(const StepScratch& s) const;
  void ApplySlipDampers(StepScratch& s);
  Eigen::Vector3d SlipDamperDirection(const Contact& ct, const Point& pt) const;
  bool MeasureAlignMiss(const StepScratch& s, const Contact& ct, double facet, AlignMiss& m);
  bool SlideOf(const StepScratch& s, const Contact& ct, const Point& pt, double& lam,
               Eigen::Vector3d& ut) const;
  double InertialForce(const StepScratch& s) const;
  void PlaceAtStepEnd(const StepScratch& s, const SmallVector& centre);
  bool PredictStepEnd();
  bool RunStep(StepReport& rep);
  bool RunPhases(int first, int last, StepReport& rep);
  bool BalanceStep(int last, StepReport& rep);
  bool Rebalance(int last, StepReport& rep);
  bool CarryStep(int last, StepReport& rep);
  bool BalanceAligned(int last, StepReport& rep);
  bool BalanceIsAcceptable(const StepScratch& s) const;
  bool PusherSlidesIn(const StepScratch& s) const;
  bool PusherPresses(const StepScratch& s) const;
  bool CarryOnPush(int last, StepReport& rep);
  double PusherSpeed() const;
  double PusherDepthAtStepEnd(const SmallVector& twist) const;
  struct PusherPlacement {
    Eigen::Vector3d base = Eigen::Vector3d::Zero();
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
    bool turned = false;
  };
  PusherPlacement PusherAt(const Contact& ct, double at) const;
  void RestoreStartFaces();
  void ReturnToStepStart(bool start_faces = true);
  void GapsFromStepEnd(const StepScratch& s);
  void ReportContacts(StepScratch& s, SlipSteering& steering);
  void AddSteering(const Eigen::Vector3d& ft, const Eigen::Vector3d& ut,
                   SlipSteering& steering) const;
  void Integrate(StepScratch& s);
  // After kSolve: an unknown in physical units, the object's velocity at p,
  // the velocity of the body a point presses on.
  double Unknown(const StepScratch& s, int i) const;
  Eigen::Vector3d ObjectVelocity(const StepScratch& s, const Eigen::Vector3d& p) const;
  Eigen::Vector3d BodyVelocity(const StepScratch& s, const Contact& ct, const Point& pt) const;
};

ContactModel::ContactModel(const Scene& scene) : impl_(std::make_unique<Impl>()) {
  impl_->scene = scene;
  impl_->Setup();
}
ContactModel::~ContactModel() = default;

SimulationStatus ContactModel::status() const { return impl_->status; }
const std::string& ContactModel::error() const { return impl_->error; }
const ModelInfo& ContactModel::info() const { return impl_->info; }
StepReport ContactModel::Step() { return impl_->Step(); }
void ContactModel::SetLcpObserver(LcpObserver observer) {
  impl_->lcp_observer = std::move(observer);
}
double ContactModel::time() const { return impl_->t; }
const Eigen::Vector3d& ContactModel::position() const { return impl_->c; }
Eigen::Quaterniond ContactModel::orientation() const { return impl_->q; }
const Eigen::Vector3d& ContactModel::velocity() const { return impl_->v; }
const Eigen::Vector3d& ContactModel::angular_velocity() const { return impl_->w; }
const std::vector<ContactState>& ContactModel::contacts() const { return impl_->states; }
Eigen::Vector3d ContactModel::pusher_force() const { return impl_->pusher_force; }
double ContactModel::force_scale() const { return impl_->Fs; }
double ContactModel::length_scale() const { return impl_->L; }
double ContactModel::gap_tolerance() const { return kGapTolerance * impl_->L; }

GraspStatus ContactModel::Grasp(std::string* note) const {
  const Impl& m = *impl_;
  if (m.status != SimulationStatus::kOk) return GraspStatus::kHeld;
  const Eigen::Matrix3d R = m.q.toRotationMatrix();
  const Eigen::Vector3d origin = m.ObjectOrigin();
  const double tolerance = kGraspTolerance * m.L;
  for (size_t i = 0; i < m.contacts.size(); ++i) {
    const Contact& ct = m.contacts[i];
    if (ct.pusher || !ct.active) continue;
    // Named only when it is news (called after every step of every trial).
    auto who = [&] { return "fingers[" + std::to_string(i) + "] '" + ct.spec.name + "'"; };
    if (m.tracked) {
      if (!ct.touching && !ct.any_active) {
        if (note) *note = who() + " lost contact: its pad passed the object's edge";
        return GraspStatus::kLost;
      }
      continue;
    }
    for (const Point& pt : ct.points) {
      const double off = std::abs(m.solid->ClosestTo(R.transpose() * (pt.p - origin)).distance);
      if (off > tolerance) {
        if (note) {
          char buf[160];
          std::snprintf(buf, sizeof buf,
                        " left the object: a frozen contact point is %.3g m off its surface", off);
          *note = who() + buf;
        }
        return GraspStatus::kLeftGeometry;
      }
    }
  }
  return GraspStatus::kHeld;
}
double ContactModel::velocity_scale() const { return impl_->Vs; }
Eigen::Vector3d ContactModel::pusher_position() const {
  if (!impl_->scene.pusher) return Eigen::Vector3d::Zero();
  return PusherPoseAt(*impl_->scene.pusher, impl_->t).position;
}
// Geometry() places the pusher at position + velocity t: rebasing the
// position keeps it where it is when the velocity changes.
bool ContactModel::SetPusherMotion(const PusherMotion& motion) {
  auto& pusher = impl_->scene.pusher;
  if (!pusher || pusher->path || motion.angular_velocity != pusher->motion.angular_velocity)
    return false;
  pusher->position = pusher_position() - motion.velocity * impl_->t;
  pusher->motion = motion;
  for (Contact& ct : impl_->contacts) {
    if (ct.pusher) ct.spec.position = pusher->position;
  }
  return true;
}

namespace {

// Minimal guards so that a hand-built scene that skipped ValidateScene()
// cannot produce NaN or a crash; ValidateScene() gives the full diagnosis.
std::string BasicCheck(const Scene& s) {
  auto finite3 = [](const Eigen::Vector3d& v) { return v.allFinite(); };
  if (!(s.object.mass > 0) || !std::isfinite(s.object.mass)) return "object.mass: must be > 0";
  if (!(s.model.dt > 0) || !std::isfinite(s.model.dt)) return "model.dt: must be > 0";
  if (s.model.facets < 3) return "model.facets: must be >= 3";
  if (s.model.points < 1) return "model.points: must be >= 1";
  if (!(s.duration >= 0) || !std::isfinite(s.duration)) return "duration: must be >= 0";
  if (!(s.grip_force >= 0) || !std::isfinite(s.grip_force)) return "grip_force: must be >= 0";
  if (!finite3(s.gravity) || !finite3(s.object.pose.position) || !finite3(s.object.pose.rpy)) {
    return "object/gravity: must be finite";
  }
  const Eigen::Matrix3d I = ObjectInertia(s.object);
  if (!I.allFinite() || I.llt().info() != Eigen::Success)
    return "object: inertia must be positive definite";
  auto contact = [&](const ContactSpec& c, const std::string& name) -> std::string {
    if (!finite3(c.position) || !finite3(c.normal) || !finite3(c.axis))
      return name + ": must be finite";
    if (!(c.normal.norm() > 0)) return name + ".normal: must be non-zero";
    if (c.type == ContactType::kLine && !(c.axis.norm() > 0))
      return name + ".axis: must be non-zero";
    if (!(c.mu >= 0) || !std::isfinite(c.mu)) return name + ".mu: must be >= 0";
    if (!(c.length >= 0) || !(c.radius >= 0) || !std::isfinite(c.length) ||
        !std::isfinite(c.radius)) {
      return name + ": length and radius must be >= 0";
    }
    return {};
  };
  for (size_t i = 0; i < s.fingers.size(); ++i) {
    const std::string e = contact(s.fingers[i], "fingers[" + std::to_string(i) + "]");
    if (!e.empty()) return e;
  }
  if (s.pusher) {
    const std::string e = contact(*s.pusher, "pusher");
    if (!e.empty()) return e;
    if (!finite3(s.pusher->motion.velocity) || !finite3(s.pusher->motion.angular_velocity)) {
      return "pusher.motion: must be finite";
    }
    if (const auto& path = s.pusher->path) {
      // PusherPoseAt() interpolates: it needs times from 0 that increase.
      if (path->t.empty() || path->t[0] != 0 || path->position.size() != path->t.size() ||
          (!path->rpy.empty() && path->rpy.size() != path->t.size()))
        return "pusher.motion.path: t from 0 with one position (and rpy) row per time";
      for (size_t k = 0; k < path->t.size(); ++k) {
        if (!std::isfinite(path->t[k]) || (k > 0 && !(path->t[k] > path->t[k - 1])) ||
            !finite3(path->position[k]) || (!path->rpy.empty() && !finite3(path->rpy[k])))
          return "pusher.motion.path: times must increase, every entry finite";
      }
    }
  }
  return {};
}

// Diagnostics: ARENA_LCP_DUMP=FILE writes a failed step's LCP (n, A, b as
// text) so that the solver can be studied on it offline.
void DumpLcp(const Eigen::MatrixXd& A, const Eigen::VectorXd& b) {
  const char* path = std::getenv("ARENA_LCP_DUMP");
  if (path == nullptr || *path == 0) return;
  FILE* f = std::fopen(path, "w");
  if (f == nullptr) return;
  std::fprintf(f, "%ld\n", static_cast<long>(b.size()));
  for (Eigen::Index i = 0; i < A.rows(); ++i) {
    for (Eigen::Index j = 0; j < A.cols(); ++j) std::fprintf(f, "%.17g ", A(i, j));
    std::fprintf(f, "\n");
  }
  for (Eigen::Index i = 0; i < b.size(); ++i) std::fprintf(f, "%.17g ", b[i]);
  std::fprintf(f, "\n");
  std::fclose(f);
}

}  // namespace

void ContactModel::Impl::Setup() {
  if (std::string e = BasicCheck(scene); !e.empty()) {
    status = SimulationStatus::kInvalidScene;
    error = e;
    return;
  }
  const ModelOptions& opt = scene.model;
  dt = opt.dt;
  mass = scene.object.mass;
  L = LengthScale(scene.object);
  inertia_body = ObjectInertia(scene.object);
  c = CentreOfMass(scene.object);
  q = Eigen::Quaterniond(RotationFromRpy(scene.object.pose.rpy));
  tracked = opt.contacts == ContactTracking::kTracked;
  solid = std::make_unique<geometry::Solid>(scene.object);
  com_O = solid->centroid_O();
  if (tracked) {
    gap_tolerance = kGapTolerance * L;
    for (int j = 0; j < opt.facets; ++j) {
      const double a = 2.0 * std::numbers::pi * j / opt.facets;
      cone_cos.push_back(std::cos(a));
      cone_sin.push_back(std::sin(a));
    }
  }

  if (!SetupReduction()) return;
  aligned = tracked && !planar && opt.cone == ConeModel::kAligned;
  quasi_static = InertiaOf(scene) == InertiaModel::kQuasiStatic;
  inertia_auto = quasi_static && opt.inertia == InertiaModel::kAuto;
  slip_dampers = aligned && quasi_static;
  SetupScales();
  SetupContacts();
  SetupUnknowns();
  if (status != SimulationStatus::kOk) return;
  info.dof = nd;
  info.facets = opt.facets;
  info.points = opt.points;
  info.dt = dt;
  info.unknowns = n;
  info.inertia = quasi_static ? InertiaModel::kQuasiStatic : InertiaModel::kCarried;
  states.assign(contacts.size(), ContactState{});
  basis.clear();
  SeatContacts();
}

// Planar reduction when the scene allows it (and asks): the plane and its
// coordinates; false (status set) when planar was required and is not there.
bool ContactModel::Impl::SetupReduction() {
  const ModelOptions& opt = scene.model;
  if (opt.reduce != Reduce::kFull) {
    PlaneCheck plane = FindPlane(scene);
    if (plane.planar && opt.contacts == ContactTracking::kTracked &&
        scene.object.shape == ObjectShape::kPrism) {
      // Tracked normals come from the surface: a prism is symmetric about its
      // mid-plane only, so only that plane keeps them in-plane.
      const Eigen::Vector3d axis = RotationFromRpy(scene.object.pose.rpy).col(2);
      if (std::abs(std::abs(axis.dot(plane.normal)) - 1) > 1e-9) {
        plane.planar = false;
        plane.reason = "a prism's tracked contacts stay in its mid-plane only";
      }
    }
    if (plane.planar) {
      planar = true;
      plane_normal = plane.normal;
    } else if (scene.support) {
      status = SimulationStatus::kInvalidScene;
      error =
          "support: needs a scene planar about the support (the support's load is fixed by "
          "its pressure, so the object moves on it), but " +
          plane.reason;
      return false;
    } else if (opt.reduce == Reduce::kPlanar) {
      status = SimulationStatus::kInvalidScene;
      error = "model.reduce: planar, but the scene is not planar (" + plane.reason + ")";
      return false;
    }
  }
  if (scene.support && !planar) {
    // reduce "full": 6 DOF would let the object tip or sink under the load
    // its pressure distribution fixes.
    status = SimulationStatus::kInvalidScene;
    error =
        "support: needs the planar model (model.reduce \"auto\" or \"planar\"); with \"full\" "
        "the support's fixed pressure cannot hold the object";
    return false;
  }
  if (planar) {
    nd = 3;
    const Eigen::Vector3d& p = plane_normal;
    const Eigen::Vector3d e1 = FirstTangent(p);  // any unit vector in the plane
    const Eigen::Vector3d e2 = p.cross(e1);
    P = Eigen::Matrix<double, 6, Eigen::Dynamic>::Zero(6, 3);
    P.block<3, 1>(0, 0) = e1;
    P.block<3, 1>(0, 1) = e2;
    P.block<3, 1>(3, 2) = p;
    Pt3 = P.transpose();
    plane_e1 = e1;
    plane_e2 = e2;
    edges_per_point = 2;
  } else {
    nd = 6;
    P = Eigen::Matrix<double, 6, Eigen::Dynamic>::Identity(6, 6);
    edges_per_point = opt.facets;
  }
  return true;
}

void ContactModel::Impl::SetupScales() {
  // Force scale: the largest of the forces the scene names (grip, weight,
  // the impulse that brings the object to the pusher's speed in one step).
  const double g = scene.gravity.norm();
  Fs = std::max(scene.grip_force, mass * g);
  if (scene.pusher) {
    const PusherTwist peak = PusherPeakRates(*scene.pusher);
    Fs = std::max(
        {Fs, mass * peak.velocity.norm() / dt, mass * peak.angular_velocity.norm() * L / dt});
  }
  if (!(Fs > 0)) Fs = mass * L / (dt * dt);
  Vs = Fs * dt / mass;
  // The slip a contact must have to be reported sliding: 1e-9 of the
  // scene's own speeds (the pusher's, what gravity adds in a step), but no
  // finer than rounding of the solve's velocity scale (1e-13 Vs). It was
  // 1e-9 Vs alone, and Vs = Fs dt / m grows as the object gets light under
  // a firm grip: a 1 g box at 10 N and dt 4 ms called slips below 4e-8 m/s
  // stick, ~1e-5 m/s at the issue's extremes.
  double kinematic = dt * scene.gravity.norm();
  if (scene.pusher) {
    const PusherTwist peak = PusherPeakRates(*scene.pusher);
    kinematic = std::max(kinematic, peak.velocity.norm() + peak.angular_velocity.norm() * L);
  }
  slip_floor = std::max(1e-9 * kinematic, 1e-13 * Vs);
  if (!(kinematic > 0)) slip_floor = 1e-9 * Vs;
}

// A line or patch pad without a stiffness (model.pads elastic): one that
// sinks kPadSink of the object's extent under the grip force. Any stiffness
// makes the pad's load split determinate (the least-squares split of an
// elastic pad pressed flush is the uniform one; a rigid pad's is a vertex
// the solver picks, history-dependent through its warm start); this one is
// stiff enough that the geometry moves by at most 1e-4 of the extent.
double ContactModel::Impl::DefaultPadStiffness() const { return scene.grip_force / (kPadSink * L); }

// The contacts and their constituent points: fingers in scene order, then
// the pusher.
void ContactModel::Impl::SetupContacts() {
  const ModelOptions& opt = scene.model;
  std::vector<ContactSpec> specs(scene.fingers.begin(), scene.fingers.end());
  if (scene.pusher) specs.push_back(*scene.pusher);
  for (size_t i = 0; i < specs.size(); ++i) {
    Contact ct;
    ct.spec = specs[i];
    ct.spec.normal.normalize();
    if (ct.spec.type == ContactType::kLine) ct.spec.axis.normalize();
    ct.pusher = scene.pusher && i + 1 == specs.size();
    ct.active = ct.pusher || scene.grip_force > 0;
    if (!ct.pusher && ct.spec.type != ContactType::kPoint && ct.spec.stiffness == 0 &&
        opt.pads == PadModel::kElastic && scene.grip_force > 0) {
      ct.spec.stiffness = DefaultPadStiffness();
    }
    for (const Eigen::Vector3d& o : ConstituentOffsets(ct.spec, opt.points)) {
      Point pt;
      pt.offset0 = o;
      ct.points.push_back(pt);
    }
    ct.jaw = !ct.pusher && scene.gripper.coupling == GripperCoupling::kParallelJaw;
    // A jaw's point finger presses with what the mechanism gives it (an
    // unknown, AssemblePadRows), not a prescribed grip force.
    if (!ct.pusher && ct.points.size() == 1 && !ct.jaw) ct.known_normal = scene.grip_force;
    if (ct.spec.type == ContactType::kLine && ct.points.size() > 2) {
      const auto along = [&](const Point& pt) { return pt.offset0.dot(ct.spec.axis); };
      const auto [lo, hi] =
          std::minmax_element(ct.points.begin(), ct.points.end(),
                              [&](const Point& a, const Point& b) { return along(a) < along(b); });
      const double s_lo = along(*lo), s_hi = along(*hi);
      for (Point& pt : ct.points) pt.interior = along(pt) > s_lo && along(pt) < s_hi;
    }
    contacts.push_back(std::move(ct));
  }
}

// Unknowns: forces first (λ, β per point), then velocities (ξ, pad y±).
void ContactModel::Impl::SetupUnknowns() {
  const bool friction_rows = edges_per_point > 0;
  for (size_t ci = 0; ci < contacts.size(); ++ci) {
    Contact& ct = contacts[ci];
    if (!ct.active) continue;
    for (size_t j = 0; j < ct.points.size(); ++j) {
      Point& pt = ct.points[j];
      if (ct.known_normal < 0) {
        pt.lambda = nf++;
        force_point.push_back(static_cast<int>(ci));
        force_point_sub.push_back(static_cast<int>(j));
        force_dir.push_back(-1);
      }
      if (ct.spec.mu > 0 && friction_rows) {
        pt.beta0 = nf;
        for (int e = 0; e < edges_per_point; ++e) {
          ++nf;
          force_point.push_back(static_cast<int>(ci));
          force_point_sub.push_back(static_cast<int>(j));
          force_dir.push_back(e);
        }
      }
    }
  }
  SetupSupport();
  n = nf;
  for (Contact& ct : contacts) {
    if (!ct.active) continue;
    for (Point& pt : ct.points) {
      if (pt.beta0 >= 0) pt.xi = n++;
    }
    if (!ct.pusher && ct.known_normal < 0) {
      if (ct.jaw && &ct != &contacts.front()) {
        ct.jaw_follower = true;
        ct.y_plus = contacts.front().y_plus;
        ct.y_minus = contacts.front().y_minus;
        continue;
      }
      ct.y_plus = n++;
      ct.y_minus = n++;
    }
  }
  if (support_beta0 >= 0) support_xi = n++;
}

// The support's force unknowns (SupportStage: its friction directions),
// after the contacts'; ξ is added with the velocity unknowns.
void ContactModel::Impl::SetupSupport() {
  if (!scene.support) return;
  if (std::string e = support.Setup(scene, plane_normal, plane_e1, plane_e2); !e.empty()) {
    status = SimulationStatus::kInvalidScene;
    error = e;
    return;
  }
  if (!support.active()) return;  // μ = 0: no friction, nothing to solve for
  support_beta0 = nf;
  for (int k = 0; k < support.directions(); ++k) {
    ++nf;
    force_point.push_back(-1);
    force_point_sub.push_back(-1);
    force_dir.push_back(k);
  }
}

// The geometry at t = 0.
void ContactModel::Impl::SeatContacts() {
  if (tracked) {
    // Fingers close on the object where it is: each pad moves along its
    // closing direction until its first constituent point meets the surface.
    const Eigen::Matrix3d R = q.toRotationMatrix();
    const Eigen::Vector3d origin = ObjectOrigin();
    for (Contact& ct : contacts) {
      if (ct.pusher || ct.known_normal >= 0) continue;  // point pads re-seat every step
      double first = std::numeric_limits<double>::infinity();
      for (const Point& pt : ct.points) {
        const auto e = solid->EntryOf(R.transpose() * (ct.spec.position + pt.offset0 - origin),
                                      R.transpose() * ct.spec.normal, gap_tolerance);
        if (e) first = std::min(first, e->s);
      }
      if (std::isfinite(first)) ct.pad = first;
    }
    TrackedGeometry();
  } else {
    Geometry();
  }
}

// Contact geometry at time t: fingers are fixed in the gripper frame but for
// their pads' travel along the normal; the pusher translates with its
// velocity and turns about its contact point.
void ContactModel::Impl::Geometry() {
  for (Contact& ct : contacts) {
    Eigen::Matrix3d Rp = Eigen::Matrix3d::Identity();
    Eigen::Vector3d vp = Eigen::Vector3d::Zero(), wp = Eigen::Vector3d::Zero();
    ct.position = ct.spec.position + ct.pad * ct.spec.normal;
    bool turned = false;
    if (ct.pusher && scene.pusher->path) {
      const PusherPose pose = PusherPoseAt(*scene.pusher, t);
      const PusherTwist twist = PusherTwistOver(*scene.pusher, t, dt);
      vp = twist.velocity;
      wp = twist.angular_velocity;
      ct.position = pose.position;
      Rp = pose.rotation;
      turned = pose.turned;
    } else if (ct.pusher) {
      vp = scene.pusher->motion.velocity;
      wp = scene.pusher->motion.angular_velocity;
      ct.position = ct.spec.position + vp * t;
      const double a = wp.norm() * t;
      if (a > 0) Rp = Eigen::AngleAxisd(a, wp.normalized()).toRotationMatrix();
      turned = wp.norm() > 0;
    }
    const Eigen::Vector3d n = Rp * ct.spec.normal;
    const bool recompute = ct.edges.empty() || (ct.pusher && turned);
    ct.normal = n;
    if (recompute) {
      if (planar) {
        const Eigen::Vector3d tau = plane_normal.cross(n).normalized();
        ct.edges = {tau, -tau};
      } else {
        ct.edges = ConeEdges(n, scene.model.facets);
      }
    }
    for (Point& pt : ct.points) {
      const Eigen::Vector3d o = Rp * pt.offset0;
      pt.p = ct.position + o;
      // An elastic pad's sunk point (gap < 0: it is -gap inside along n)
      // pushes on the object's surface, so its force acts there: at the
      // sunk point, its friction's arm differed from the opposite pad's by
      // the sinking and turned the object. Along n the velocity rows are
      // the same (n · (ω × n) = 0), so the gap it integrates is unchanged.
      if (ct.spec.stiffness > 0 && pt.gap < 0) pt.p += pt.gap * n;
      pt.body_velocity = vp + wp.cross(o);
    }
  }
}

// Friction directions of a tracked point: the docs/scene.md tangent basis of its
// current normal (or the in-plane tangents of the planar reduction).
void ContactModel::Impl::SetEdges(Point& pt) {
  if (edges_per_point == 0) return;
  if (planar) {
    // Normals stay in the plane of a planar scene (the solid is symmetric
    // about it, Setup()), so p × n is unit but for rounding and is
    // normalised only when it is not. A normal out of the plane (a point
    // inside a thin solid nearest its side across the plane) has a force
    // the reduction drops, and along the plane normal no tangent at all: it
    // gave no friction, silently. Refused, typed, naming the contact.
    const Eigen::Vector3d cr = plane_normal.cross(pt.n);
    const double length2 = cr.squaredNorm();
    Eigen::Vector3d tau = Eigen::Vector3d::Zero();
    if (std::abs(length2 - 1.0) <= 1e-15) {
      tau = cr;
    } else if (1.0 - length2 <= kOutOfPlane * kOutOfPlane) {
      tau = cr / std::sqrt(length2);
    } else if (refused.empty()) {
      char buf[256];
      std::snprintf(
          buf, sizeof buf,
          "a contact normal leaves the plane of the planar model (by %.3g rad; limit "
          "%.3g): its friction has no in-plane direction; run the scene with model.reduce "
          "\"full\"",
          std::asin(std::sqrt(std::clamp(1.0 - length2, 0.0, 1.0))), kOutOfPlane);
      refused = buf;
    }
    pt.edges.resize(2);
    pt.edges[0] = tau;
    pt.edges[1] = -tau;
    return;
  }
  Eigen::Vector3d t1 = FirstTangent(pt.n);
  if (scene.model.cone == ConeModel::kAligned && pt.slip.squaredNorm() > 0) {
    // An edge along the friction of the last slip: a slide in a free
    // direction then meets the cone at a vertex, where any slip direction
    // within the vertex's fan is allowed, so the facets no longer steer it
    // (the polyhedral cone's force opposes the slip exactly once the slip
    // stops turning). A slip now mostly along the normal keeps the basis.
    // A slip along an edge of the basis (a slide the facets cannot steer)
    // keeps the basis and its cheap, exact polyhedral answer.
    const Eigen::Vector3d f = -(pt.slip - pt.slip.dot(pt.n) * pt.n);
    const double length = f.norm();
    if (length > 0.5) {
      const Eigen::Vector3d u = f / length;
      const double angle = std::atan2(u.dot(pt.n.cross(t1)), u.dot(t1));
      const double facet = 2.0 * std::numbers::pi / static_cast<double>(scene.model.facets);
      const double off = std::remainder(angle, facet);
      if (std::abs(off) > kAlignAngle) t1 = u;
    }
  }
  const Eigen::Vector3d t2 = pt.n.cross(t1);
  pt.edges.resize(cone_cos.size());
  for (size_t j = 0; j < cone_cos.size(); ++j) pt.edges[j] = cone_cos[j] * t1 + cone_sin[j] * t2;
}

// One constituent point of a primitive at q (gripper frame) against the
// object. A finger's point touches only where its closing line meets the
// object (past an edge it has nothing to press on); the pusher's point meets
// the closest surface point, so it may push an edge or a corner. A point
// contact with a radius is a sphere: its centre is q moved back along the
// closing direction by the radius.
void ContactModel::Impl::PlaceOnSolid(Contact& ct, Point& pt, const Eigen::Vector3d& q_in,
                                      const Eigen::Vector3d& base, const Eigen::Vector3d& closing,
                                      const Eigen::Vector3d& vp, const Eigen::Vector3d& wp) {
  const Eigen::Matrix3d& R = pose_R;
  const Eigen::Vector3d& origin = pose_origin;
  const double r = ct.spec.type == ContactType::kPoint ? ct.spec.radius : 0.0;
  const Eigen::Vector3d centre = q_in - r * closing;
  const Eigen::Vector3d centre_O = R.transpose() * (centre - origin);
  pt.active = true;
  if (!ct.pusher) {
    const auto e = solid->EntryOf(centre_O, R.transpose() * closing, gap_tolerance + r);
    if (!e) {
      pt.active = false;
      pt.gap = std::numeric_limits<double>::infinity();
      pt.p = q_in;
      return;
    }
    if (r == 0) {
      pt.p = origin + R * e->point_O;
      pt.n = -(R * e->normal_O);
      pt.gap = e->s * closing.dot(pt.n);
      SetEdges(pt);
      return;
    }
  }
  // On an edge or a vertex, the face pressed last step, or at first the one
  // the point closes onto: the least deep face alone flips with rounding.
  const Eigen::Vector3d prefer_O =
      pt.face_O.squaredNorm() > 0 ? pt.face_O : Eigen::Vector3d(-(R.transpose() * closing));
  // A quasi-static iterate placed at the step's end keeps the pusher's face
  // from the step's start (RestoreStartFaces) down to the depth its motion
  // reaches in the step: at the full speed of the off-centre edge push
  // (1 cm/s, dt 4 ms) the first iterate, the object not yet moved, has the
  // pusher 40 µm under the bottom face, and the least deep face, the front
  // one it moves in the plane of, let it slide up the face with no force.
  const double keep = ct.pusher && at_step_end ? gap_tolerance + dt * PusherSpeed() : gap_tolerance;
  const geometry::Closest cl = solid->ClosestTo(centre_O, prefer_O, keep);
  pt.face_O = cl.normal_O;
  pt.p = origin + R * cl.point_O;
  pt.n = -(R * cl.normal_O);
  pt.gap = cl.distance - r;
  const Eigen::Vector3d body_point = centre + r * pt.n;
  pt.body_velocity = vp + wp.cross(body_point - base);
  SetEdges(pt);
}

// A flat pad (patch) whose first feature towards it is an edge or a vertex
// of the object lying over the disk touches along that edge's chord (a
// line) or at that vertex (a point): its constituent points move there, with
// the disk's normal. Returns false when the pad rests on a face (or its rim
// meets the object): then the ring of constituent points stays.
bool ContactModel::Impl::PlacePatch(Contact& ct, const Eigen::Vector3d& base,
                                    const Eigen::Vector3d& closing, const Eigen::Vector3d& vp,
                                    const Eigen::Vector3d& wp) {
  const Eigen::Matrix3d& R = pose_R;
  const Eigen::Vector3d& origin = pose_origin;
  const geometry::Feature f = solid->Support(R.transpose() * closing, gap_tolerance);
  if (f.kind == geometry::Feature::Kind::kFace) return false;
  const double radius = ct.spec.radius;
  auto in_plane = [&](const Eigen::Vector3d& x) {
    const Eigen::Vector3d d = x - base;
    return Eigen::Vector3d(d - closing.dot(d) * closing);
  };
  std::vector<Eigen::Vector3d> at;  // contact points on the object (gripper frame)
  if (f.kind == geometry::Feature::Kind::kEdge) {
    const Eigen::Vector3d a = origin + R * f.points_O[0];
    const Eigen::Vector3d ab = R * (f.points_O[1] - f.points_O[0]);
    const Eigen::Vector3d pa = in_plane(a), pab = ab - closing.dot(ab) * closing;
    const double A2 = pab.squaredNorm(), B2 = 2 * pa.dot(pab),
                 C2 = pa.squaredNorm() - radius * radius;
    const double disc = B2 * B2 - 4 * A2 * C2;
    if (!(A2 > 1e-24 * L * L) || disc <= 0) return false;
    const double root = std::sqrt(disc);
    const double u0 = std::max(0.0, (-B2 - root) / (2 * A2));
    const double u1 = std::min(1.0, (-B2 + root) / (2 * A2));
    if (!((u1 - u0) * ab.norm() > 1e-6 * radius)) return false;
    const size_t k = ct.points.size();
    for (size_t j = 0; j < k; ++j) {
      const double u = k == 1 ? (u0 + u1) / 2 : u0 + (u1 - u0) * static_cast<double>(j) / (k - 1);
      at.push_back(a + u * ab);
    }
  } else {
    const Eigen::Vector3d v = origin + R * f.points_O[0];
    if (in_plane(v).norm() > radius) return false;
    at.push_back(v);
  }
  for (size_t j = 0; j < ct.points.size(); ++j) {
    Point& pt = ct.points[j];
    if (j >= at.size()) {
      pt.active = false;
      pt.gap = std::numeric_limits<double>::infinity();
      pt.p = base;
      continue;
    }
    pt.active = true;
    pt.p = at[j];
    pt.n = closing;
    pt.gap = closing.dot(at[j] - base);
    pt.body_velocity = vp + wp.cross(at[j] - pt.gap * closing - base);
    SetEdges(pt);
  }
  return true;
}

// Where the pusher contact `ct` is at time `at`: a recorded path's pose, or
// its constant motion from its start (the product the model has always
// computed, so trajectories stay bit for bit); the rotation is the identity
// unless it turns.
ContactModel::Impl::PusherPlacement ContactModel::Impl::PusherAt(const Contact& ct,
                                                                 double at) const {
  PusherPlacement placed;
  if (scene.pusher->path) {
    const PusherPose pose = PusherPoseAt(*scene.pusher, at);
    placed.base = pose.position;
    placed.turned = pose.turned;
    placed.rotation = pose.rotation;
    return placed;
  }
  const PusherMotion& m = scene.pusher->motion;
  placed.base = ct.spec.position + m.velocity * at;
  const double a = m.angular_velocity.norm() * at;
  placed.turned = a > 0;
  if (placed.turned)
    placed.rotation = Eigen::AngleAxisd(a, m.angular_velocity.normalized()).toRotationMatrix();
  return placed;
}

// Contact geometry at time t from the object's pose: each primitive sits
// where the hand (fingers: at their pads' travel along the closing
// direction) or the pusher's motion puts it; its constituent points meet the
// object's surface (PlaceOnSolid, PlacePatch). Point fingers are
// force-controlled pads that stay on the surface: they are re-seated along
// their closing direction every step.
void ContactModel::Impl::TrackedGeometry() {
  // The object's pose, once per step for every primitive placed on it.
  pose_R = q.toRotationMatrix();
  pose_origin = c - pose_R * com_O;  // ObjectOrigin() without converting q again
  for (Contact& ct : contacts) {
    // Only a turning pusher has a rotation (fingers and most pushers keep
    // their directions: no product per point and step).
    bool turned = false;
    Eigen::Matrix3d Rp = Eigen::Matrix3d::Identity();
    Eigen::Vector3d vp = Eigen::Vector3d::Zero(), wp = Eigen::Vector3d::Zero();
    Eigen::Vector3d base = ct.spec.position + ct.pad * ct.spec.normal;
    if (ct.pusher) {
      const PusherPlacement placed = PusherAt(ct, t + place_lead);
      base = placed.base;
      turned = placed.turned;
      Rp = placed.rotation;
      if (scene.pusher->path) {
        // A recorded path: its mean motion over the step.
        const PusherTwist twist = PusherTwistOver(*scene.pusher, t, dt);
        vp = twist.velocity;
        wp = twist.angular_velocity;
      } else {
        vp = scene.pusher->motion.velocity;
        wp = scene.pusher->motion.angular_velocity;
      }
    }
    const Eigen::Vector3d closing = turned ? Eigen::Vector3d(Rp * ct.spec.normal) : ct.spec.normal;
    ct.normal = closing;
    ct.position = base;
    const bool patch = ct.spec.type == ContactType::kPatch && ct.points.size() > 1;
    if (!(patch && PlacePatch(ct, base, closing, vp, wp))) {
      for (Point& pt : ct.points) {
        const Eigen::Vector3d at =
            turned ? Eigen::Vector3d(base + Rp * pt.offset0) : Eigen::Vector3d(base + pt.offset0);
        PlaceOnSolid(ct, pt, at, base, closing, vp, wp);
      }
    }
    if (!ct.pusher && ct.known_normal >= 0 && ct.points[0].active) {
      // A point pad keeps pressing: it travels along its closing direction
      // onto the surface (first order in the gap; the gap is then zero).
      Point& pt = ct.points[0];
      const double along = closing.dot(pt.n);
      if (along < kGrazingFactor && refused.empty()) {
        char buf[200];
        std::snprintf(buf, sizeof buf,
                      "fingers[%d] '%s': presses on a grazing face (its normal %.3g deg from the "
                      "closing direction, limit %.3g): the pad cannot press on it as modelled",
                      static_cast<int>(&ct - contacts.data()), ct.spec.name.c_str(),
                      std::acos(std::clamp(along, -1.0, 1.0)) * 180 / std::numbers::pi,
                      std::acos(kGrazingFactor) * 180 / std::numbers::pi);
        refused = buf;
      }
      if (along >= kGrazingFactor) {
        ct.pad += pt.gap / along;
        ct.position = ct.spec.position + ct.pad * ct.spec.normal;
        pt.gap = 0;
      }
    }
    ct.any_active = false;
    ct.touching = false;
    for (const Point& pt : ct.points) {
      ct.any_active = ct.any_active || pt.active;
      ct.touching = ct.touching || (pt.active && pt.gap <= gap_tolerance);
    }
  }
}

// In a planar scene every point of a line that lies in the plane moves with
// the same tangential velocity, and its velocity along a shared normal is
// linear along the line; so is the gap to a flat face. A force at an interior
// point is then a positive combination of forces at the two ends with the
// same wrench, and pressing there (zero normal velocity) means both ends
// press too: the interior points add nothing to the motion but unknowns to
// the warm-started basis (19 of them for two 3-point lines and a pusher).
// They keep no rows while both ends have rows with one normal; otherwise (an
// end past the object's edge, the line across an edge) all points do.
void ContactModel::Impl::MarkRedundantPoints() {
  for (Contact& ct : contacts) {
    // An elastic pad's interior points carry load by penetration: kept.
    if (ct.spec.type != ContactType::kLine || ct.points.size() <= 2 || ct.spec.stiffness > 0)
      continue;
    bool ends_press = true;
    for (const Point& pt : ct.points) {
      if (!tracked) break;
      const bool same_face = (pt.n - ct.points[0].n).norm() <= 1e-12;
      if (pt.interior ? !same_face : !(pt.active && same_face)) ends_press = false;
    }
    for (Point& pt : ct.points) pt.redundant = pt.interior && ends_press;
  }
}

// ---------------------------------------------------------------------------
// One step in named phases (StepPhase, model_tester.hpp). Each phase reads
// the model's state and the step's scratch (StepScratch) and writes only the
// scratch, except where it says so: PlaceContacts moves the tracked geometry
// (points, normals, gaps, pads re-seated), ReportContacts writes the contact
// states and Integrate the state. The phases' order is the physics':
//   geometry -> inertia -> free motion -> grasp map -> LCP rows (one phase per
//   kind of row) -> solve -> bad values -> contact states -> integration.
// A new kind of contact adds its unknowns in Setup() (force unknowns first,
// velocity unknowns after), its known wrench in FormFreeMotion, its rows in a
// phase of its own after AssemblePadRows (StepMatrix::Set on its unknowns'
// rows and columns; b set alongside), and its report in ReportContacts.

bool ContactModel::Impl::RunPhase(StepPhase phase, StepReport& rep) {
  StepScratch& s = scratch;
  switch (phase) {
    case StepPhase::kPlaceContacts:
      refused.clear();
      PlaceContacts(s);
      if (!refused.empty()) {
        rep.ok = false;
        rep.failure = StepFailure::kModel;
        rep.error = refused;
        return false;
      }
      return true;
    case StepPhase::kMassMatrix:
      FormMassMatrix(s);
      return true;
    case StepPhase::kFreeMotion:
      return FormFreeMotion(s, rep);
    case StepPhase::kGraspMap:
      FormGraspMap(s);
      return true;
    case StepPhase::kContactRows:
      AssembleContactRows(s);
      return true;
    case StepPhase::kConeRows:
      AssembleConeRows(s);
      return true;
    case StepPhase::kPadRows:
      AssemblePadRows(s);
      return true;
    case StepPhase::kSupportRows:
      AssembleSupportRows(s);
      return true;
    case StepPhase::kSolve:
      return Solve(s, rep);
    case StepPhase::kCheckValues:
      return CheckValues(s, rep);
    case StepPhase::kContactStates:
      ReportContacts(s, rep.steering);
      return true;
    case StepPhase::kIntegrate:
      Integrate(s);
      return true;
  }
  return false;
}

bool ContactModel::Impl::BeginStep(StepReport& rep) {
  if (status != SimulationStatus::kOk) {
    rep.ok = false;
    rep.error = error;
    rep.failure = StepFailure::kModel;
    return false;
  }
  ++steps_taken;
  return true;
}

StepReport ContactModel::Impl::Step() {
  StepReport rep;
  if (!BeginStep(rep)) return rep;
  if (quasi_static && tracked && PredictStepEnd()) {
    // A step its predicted end refuses (a contact placed off the object, a
    // solve that fails there) is solved from its start instead.
    StepReport predicted = rep;
    if (RunStep(predicted)) return predicted;
    ReturnToStepStart();
    rep.pivots = predicted.pivots;
    rep.quasi_static_solves = predicted.quasi_static_solves + 1;
  }
  RunStep(rep);
  return rep;
}

// The phases of one step (Step); false when one refused it (rep says why).
bool ContactModel::Impl::RunStep(StepReport& rep) {
  for (int i = 0; i < kStepPhases; ++i) {
    const auto phase = static_cast<StepPhase>(i);
    // The faces the accepted answer was placed on are the next step's.
    if (phase == StepPhase::kIntegrate) ReturnToStepStart(false);
    if (!RunPhase(phase, rep)) return false;
    if (phase != StepPhase::kCheckValues) continue;
    // Aligned cones: while a sliding point's slip turned away from the
    // cone edge its friction sits on, turn the edge onto the new slip and
    // solve the step again (AlignCones); at the fixed point the friction
    // opposes the slip with its full μ λ, as on the circular cone.
    // (Quasi-static steps turn their cones between balances: BalanceAligned.)
    for (int k = 0; k < kAlignSolves && !slip_dampers && AlignCones(scratch); ++k) {
      ++rep.align_solves;
      for (int j = static_cast<int>(StepPhase::kGraspMap); j <= i; ++j) {
        if (!RunPhase(static_cast<StepPhase>(j), rep)) return false;
      }
    }
    if (quasi_static && !(aligned ? BalanceAligned(i, rep) : BalanceStep(i, rep))) return false;
    if (quasi_static && !CarryOnPush(i, rep)) return false;
  }
  if (quasi_static && tracked) last_vr = scratch.vr_new;
  return true;
}

// Quasi-static, tracked: the first solve is placed where the step ends if
// it keeps the last step's twist (the pads travelling as in the last step),
// the end a balanced path nearly reaches, so that the first solve's geometry
// is already the balanced answer's: the pivot past its stall needed 2 extra
// solves in each of its 96 steps before the stall when the first solve was
// placed at the step's start (218 in 600 steps; now 120). Continuing the
// twist by its change over the step before as well doubled them (416; why
// not traced), so the last twist alone is the prediction.
// False when there is nothing to predict from yet (the first step).
bool ContactModel::Impl::PredictStepEnd() {
  if (last_vr.size() != nd || scratch.solution.z.size() == 0) return false;
  PlaceAtStepEnd(scratch, last_vr);
  return true;
}

// Runs the phases from `first` to `last` (and the aligned cones'
// re-solves); false when one refused the step (rep says why).
bool ContactModel::Impl::RunPhases(int first, int last, StepReport& rep) {
  for (int j = first; j <= last; ++j) {
    if (!RunPhase(static_cast<StepPhase>(j), rep)) return false;
  }
  if (balancing_held_cones) return true;
  for (int a = 0; a < kAlignSolves && AlignCones(scratch); ++a) {
    ++rep.align_solves;
    for (int j = static_cast<int>(StepPhase::kGraspMap); j <= last; ++j) {
      if (!RunPhase(static_cast<StepPhase>(j), rep)) return false;
    }
  }
  return true;
}

// Quasi-static (model.inertia): the step solved again from its own answer
// (the mass a proximal term only) until the inertial force it needs
// vanishes. Tracked contacts are placed where that answer ends the step
// (the object at its end pose, the pusher at t + dt): the forces balance on
// the geometry the step ends on. Frozen at the step's start instead, a pivot
// past its stall had no balanced answer (the pusher's line passes the grip
// axis only at the end pose) and ended 23 % short of its closed form.
// A soft mode (an object turning about a sticking pusher between sliding
// fingers) converges linearly with a factor ρ near 1 (0.9993 on the push
// along the grip axis: thousands of solves); from two successive changes
// of the answer ρ is estimated and the answer extrapolated to its limit
// (Aitken), which the next solves check. Where no balanced answer exists
// (ρ = 1: every solve changes the twist by the same unbalanced force, e.g.
// an object sliding out of its grasp) or none is found within
// kQuasiStaticSolves, the step is the carried one: quasi-static where the
// forces can balance, dynamic where they cannot. False when a phase refused
// the step.
bool ContactModel::Impl::BalanceStep(int last, StepReport& rep) {
  return Rebalance(last, rep) || CarryStep(last, rep);
}

// BalanceStep's solves: true when the answer balances and a push gives it
// (last_step_carried cleared); false when none was found (the caller carries
// the step: the scratch may hold a solve placed where it found no answer).
bool ContactModel::Impl::Rebalance(int last, StepReport& rep) {
  SmallVector previous;  // the last solve's change of twist (none after an extrapolation)
  bool balanced = InertialForce(scratch) <= kQuasiStatic;
  for (int k = 0; k < kQuasiStaticSolves && !balanced; ++k) {
    SmallVector centre = scratch.vr_new;
    const SmallVector change = scratch.vr_new - scratch.vr;
    bool extrapolated = false;
    if (previous.size() == change.size()) {
      const double den = previous.dot(scratch.Mr * previous);
      const double rho = den > 0 ? change.dot(scratch.Mr * previous) / den : 0.0;
      if (std::abs(rho - 1) <= kNoBalance) break;
      if (rho > kExtrapolateFrom && rho < 1) {
        centre += rho / (1 - rho) * change;
        extrapolated = true;
      }
    }
    previous = extrapolated ? SmallVector() : change;
    ++rep.quasi_static_solves;
    int first = static_cast<int>(StepPhase::kFreeMotion);
    if (tracked) {
      PlaceAtStepEnd(scratch, centre);
      first = static_cast<int>(StepPhase::kPlaceContacts);
    } else {
      scratch.vr = centre;
    }
    // An answer the step cannot take there (an extrapolation too far) is
    // no balance either: the carried step decides.
    StepReport trial = rep;
    if (!RunPhases(first, last, trial)) {
      rep.pivots = trial.pivots;
      rep.quasi_static_solves = trial.quasi_static_solves;
      return false;
    }
    rep = trial;
    balanced = InertialForce(scratch) <= kQuasiStatic;
  }
  if (balanced && BalanceIsAcceptable(scratch)) {
    last_step_carried = false;
    return true;
  }
  return false;
}

// The step that found no acceptable balance: the carried one, solved again
// where the step starts (and on the faces its points pressed there: an
// iterate's placement must not choose them), its cones turned within it.
bool ContactModel::Impl::CarryStep(int last, StepReport& rep) {
  last_step_carried = true;
  ReturnToStepStart();
  ++rep.quasi_static_carried;
  balancing_held_cones = false;
  // Its inertia chooses the slip: no slip dampers (ones set by a balance
  // that failed, kept, left a carried step of the pivot past its stall at
  // dt 4 ms with a damper at 22 % of μ λ, the friction outside its cone).
  for (Contact& ct : contacts)
    for (Point& pt : ct.points) pt.damp_c = 0;
  return RunPhases(static_cast<int>(StepPhase::kPlaceContacts), last, rep);
}

// Quasi-static with aligned cones: the step balanced with its cones held
// and their slip dampers set (SetSlipDampers), then the cones turned onto
// the balanced answer's slip (AlignCones) and the step balanced again, until
// no cone turns (at most kAlignSolves turns). Turned inside every solve of
// the balance instead, each solve met other cones: the balance's changes
// never fell below the cones' own tolerance, its estimate of their
// convergence came out near 1 and its extrapolation threw the object off
// its contacts (issue 31's tilted push through the grip axis ended metres
// away). Balances resumed after a turn when not yet found (8 solves between
// turns) ended further off (+2.4 % against +0.09 % on that push at dt 1 ms,
// 8 facets) at 5 times the solves. A step with no balance is the carried
// one, its cones turned within it.
bool ContactModel::Impl::BalanceAligned(int last, StepReport& rep) {
  for (int a = 0;; ++a) {
    balancing_held_cones = true;
    if (slip_dampers) SetSlipDampers(scratch);
    const bool balanced = Rebalance(last, rep);
    balancing_held_cones = false;
    if (!balanced) return CarryStep(last, rep);
    if (a >= kAlignSolves || !TurnCones(scratch)) return true;
    ++rep.align_solves;
    if (slip_dampers) SetSlipDampers(scratch);
    // From the free motion on: the dampers across the turned edges
    // (ApplySlipDampers) as well as the edges' rows.
    for (int j = static_cast<int>(StepPhase::kMassMatrix); j <= last; ++j) {
      if (!RunPhase(static_cast<StepPhase>(j), rep)) return false;
    }
  }
}

// Quasi-static, after the balance: a push that needs the object's momentum.
// The pusher moving into the object across a face it does not press (its
// face turned at an edge between balanced and carried steps), or a step
// with no balance while the pusher presses (carried, CarryStep), mixes the
// two models: the momentum a carried step gives the next balanced one
// drops, so the run is neither's answer (the off-centre edge push at dt
// 0.1 ms, aligned cones: 456 of 2000 steps carried, x(T) 17 % off its
// resolved branch, "ok"). With "auto" the run turns carried from this step
// on (the step solved again carried; ModelInfo says carried, and Simulate
// runs an open-loop scene again carried from its start); with
// "quasi_static" it is refused naming model.inertia. False when refused.
bool ContactModel::Impl::CarryOnPush(int last, StepReport& rep) {
  const bool slides_in = tracked && PusherSlidesIn(scratch);
  if (!slides_in && !(last_step_carried && scene.pusher && PusherPresses(scratch))) return true;
  if (inertia_auto) {
    quasi_static = slip_dampers = false;
    info.inertia = InertiaModel::kCarried;
    if (last_step_carried) return true;
    return CarryStep(last, rep);
  }
  rep.ok = false;
  rep.failure = StepFailure::kModel;
  rep.error = slides_in
                  ? "model.inertia: quasi_static: the pusher moves into the object across a face "
                    "it does not press (its face turned at an edge between balanced and carried "
                    "steps); \"inertia\": \"carried\" or \"auto\" models this push"
                  : "model.inertia: quasi_static: no balance while the pusher presses (the push "
                    "needs the object's momentum); \"inertia\": \"carried\" or \"auto\" models "
                    "this push";
  return false;
}

// Quasi-static: whether a balanced answer (no inertial force) is one a push
// gives. The balance weighs forces only, so it passes two answers no push
// does, which are then refused and the carried step taken
// (solver.quasi_static_carried): a twist the drive cannot reach in a step
// (an extrapolation that throws the object out of its grasp is a free
// flight, trivially balanced), and a pusher that ends the step inside the
// object (it pushes nothing there). Carried steps reach their twist through
// the contact forces' impulse; balanced ones may also take up the pusher's
// motion at once, so the bound is that motion (kReachFactor at the object's
// extent) plus the impulse of every force in the step.
bool ContactModel::Impl::BalanceIsAcceptable(const StepScratch& s) const {
  const Eigen::Matrix<double, 6, 1> tw = P * s.vr_new;
  const Eigen::Vector3d& v0 = step_start ? step_start->v : v;
  const Eigen::Vector3d& w0 = step_start ? step_start->w : w;
  const double change = (tw.head<3>() - v0).norm() + (tw.tail<3>() - w0).norm() * L;
  const double pusher_speed = PusherSpeed();
  // Every force's magnitude (λ, β and the support's unknowns; the point
  // pads' known normals), and the known load.
  double force = mass * scene.gravity.norm();
  for (int i = 0; i < nf; ++i) force += std::abs(Unknown(s, i));
  // (A point finger off the object gives none: counted, its load let an
  // iterate that threw the object out of the grasp pass as reachable.)
  for (const Contact& ct : contacts)
    if (ct.known_normal > 0 && Live(ct.points[0])) force += (1 + ct.spec.mu) * ct.known_normal;
  const double I_min = inertia_body.diagonal().minCoeff();
  const double reach = kReachFactor * pusher_speed + force * dt * (1 / mass + L * L / I_min);
  if (!(change <= reach)) return false;
  // After a carried step, an object that moves while its pusher presses
  // nothing coasts on what the carried step gave its free modes (along the
  // grip axis, the pads following; about it, between point fingers): no
  // inertial force, but momentum, not a balance (the edge push at dt 0.1 ms
  // after its carried start coasted away from the pusher, x(T) -1.94 mm).
  if (scene.pusher && last_step_carried &&
      tw.head<3>().norm() + tw.tail<3>().norm() * L > slip_floor && !PusherPresses(s))
    return false;
  return !tracked || !(PusherDepthAtStepEnd(s.vr_new) < -gap_tolerance);
}

// Whether the pusher presses the object in the step's answer (its normal
// forces above 1e-9 of the force scale).
bool ContactModel::Impl::PusherPresses(const StepScratch& s) const {
  double pressed = 0;
  for (const Contact& ct : contacts)
    if (ct.pusher)
      for (const Point& pt : ct.points)
        if (HasRows(pt) && pt.lambda >= 0) pressed += Unknown(s, pt.lambda);
  return pressed > 1e-9 * Fs;
}

// Quasi-static, tracked: whether the step's answer has a pusher point that
// touches a face across its closing direction (|n · closing| < 1/2), presses
// it with no force, and moves into the object along the closing direction
// at more than half its speed: it passes into the object through the face
// it closes onto, which no model does. The off-centre edge push at dt
// 0.1 ms reached it after its carried start (x(T) 2.3 % off, the pusher on
// the front face for the last 99 % of the run); the step is refused, typed,
// rather than run on (docs/scene.md).
bool ContactModel::Impl::PusherSlidesIn(const StepScratch& s) const {
  const double speed = PusherSpeed();
  if (!(speed > 0)) return false;
  for (const Contact& ct : contacts) {
    if (!ct.pusher) continue;
    for (const Point& pt : ct.points) {
      if (!pt.active || pt.gap > gap_tolerance || std::abs(pt.n.dot(ct.normal)) >= 0.5) continue;
      const double lam = HasRows(pt) && pt.lambda >= 0 ? Unknown(s, pt.lambda) : 0.0;
      if (lam > 1e-9 * Fs) continue;
      const double inward = (pt.body_velocity - ObjectVelocity(s, pt.p)).dot(ct.normal);
      if (inward > 0.5 * speed) return true;
    }
  }
  return false;
}

// The fastest the pusher moves over this step at the object's extent (m/s;
// 0 without a pusher).
double ContactModel::Impl::PusherSpeed() const {
  if (!scene.pusher) return 0;
  const PusherTwist twist = PusherTwistOver(*scene.pusher, t, dt);
  const Eigen::Vector3d& vp = scene.pusher->path ? twist.velocity : scene.pusher->motion.velocity;
  const Eigen::Vector3d& wp =
      scene.pusher->path ? twist.angular_velocity : scene.pusher->motion.angular_velocity;
  return vp.norm() + wp.norm() * ((scene.pusher->position - c).norm() + L);
}

// Tracked: the pusher's deepest point inside the object (its signed
// distance, < 0 inside; 0 without a pusher) where the twist ends the step.
double ContactModel::Impl::PusherDepthAtStepEnd(const SmallVector& twist) const {
  const Eigen::Matrix<double, 6, 1> tw = P * twist;
  const Eigen::Vector3d c0 = step_start ? step_start->c : c;
  const Eigen::Quaterniond q0 = step_start ? step_start->q : q;
  Eigen::Quaterniond q_end = q0;
  const double angle = tw.tail<3>().norm() * dt;
  if (angle > 0)
    q_end =
        (Eigen::Quaterniond(Eigen::AngleAxisd(angle, tw.tail<3>().normalized())) * q0).normalized();
  const Eigen::Matrix3d R = q_end.toRotationMatrix();
  const Eigen::Vector3d origin = c0 + dt * tw.head<3>() - R * com_O;
  double deepest = 0;
  for (const Contact& ct : contacts) {
    if (!ct.pusher) continue;
    const PusherPlacement placed = PusherAt(ct, t + dt);
    const Eigen::Vector3d& base = placed.base;
    const Eigen::Matrix3d& Rp = placed.rotation;
    const double r = ct.spec.type == ContactType::kPoint ? ct.spec.radius : 0.0;
    const Eigen::Vector3d closing = Rp * ct.spec.normal;
    for (const Point& pt : ct.points) {
      const Eigen::Vector3d centre = base + Rp * pt.offset0 - r * closing;
      deepest = std::min(deepest, solid->ClosestTo(R.transpose() * (centre - origin)).distance - r);
    }
  }
  return deepest;
}

// Quasi-static, tracked: moves the state to where the last solve ends the
// step (pose and twist, the free pads' travel) and places the contacts
// there on the next kPlaceContacts, the pusher at t + dt. Integrate starts
// from the step's start again (ReturnToStepStart).
void ContactModel::Impl::PlaceAtStepEnd(const StepScratch& s, const SmallVector& centre) {
  const Eigen::Matrix<double, 6, 1> tw = P * centre;
  const Eigen::Vector3d v_end = tw.head<3>(), w_end = tw.tail<3>();
  if (!step_start) {
    StepStart start{c, v, w, q, {}};
    start_faces.clear();
    start_slips.clear();
    for (const Contact& ct : contacts) {
      start.pads.push_back(ct.pad);
      for (const Point& pt : ct.points) {
        start_faces.push_back(pt.face_O);
        start_slips.push_back(pt.slip);
      }
    }
    step_start = std::move(start);
  }
  RestoreStartFaces();
  const StepStart& start = *step_start;
  for (size_t i = 0; i < contacts.size(); ++i) {
    Contact& ct = contacts[i];
    ct.pad = start.pads[i];
    if (!ct.pusher && ct.active && ct.y_plus >= 0 && ct.known_normal < 0)
      ct.pad += dt * (Unknown(s, ct.y_plus) - Unknown(s, ct.y_minus));
  }
  c = start.c + dt * v_end;
  q = start.q;
  const double angle = w_end.norm() * dt;
  if (angle > 0)
    q = (Eigen::Quaterniond(Eigen::AngleAxisd(angle, w_end.normalized())) * q).normalized();
  v = v_end;
  w = w_end;
  place_lead = dt;
  at_step_end = true;
}

// Every iterate of a step is placed from the faces its points pressed at
// the step's start (PlaceOnSolid keeps a face while the point stays within
// tolerance of it). Kept from the iterate before instead, one extrapolated
// iterate that sank the pusher on the bottom-front edge deeper than the
// tolerance under the bottom face put it on the front face for every later
// iterate: its normal turned across the push, the pusher slid into the
// object with no force, and the object's slide along the grip axis passed
// as balanced (docs/scene.md, the off-centre edge push).
void ContactModel::Impl::RestoreStartFaces() {
  if (!step_start) return;
  size_t k = 0;
  for (Contact& ct : contacts)
    for (Point& pt : ct.points) pt.face_O = start_faces[k++];
}

// Undoes PlaceAtStepEnd before the step integrates (start_faces false: the
// accepted answer's faces stay) or is solved again from its start.
void ContactModel::Impl::ReturnToStepStart(bool start_faces) {
  place_lead = 0;
  at_step_end = false;
  if (!step_start) return;
  if (start_faces) {
    RestoreStartFaces();
    size_t k = 0;
    for (Contact& ct : contacts)
      for (Point& pt : ct.points) pt.slip = start_slips[k++];
  }
  c = step_start->c;
  q = step_start->q;
  v = step_start->v;
  w = step_start->w;
  for (size_t i = 0; i < contacts.size(); ++i) contacts[i].pad = step_start->pads[i];
  step_start.reset();
}

// Placed at the end of the step (PlaceAtStepEnd), a gap g is where the
// iterate (twist u_k at the point, the body's u_b) leaves it; the rows
// linearise around that iterate, g + dt n·(u - u_k) >= 0, so each row's gap
// becomes g - dt n·(u_k - u_b), which the rows add to n·(u - u_b) dt.
void ContactModel::Impl::GapsFromStepEnd(const StepScratch& s) {
  for (Contact& ct : contacts) {
    if (!ct.active) continue;
    for (Point& pt : ct.points) {
      if (pt.lambda < 0 || !HasRows(pt)) continue;
      const Eigen::Vector3d& nrm = NormalOf(ct, pt);
      const Eigen::Vector3d u_k = v + w.cross(pt.p - c);
      double u_b = nrm.dot(pt.body_velocity);
      if (!ct.pusher)
        u_b = ct.y_plus >= 0 ? nrm.dot(ct.normal) * (Unknown(s, ct.y_plus) - Unknown(s, ct.y_minus))
                             : 0.0;
      pt.gap -= dt * (nrm.dot(u_k) - u_b);
    }
  }
}

// The inertial force (and torque over the length scale) of the step's
// change of twist, relative to the force scale.
double ContactModel::Impl::InertialForce(const StepScratch& s) const {
  const SmallVector f = s.Mr * (s.vr_new - s.vr) / dt;
  double worst = 0;
  for (int i = 0; i < nd; ++i) {
    const bool torque = planar ? i == 2 : i >= 3;
    worst = std::max(worst, std::abs(f[i]) / (Fs * (torque ? L : 1.0)));
  }
  return worst;
}

// Quasi-static, aligned cones: a sliding point's friction is its cone's
// aligned edge (μ λ) plus a damper across the edge, -c (d · u) d for its
// slip u and d the tangent across the edge, with c = μ λ / |u| of the last
// solve: the circular cone's -μ λ u / |u| to first order in the slip's turn
// off the edge. At a vertex of the polyhedral cone alone the slip may lie
// anywhere in the vertex's fan (±π/facets); a balance weighs forces only,
// so nothing chose it there and the balance drifted along that freedom
// (carried steps' inertia chooses it). The damper chooses it smoothly, and
// where the cones settle (the edge opposing the slip) its force vanishes to
// second order in the miss. It replaced two extra cone edges 0.8 mrad
// either side of the aligned one, which chose the slip within ±0.4 mrad but
// moved the friction between them in steps of μ λ · 8e-4 as the balance's
// iterate moved: balances stalled near 1e-4 of the force scale (the target
// is 1e-6) and the warm start failed (20-33 Lemke pivots a solve): 26 to 46
// times the default model's cost on 6-DOF line and patch fingers, 3 to 4
// times with the dampers (bench/README.md, "Aligned cones with quasi-static
// steps"). c is held within a balance, so its solves meet one map.
void ContactModel::Impl::SetSlipDampers(const StepScratch& s) {
  for (Contact& ct : contacts) {
    for (Point& pt : ct.points) {
      pt.damp_c = 0;
      if (!ct.active || !HasRows(pt) || pt.beta0 < 0 || pt.edges.empty()) continue;
      double lam = 0;
      Eigen::Vector3d ut;
      if (!SlideOf(s, ct, pt, lam, ut)) continue;
      pt.damp_c = ct.spec.mu * lam / ut.norm();
      pt.damp_edge = 0;
      if (Unknown(s, pt.beta0) > 0) continue;  // on the turned edge (or beside it on a face)
      for (int e = 1; e < edges_per_point; ++e) {
        if (Unknown(s, pt.beta0 + e) > Unknown(s, pt.beta0 + pt.damp_edge)) pt.damp_edge = e;
      }
    }
  }
}

// AlignCones, and with slip dampers also true (solve again with their
// coefficients renewed: SetSlipDampers) while a damper's force is not yet
// negligible: its coefficient is the last solve's μ λ / |u|, so a slip that
// sped up since carries a damper too strong for its miss (a step of issue
// 31's tilted push left one at 11 % of μ λ across
// its edge after its slip sped up about 30-fold, the friction 0.6 % outside
// its cone).
bool ContactModel::Impl::TurnCones(StepScratch& s) {
  return AlignCones(s) || (slip_dampers && !DampersSettled(s));
}

// Every slip damper's force at most kAlignMiss of its point's μ λ: the miss
// the cones' turns leave (AlignCones), so the friction's direction within it
// and its size within the cone to second order.
bool ContactModel::Impl::DampersSettled(const StepScratch& s) const {
  if (s.D.size() == 0) return true;
  for (const Contact& ct : contacts) {
    if (!ct.active) continue;
    for (const Point& pt : ct.points) {
      if (!(pt.damp_c > 0) || !HasRows(pt) || pt.beta0 < 0 || pt.edges.empty()) continue;
      const double lam = pt.lambda >= 0 ? Unknown(s, pt.lambda) : ct.known_normal;
      const double force = pt.damp_c * std::abs(SlipDamperDirection(ct, pt).dot(pt.urel));
      if (force > kAlignMiss * ct.spec.mu * std::max(lam, 0.0)) return false;
    }
  }
  return true;
}

// Whether a point slides in the last solve with its friction on its cone's
// rim and a slip fast enough to have a direction (kAlignSlip): its normal
// force in lam and its slip in the tangent plane in ut (aligned cones:
// MeasureAlignMiss, SetSlipDampers).
bool ContactModel::Impl::SlideOf(const StepScratch& s, const Contact& ct, const Point& pt,
                                 double& lam, Eigen::Vector3d& ut) const {
  lam = pt.lambda >= 0 ? Unknown(s, pt.lambda) : ct.known_normal;
  if (!(lam > 1e-9 * Fs)) return false;
  double bsum = 0;
  for (int e = 0; e < edges_per_point; ++e) bsum += Unknown(s, pt.beta0 + e);
  if (ct.spec.mu * lam - bsum > 1e-9 * ct.spec.mu * lam) return false;  // sticking
  ut = pt.urel - pt.n.dot(pt.urel) * pt.n;
  return ut.squaredNorm() > kAlignSlip * kAlignSlip * Vs * Vs;
}

// The tangent across a point's aligned edge (damp_edge) along which its
// damper acts: a point finger's pad follows the object along its closing
// direction, so the slip across the edge as its friction rows see it
// (FormGraspMap). (Across edges[0] whatever the slip, a finger sliding
// along ±t2 at 8 facets had a damper along its slip: twice its friction.)
Eigen::Vector3d ContactModel::Impl::SlipDamperDirection(const Contact& ct, const Point& pt) const {
  Eigen::Vector3d d = pt.n.cross(pt.edges[static_cast<size_t>(pt.damp_edge)]);
  if (tracked && ct.known_normal >= 0 && !ct.pusher) {
    const double along = pt.n.dot(ct.normal);
    if (along >= kGrazingFactor) d -= d.dot(ct.normal) / along * pt.n;
  }
  return d;
}

// Phase 3, aligned and quasi-static: the dampers in the step's equation,
// (M/dt + D) v' = M v/dt + Q + Db + J f, so that M⁻¹ and the free twist
// become those of M + dt D; the force balance's residual counts D v' - Db.
void ContactModel::Impl::ApplySlipDampers(StepScratch& s) {
  // Six coordinates (slip dampers need 6 DOF): fixed sizes throughout.
  Eigen::Matrix<double, 6, 6> D = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> Db = Eigen::Matrix<double, 6, 1>::Zero();
  bool any = false;
  for (const Contact& ct : contacts) {
    if (!ct.active) continue;
    for (const Point& pt : ct.points) {
      if (!(pt.damp_c > 0) || !HasRows(pt) || pt.edges.empty()) continue;
      const Eigen::Vector3d d = SlipDamperDirection(ct, pt);
      Eigen::Matrix<double, 6, 1> j;
      j << d, (pt.p - c).cross(d);
      D.noalias() += pt.damp_c * j * j.transpose();
      if (ct.pusher) Db += pt.damp_c * d.dot(pt.body_velocity) * j;
      any = true;
    }
  }
  if (!any) {
    s.Minv = InverseOfSpd(s.Mr);
    s.vfree = s.vr + dt * s.Minv * s.Q;
    return;
  }
  // In reduced coordinates (P orthonormal: the identity in full 6 DOF).
  const SmallMatrix Dr = P.transpose() * D * P;
  const SmallVector Dbr = P.transpose() * Db;
  s.Minv = InverseOfSpd(s.Mr + dt * Dr);
  s.vfree = s.Minv * (s.Mr * s.vr + dt * (s.Q + Dbr));
  s.D = Dr;
  s.Db = Dbr;
}

// AlignCones, one point: false when it does not slide in a direction worth
// aligning to; otherwise its miss, the friction's direction ψ, and whether
// the friction lies on a face (or is pinned there) in m.
bool ContactModel::Impl::MeasureAlignMiss(const StepScratch& s, const Contact& ct, double facet,
                                          AlignMiss& m) {
  Point& pt = *m.pt;
  double lam = 0;
  Eigen::Vector3d ut;
  if (!SlideOf(s, ct, pt, lam, ut)) return false;
  m.t1 = FirstTangent(pt.n);
  m.t2 = pt.n.cross(m.t1);
  const Eigen::Vector3d& e0 = pt.edges[0];
  const double phi = std::atan2(-ut.dot(m.t2), -ut.dot(m.t1));
  // The edges repeat every facet: the friction sits on the one nearest
  // the slip's opposite. (Measured from edges[0] alone, a slide along
  // another edge of the basis, e.g. -t1, which a snap onto the basis
  // or SetEdges leaves with edges[0] = t1, missed by π every solve and
  // spent all kAlignSolves re-solves on every step, the answer unchanged.)
  const double theta0 = std::atan2(e0.dot(m.t2), e0.dot(m.t1));
  m.miss = std::remainder(phi - theta0, facet);
  m.theta = phi - m.miss;
  // The friction on a face of the cone (between two edges) rather than
  // on an edge: the slip is then along the face's normal, half a facet
  // from both edges, and its miss says nothing (its sign is rounding).
  // The friction's own direction ψ does: where the balance fixes it (the
  // pusher sticking, the object's inertia over dt small), the slip swings
  // across the whole fan for a turn of the edge far below kAlignAngle,
  // and the edge belongs on ψ (the tilted push through the grip axis at
  // dt 4 ms missed by ±π/8 on every re-solve of every step, 12 each, and
  // ended 1.8 % short of its closed form; on ψ it is within 0.05 %).
  Eigen::Vector3d friction = Eigen::Vector3d::Zero();
  for (int e = 0; e < edges_per_point; ++e) friction += Unknown(s, pt.beta0 + e) * pt.edges[e];
  m.psi = std::atan2(friction.dot(m.t2), friction.dot(m.t1));
  m.face = std::abs(std::remainder(m.psi - theta0, facet)) > kAlignAngle;
  // Pinned: the edge was put on ψ in this step and the friction went
  // back onto a face at the same ψ, or the friction lies on a face again
  // after the step before put the edge on ψ (or was pinned): the balance
  // fixes the friction, and where the slip falls within the fan is not
  // resolved by turning the edge (the pivot past its stall, rocking:
  // 2,900 re-solves in its 600 steps without this rule, 367 pinning only
  // within a step, 109 with it). It is left where it is.
  // (Not in quasi-static steps: their fan beside the edge resolves the
  // slip, and a pin held the tilted push's fingers on a face of the cone
  // step after step: 67 % too far at dt 2 ms, 8 facets.)
  if (m.face && !quasi_static &&
      ((pt.align_jump_step == steps_taken &&
        std::abs(std::remainder(m.psi - pt.align_jump_psi, 2 * std::numbers::pi)) <= kAlignAngle) ||
       pt.align_pinned_step >= steps_taken - 1 || pt.align_jump_step == steps_taken - 1)) {
    m.face = false;
    m.pinned = true;
    pt.align_pinned_step = steps_taken;
  }
  return true;
}

// Aligned cones (tracked, 6 DOF): for every sliding point, the angle θ of
// the edge its friction sits on and the angle φ(θ) opposite its slip after
// the solve; the cone is right where φ(θ) = θ (friction opposing the slip
// with its full μ λ, the circular cone's answer). Simply turning the edge
// onto the slip (θ ← φ) need not converge: with the pusher sticking, a
// small turn of the friction swings the slip by many times as much (the
// object's small inertia over dt), and the edge flips between two sides.
// So the first miss moves θ onto the slip and the next ones take the secant
// step on the miss φ(θ) - θ; a friction on a face of the cone (where the
// miss says nothing) moves θ onto the friction's own direction, and a probe
// then measures the slope (MeasureAlignMiss). True when a cone turned
// (solve again).
bool ContactModel::Impl::AlignCones(StepScratch& s) {
  if (!aligned) return false;
  using Miss = AlignMiss;
  std::vector<Miss>& misses = align_misses;
  misses.clear();
  bool any = false;
  double num = 0, den = 0;  // the secant slope, fitted over the sliding points
  const double facet = 2.0 * std::numbers::pi / static_cast<double>(scene.model.facets);
  for (Contact& ct : contacts) {
    if (!ct.active) continue;
    for (Point& pt : ct.points) {
      if (!HasRows(pt) || pt.beta0 < 0 || pt.edges.empty()) continue;
      Miss m{&pt, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 0, 0};
      if (!MeasureAlignMiss(s, ct, facet, m)) continue;
      if (!m.pinned && (m.face || std::abs(m.miss) > kAlignAngle)) any = true;
      if (pt.align_step == steps_taken && !m.face && !m.pinned && !pt.align_face) {
        const double dtheta = std::remainder(m.theta - pt.align_theta, 2 * std::numbers::pi);
        num += (m.miss - pt.align_miss) * dtheta;
        den += dtheta * dtheta;
      }
      misses.push_back(m);
    }
  }
  if (!any) return false;
  // The sliding points sit on one rigid object, so their misses move
  // together: one slope for all of them (a slope per point lets two
  // fingers that share a slip fight each other).
  // The slope may have either sign: where the friction's direction is
  // fixed by the balance, the slip turns with the edge, faster than it.
  if (den > 0 && num != 0) align_slope = num / den;
  // The secant step (the slope of the last step's solves until this step
  // has its own), no longer than a facet (the miss is not linear once the
  // slip leaves the edge's fan); without a slope, half the miss.
  const auto turn = [&](const Miss& m) {
    // Just put on ψ: a small step towards the slip, to measure the slope.
    if (m.pt->align_face && m.pt->align_step == steps_taken)
      return std::copysign(kAlignProbe, m.miss);
    return align_slope != 0 ? std::clamp(-m.miss / align_slope, -facet, facet)
                            : kAlignFirst * m.miss;
  };
  // Done once no cone would turn by more than kAlignAngle: the friction's
  // direction is then right within it even where the slip itself is not
  // (the slip can jump across a vertex's whole fan, ±π/facets, when the
  // friction turns by less than 1e-3 rad: the carried pivot past its stall
  // missed by exactly ±π/8 on 497 of its 600 steps and spent all
  // kAlignSolves re-solves on each; stopped here, 401 re-solves in the run).
  double largest = 0;
  for (const Miss& m : misses)
    if (!m.pinned) largest = std::max(largest, m.face ? facet : std::abs(turn(m)));
  // And the slip within kAlignMiss of opposing it: with a steep slope a
  // turn below kAlignAngle can leave the slip 1e-2 rad off (+0.7 % on the
  // tilted push at dt 4 ms).
  // (Not a point on an edge of the tangent basis whose turn would snap
  // straight back onto it: the snap keeps a slide along that edge the
  // polyhedral cone's exact answer, and waiting for its miss spent all
  // kAlignSolves re-solves on every step of a centred push 3 mrad off
  // plane.)
  const auto on_basis = [&](double angle) {
    return std::abs(std::remainder(angle, facet)) <= kAlignAngle;
  };
  double worst_miss = 0;
  for (const Miss& m : misses) {
    if (m.pinned) continue;
    if (!m.face && on_basis(m.theta) && on_basis(m.theta + turn(m))) continue;
    worst_miss = std::max(worst_miss, m.face ? facet : std::abs(m.miss));
  }
  if (largest <= kAlignAngle && worst_miss <= kAlignMiss) return false;
  for (const Miss& m : misses) {
    Point& pt = *m.pt;
    if (m.pinned) continue;
    double next = m.face ? m.psi : m.theta + turn(m);
    pt.align_face = m.face;
    if (m.face) {
      pt.align_jump_step = steps_taken;
      pt.align_jump_psi = m.psi;
    }
    // Within kAlignAngle of an edge of the tangent basis: that edge, exactly
    // (a slide along an edge keeps the polyhedral cone's exact answer).
    const bool snap = on_basis(next);
    if (snap) next -= std::remainder(next, facet);
    pt.align_step = steps_taken;
    pt.align_theta = m.theta;
    pt.align_miss = m.miss;
    const Eigen::Vector3d u =
        snap ? m.t1 : Eigen::Vector3d(std::cos(next) * m.t1 + std::sin(next) * m.t2);
    pt.slip = snap ? Eigen::Vector3d(-(std::cos(next) * m.t1 + std::sin(next) * m.t2)) : -u;
    const Eigen::Vector3d u2 = pt.n.cross(u);
    for (size_t j = 0; j < cone_cos.size(); ++j) pt.edges[j] = cone_cos[j] * u + cone_sin[j] * u2;
  }
  return true;
}

// Phase 1. This step's geometry: points, normals, friction directions, gaps,
// and whether each point has rows.
void ContactModel::Impl::PlaceContacts(StepScratch& s) {
  if (tracked) {
    TrackedGeometry();
  } else {
    Geometry();
  }
  if (planar) MarkRedundantPoints();
  if (at_step_end) GapsFromStepEnd(s);
  // The object's rotation (tracked geometry has just formed it from q).
  s.R = tracked ? pose_R : q.toRotationMatrix();
}

// Phase 2. Reduced mass matrix, its inverse, and the twist in reduced
// coordinates.
void ContactModel::Impl::FormMassMatrix(StepScratch& s) {
  Eigen::Matrix<double, 6, 1> tw;
  tw << v, w;
  if (planar) {
    // Pᵀ diag(m I, R I Rᵀ) P on the plane's coordinates (e1, e2 in the
    // plane, turning about its normal p), written out on fixed 3x3 sizes.
    const Eigen::Vector3d p_body = s.R.transpose() * plane_normal;
    Eigen::Matrix3d Mr3 = Eigen::Matrix3d::Zero();
    Mr3(0, 0) = mass * plane_e1.dot(plane_e1);
    Mr3(0, 1) = Mr3(1, 0) = mass * plane_e1.dot(plane_e2);
    Mr3(1, 1) = mass * plane_e2.dot(plane_e2);
    Mr3(2, 2) = p_body.dot(inertia_body * p_body);
    s.Mr = Mr3;
    s.Minv = Mr3.inverse();  // closed form for 3x3 (Mr3 is the planar mass: SPD)
    s.vr = Pt3 * tw;
  } else {
    Eigen::Matrix<double, 6, 6> M6 = Eigen::Matrix<double, 6, 6>::Zero();
    M6.topLeftCorner<3, 3>() = mass * Eigen::Matrix3d::Identity();
    M6.bottomRightCorner<3, 3>() = s.R * inertia_body * s.R.transpose();
    s.Mr = P.transpose() * M6 * P;
    // With slip dampers the inverse is that of M + dt D (ApplySlipDampers).
    if (!slip_dampers) s.Minv = InverseOfSpd(s.Mr);
    s.vr = P.transpose() * tw;
  }
}

// Phase 3. Known wrench: gravity and point fingers' normal forces; the
// twist they give without contact forces. The gyroscopic torque -ω × Iω is
// left out: it is second order in the slow turning rates of pushing (the
// quasi-dynamic regime of the model), and its explicit integration pumps
// energy into a spinning body. A non-finite free twist (a state or a known
// wrench gone bad) is refused here, before the solver sees it.
bool ContactModel::Impl::FormFreeMotion(StepScratch& s, StepReport& rep) {
  Eigen::Matrix<double, 6, 1> known = Eigen::Matrix<double, 6, 1>::Zero();
  known.head<3>() = mass * scene.gravity;
  for (const Contact& ct : contacts) {
    if (ct.known_normal > 0 && Live(ct.points[0])) {
      const Eigen::Vector3d f = ct.known_normal * NormalOf(ct, ct.points[0]);
      known.head<3>() += f;
      known.tail<3>() += (ct.points[0].p - c).cross(f);
    }
  }
  s.Q = planar ? SmallVector(Pt3 * known) : SmallVector(P.transpose() * known);
  s.D.resize(0, 0);
  if (slip_dampers) {
    ApplySlipDampers(s);
  } else {
    s.vfree = s.vr + dt * s.Minv * s.Q;
  }
  if (AllFiniteEntries(s.vfree) && AllFiniteEntries(s.Minv)) return true;
  return Refuse(rep, "non-finite free twist (the object's twist, mass matrix or known wrench)");
}

// Phase 4. Columns of the grasp map for every force unknown, in reduced
// coordinates, and K = M⁻¹ J. Velocity rows use Jv: the same directions,
// except that a tracked point finger's pad follows the object along its
// closing direction c, so its friction rows see d' = d - (d·c)/(n·c) n (the
// pad's normal following removed from the relative velocity).
void ContactModel::Impl::FormGraspMap(StepScratch& s) {
  Eigen::MatrixXd& Jc = s.Jc;
  Eigen::MatrixXd& Jv = s.Jv;
  Jc.resize(nd, nf);
  if (tracked) Jv.resize(nd, nf);
  const Point* arm_of = nullptr;  // the point whose arm is below (its unknowns are consecutive)
  Eigen::Vector3d arm = Eigen::Vector3d::Zero(), p_cross_arm = Eigen::Vector3d::Zero();
  const int nf_contacts = ContactForceUnknowns();
  if (support_beta0 >= 0) {
    // The support's limit-surface directions at this pose (planar only).
    support.Columns(s.R, c - s.R * com_O, c, support_twist, &support_D);
    for (int k = nf_contacts; k < nf; ++k) {
      Jc.col(k) = support_D.col(k - nf_contacts);
      if (tracked) Jv.col(k) = Jc.col(k);
    }
  }
  for (int k = 0; k < nf_contacts; ++k) {
    const Contact& ct = contacts[static_cast<size_t>(force_point[static_cast<size_t>(k)])];
    const Point& pt = ct.points[static_cast<size_t>(force_point_sub[static_cast<size_t>(k)])];
    const int e = force_dir[static_cast<size_t>(k)];
    if (!HasRows(pt)) {
      Jc.col(k).setZero();
      if (tracked) Jv.col(k).setZero();
      continue;
    }
    const Eigen::Vector3d d = e < 0 ? NormalOf(ct, pt) : EdgeOf(ct, pt, e);
    if (&pt != arm_of) {
      arm_of = &pt;
      arm = pt.p - c;
      if (planar) p_cross_arm = plane_normal.cross(arm);
    }
    SetGraspColumn(Jc, k, d, arm, p_cross_arm);
    if (tracked) {
      Jv.col(k) = Jc.col(k);
      if (e >= 0 && ct.known_normal >= 0 && !ct.pusher) {
        const double along = pt.n.dot(ct.normal);
        if (along >= kGrazingFactor) {  // else the step is refused (PlaceContacts)
          const Eigen::Vector3d dv = d - (d.dot(ct.normal) / along) * pt.n;
          SetGraspColumn(Jv, k, dv, arm, p_cross_arm);
        }
      }
    }
  }
  if (planar) {
    // Written out (Eigen's product sums over the 3 coordinates from zero in
    // order: the same bits, without its kernel's packing).
    s.K.resize(3, nf);
    for (int j = 0; j < nf; ++j) {
      for (int i = 0; i < 3; ++i) {
        double acc = 0.0;
        for (int k = 0; k < 3; ++k) acc += s.Minv(i, k) * Jc(k, j);
        s.K(i, j) = acc;
      }
    }
  } else if (nd == 6) {
    // Six coordinates on fixed sizes, coefficient by coefficient: Eigen's
    // general product packs its operands for blocks far larger than 6 x nf.
    const Eigen::Matrix<double, 6, 6> Minv = s.Minv;
    s.K.resize(6, nf);
    s.K.noalias() = Minv.lazyProduct(Jc);
  } else {
    s.K.noalias() = s.Minv * Jc;
  }
}

// Phase 5. The force block and the rows of the force unknowns (normals and
// friction edges). Nondimensional LCP: force unknowns scale with Fs,
// velocity unknowns with Vs = Fs dt / m; velocity rows are divided by Vs,
// force rows by Fs. A tracked point without rows this step keeps its
// unknowns at zero (a unit diagonal and b = 1), so the LCP keeps its size.
void ContactModel::Impl::AssembleContactRows(StepScratch& s) {
  const Eigen::MatrixXd& Jrows = tracked ? s.Jv : s.Jc;
  StepMatrix& A = s.A;
  Eigen::VectorXd& b = s.b;
  A.Reset(n, nf, mass, Jrows, s.K);
  b.setZero(n);
  const SmallVector& vfree = s.vfree;
  if (planar) {
    const double* J = Jrows.data();
    for (int k = 0; k < nf; ++k)
      b[k] = J[3 * k] * vfree[0] + J[3 * k + 1] * vfree[1] + J[3 * k + 2] * vfree[2];
  } else {
    b.head(nf).noalias() = Jrows.transpose() * vfree;
  }
  const double inv_dt = 1.0 / dt, inv_Vs = 1.0 / Vs;
  for (int k = 0; k < ContactForceUnknowns(); ++k) {
    const Contact& ct = contacts[static_cast<size_t>(force_point[static_cast<size_t>(k)])];
    const Point& pt = ct.points[static_cast<size_t>(force_point_sub[static_cast<size_t>(k)])];
    const int e = force_dir[static_cast<size_t>(k)];
    if (!HasRows(pt)) {
      A.Set(k, k, 1);
      b[k] = 1;
      continue;
    }
    const Eigen::Vector3d d = e < 0 ? NormalOf(ct, pt) : EdgeOf(ct, pt, e);
    // The pad's own velocity along its closing direction (fixed: d·n = 1 or 0).
    const double pad_along = tracked ? d.dot(ct.normal) : (e < 0 ? 1.0 : 0.0);
    double bk = b[k] - d.dot(pt.body_velocity);
    if (e < 0) bk += pt.gap * inv_dt;
    if (ct.y_plus >= 0 && pad_along != 0) {
      A.Set(k, ct.y_plus, -pad_along);
      A.Set(k, ct.y_minus, pad_along);
    }
    if (e >= 0) A.Set(k, pt.xi, 1);
    // An elastic pad: the point sinks in by its force over its stiffness,
    // w = v_n + gap/dt + λ/(k dt), nondimensional m/(k dt²) on the diagonal.
    if (e < 0 && ct.spec.stiffness > 0) A.AddToForceDiagonal(k, mass * PadCompliance(ct));
    b[k] = bk * inv_Vs;
  }
}

// Phase 6. The friction cone's rows (ξ): μ λ - Σβ ≥ 0 ⊥ ξ ≥ 0; a point
// finger's λ is its known normal force (in b).
void ContactModel::Impl::AssembleConeRows(StepScratch& s) {
  for (const Contact& ct : contacts) {
    if (!ct.active) continue;
    for (const Point& pt : ct.points) {
      if (pt.xi < 0) continue;
      if (!HasRows(pt)) {
        s.A.Set(pt.xi, pt.xi, 1);
        s.b[pt.xi] = 1;
        continue;
      }
      if (pt.lambda >= 0) s.A.Set(pt.xi, pt.lambda, ct.spec.mu);
      for (int e = 0; e < edges_per_point; ++e) s.A.Set(pt.xi, pt.beta0 + e, -1);
      s.b[pt.xi] = ct.known_normal > 0 ? ct.spec.mu * ct.known_normal / Fs : 0.0;
    }
  }
}

// Phase 7. The force-controlled pads' rows (y±): the pad's points' normal
// forces sum to the grip force, paired with its free velocity.
void ContactModel::Impl::AssemblePadRows(StepScratch& s) {
  for (const Contact& ct : contacts) {
    if (!ct.active || ct.y_plus < 0 || ct.jaw_follower) continue;
    if (ct.jaw) {
      AssembleJawRows(s);
      continue;
    }
    if (tracked && !ct.any_active) {
      // The pad has passed the object's edge: it presses on nothing.
      s.A.Set(ct.y_plus, ct.y_plus, 1);
      s.A.Set(ct.y_minus, ct.y_minus, 1);
      s.b[ct.y_plus] = 1;
      s.b[ct.y_minus] = 1;
      continue;
    }
    for (const Point& pt : ct.points) {
      if (!HasRows(pt)) continue;
      s.A.Set(ct.y_plus, pt.lambda, 1);
      s.A.Set(ct.y_minus, pt.lambda, -1);
    }
    s.b[ct.y_plus] = -scene.grip_force / Fs;
    s.b[ct.y_minus] = scene.grip_force / Fs;
  }
}

// A parallel jaw (gripper.coupling): two opposed fingers on one mechanism
// that closes symmetrically about a centre fixed in the hand. Its one
// coordinate is the closing travel s: both pads move along their own
// closing directions c₁ = -c₂ at ṡ = y = y⁺ - y⁻ (the second finger's
// normal rows use the first's y±, SetupUnknowns), so the centre between
// them stays put. The motor drives s with each finger's grip force; by
// virtual work, λ₁ ṡ + λ₂ ṡ = 2 g ṡ, the jaw's row is
//   Σ₁ λ + Σ₂ λ - 2 g = 0,  y free (the y± pair, as a pad's),
// and nothing constrains λ₁ - λ₂: that is the force the jaw takes along
// its axis. Where both fingers press (w = c·(v_obj) - y + gap/dt = 0 on
// each, c₁ = -c₂) the object's velocity along the axis is zero: the jaw
// holds its position there; where no net axial force acts, λ₁ = λ₂ = g, the
// independent pads' answer.
void ContactModel::Impl::AssembleJawRows(StepScratch& s) {
  const Contact& lead = contacts.front();
  bool pressing = false;
  for (const Contact& ct : contacts) pressing = pressing || (ct.jaw && (!tracked || ct.any_active));
  if (!pressing) {
    // Both pads have passed the object's edges: the jaw presses on nothing.
    s.A.Set(lead.y_plus, lead.y_plus, 1);
    s.A.Set(lead.y_minus, lead.y_minus, 1);
    s.b[lead.y_plus] = 1;
    s.b[lead.y_minus] = 1;
    return;
  }
  for (const Contact& ct : contacts) {
    if (!ct.jaw) continue;
    for (const Point& pt : ct.points) {
      if (!HasRows(pt)) continue;
      s.A.Set(lead.y_plus, pt.lambda, 1);
      s.A.Set(lead.y_minus, pt.lambda, -1);
    }
  }
  s.b[lead.y_plus] = -2 * scene.grip_force / Fs;
  s.b[lead.y_minus] = 2 * scene.grip_force / Fs;
}

// Phase 8. The support's rows (SupportStage): per friction direction k,
// ξ + D_kᵀ ν⁺ >= 0 ⊥ β_k >= 0 (b[k] holds D_kᵀ ν_free from the force block's
// phase); μN - Σ_k β_k >= 0 ⊥ ξ >= 0.
void ContactModel::Impl::AssembleSupportRows(StepScratch& s) {
  if (support_xi < 0) return;
  const double inv_Vs = 1.0 / Vs;
  for (int k = support_beta0; k < nf; ++k) {
    s.A.Set(k, support_xi, 1);
    s.b[k] *= inv_Vs;
  }
  for (int k = support_beta0; k < nf; ++k) s.A.Set(support_xi, k, -1);
  s.b[support_xi] = support.limit() / Fs;
}

// The support's complementarity and cone residuals (CheckResiduals).
void ContactModel::Impl::SupportResiduals(StepScratch& s) {
  if (support_xi < 0) return;
  Residuals& res = s.res;
  const double inv_Vs = 1.0 / Vs, inv_Fs = 1.0 / Fs;
  const double xi = Unknown(s, support_xi);
  double bsum = 0;
  for (int k = support_beta0; k < nf; ++k) {
    const double be = Unknown(s, k);
    bsum += be;
    double along = 0;  // D_kᵀ ν⁺
    for (int i = 0; i < 3; ++i) along += s.Jc(i, k) * s.vr_new[i];
    res.complementarity =
        std::max(res.complementarity, std::abs(std::min(be * inv_Fs, (xi + along) * inv_Vs)));
  }
  const double slack = support.limit() - bsum;
  res.complementarity =
      std::max(res.complementarity, std::abs(std::min(xi * inv_Vs, slack * inv_Fs)));
  res.cone = std::max(res.cone, -slack * inv_Fs);
}

// An unknown in physical units (force unknowns N, velocity unknowns m/s);
// 0 for an index of none.
double ContactModel::Impl::Unknown(const StepScratch& s, int i) const {
  return i >= 0 ? s.solution.z[i] * (i < nf ? Fs : Vs) : 0.0;
}

Eigen::Vector3d ContactModel::Impl::ObjectVelocity(const StepScratch& s,
                                                   const Eigen::Vector3d& p) const {
  return s.v_new + s.w_new.cross(p - c);
}

// Velocity of the body a point presses on: the pusher's, or the pad's
// along its closing direction (a tracked point pad follows the object).
Eigen::Vector3d ContactModel::Impl::BodyVelocity(const StepScratch& s, const Contact& ct,
                                                 const Point& pt) const {
  if (ct.pusher) return pt.body_velocity;
  double vf = Unknown(s, ct.y_plus) - Unknown(s, ct.y_minus);
  if (tracked && ct.known_normal >= 0) {
    const double along = pt.n.dot(ct.normal);
    vf = along >= kGrazingFactor ? pt.n.dot(ObjectVelocity(s, pt.p)) / along : 0.0;
  }
  return vf * ct.normal;
}

// Phase 9. Solve (warm from the last basis), recover the forces and the new
// twist, then check the physical residuals; a warm-started answer that fails
// them is solved again cold. On failure the basis is dropped.
bool ContactModel::Impl::Solve(StepScratch& s, StepReport& rep) {
  LcpResult& sol = s.solution;
  s.A.Finish();
  if (lcp_observer) lcp_observer(s.A.Dense(), s.b);
  int next_covering = 0;
  for (int attempt = 0;; ++attempt) {
    // Attempt 0 may start warm; later attempts start cold, each from another
    // covering vector, since Lemke's path (and its accuracy on an
    // ill-conditioned step) depends on it.
    LcpOptions lcp_options;
    const bool warm = attempt == 0 && !basis.empty();
    lcp_options.first_covering = next_covering;
    SolveLcp(s.A, s.b, warm ? &basis : nullptr, lcp_options, sol);
    if (!sol.warm_start_used) ++next_covering;
    rep.pivots += sol.pivots;
    rep.warm_start_used = sol.warm_start_used;
    if (!sol.ok) {
      DumpLcp(s.A.Dense(), s.b);
      rep.ok = false;
      rep.error = "LCP (" + std::to_string(n) + " unknowns): " + sol.reason;
      rep.failure = StepFailure::kSolver;
      basis.clear();
      return false;
    }
    RecoverMotion(s);
    const double worst = CheckResiduals(s);
    if (std::isfinite(worst) && worst <= kAcceptedResidual) break;
    if (attempt < kAccuracyAttempts) continue;
    DumpLcp(s.A.Dense(), s.b);
    char buf[128];
    std::snprintf(buf, sizeof buf,
                  "LCP (%d unknowns): inaccurate solution (relative residual %.3g)", n, worst);
    rep.ok = false;
    rep.error = buf;
    rep.failure = StepFailure::kInaccurate;
    basis.clear();
    return false;
  }
  basis = sol.basis;
  rep.residuals = s.res;
  return true;
}

// Forces (N) and the new twist from the solver's answer.
void ContactModel::Impl::RecoverMotion(StepScratch& s) {
  LcpResult& sol = s.solution;
  // A pad's velocity is y+ - y-; their common part is a free direction.
  for (const Contact& ct : contacts) {
    if (ct.y_plus < 0) continue;
    const double common = std::min(sol.z[ct.y_plus], sol.z[ct.y_minus]);
    sol.z[ct.y_plus] -= common;
    sol.z[ct.y_minus] -= common;
  }
  Eigen::VectorXd& f = s.forces;
  f = Fs * sol.z.head(nf);
  SmallVector Kf;  // at most 6: on the stack (a product in an expression is a heap temporary)
  SmallVector& Jf = s.Jf;
  if (planar) {
    // Written out: Eigen's general product on a 3 x nf block dispatches
    // to its blocked kernel.
    Kf.setZero(3);
    Jf.setZero(3);
    for (int j = 0; j < nf; ++j) {
      const double fj = f[j];
      if (fj == 0) continue;
      for (int i = 0; i < 3; ++i) {
        Kf[i] += s.K(i, j) * fj;
        Jf[i] += s.Jc(i, j) * fj;
      }
    }
  } else {
    Kf.noalias() = s.K * f;
    Jf.noalias() = s.Jc * f;
  }
  s.vr_new = s.vfree + dt * Kf;
  const Eigen::Matrix<double, 6, 1> tw_new = P * s.vr_new;
  s.v_new = tw_new.head<3>();
  s.w_new = tw_new.tail<3>();
}

// Residuals, recomputed from the physical quantities (not the solver's w);
// returns the worst. Keeps each point's relative velocity for the states.
double ContactModel::Impl::CheckResiduals(StepScratch& s) {
  Residuals& res = s.res;
  res = Residuals{};
  {
    SmallVector newton = s.Mr * (s.vr_new - s.vr) / dt - (s.Jf + s.Q);
    if (s.D.size() > 0) newton += s.D * s.vr_new - s.Db;
    for (int i = 0; i < nd; ++i) {
      const bool torque = planar ? i == 2 : i >= 3;
      res.force_balance =
          std::max(res.force_balance, std::abs(newton[i]) / (Fs * (torque ? L : 1.0)));
    }
  }
  const double inv_dt = 1.0 / dt, inv_Vs = 1.0 / Vs, inv_Fs = 1.0 / Fs;
  auto comp = [&](double z_nd, double w_nd) {
    res.complementarity = std::max(res.complementarity, std::abs(std::min(z_nd, w_nd)));
  };
  double jaw_sum = 0;  // a parallel jaw's normal forces, both fingers
  bool jaw_pressing = false;
  for (Contact& ct : contacts) {
    if (!ct.active) continue;
    double sum = 0;
    for (Point& pt : ct.points) {
      if (!HasRows(pt)) continue;  // a redundant point's unknowns are zero by construction
      const Eigen::Vector3d urel = ObjectVelocity(s, pt.p) - BodyVelocity(s, ct, pt);
      pt.urel = urel;
      pt.urel_step = steps_taken;
      const double lam = pt.lambda >= 0 ? Unknown(s, pt.lambda) : ct.known_normal;
      sum += lam;
      if (pt.lambda >= 0) {
        const double sink = ct.spec.stiffness > 0 ? lam * PadCompliance(ct) * dt : 0.0;
        comp(lam * inv_Fs, (NormalOf(ct, pt).dot(urel) + pt.gap * inv_dt + sink) * inv_Vs);
      }
      if (pt.beta0 >= 0) {
        const double xi = Unknown(s, pt.xi);
        double bsum = 0;
        for (int e = 0; e < edges_per_point; ++e) {
          const double be = Unknown(s, pt.beta0 + e);
          bsum += be;
          comp(be * inv_Fs, (xi + EdgeOf(ct, pt, e).dot(urel)) * inv_Vs);
        }
        const double slack = ct.spec.mu * lam - bsum;
        comp(xi * inv_Vs, slack * inv_Fs);
        res.cone = std::max(res.cone, -slack * inv_Fs);
      }
    }
    if (ct.jaw) {
      // The jaw's one row (AssembleJawRows), checked once both fingers are summed.
      jaw_sum += sum;
      jaw_pressing = jaw_pressing || !tracked || ct.any_active;
      if (!ct.jaw_follower || !jaw_pressing) continue;
      const double err = (jaw_sum - 2 * scene.grip_force) * inv_Fs;
      res.force_balance = std::max(res.force_balance, std::abs(err));
      comp(Unknown(s, ct.y_plus) * inv_Vs, err);
      comp(Unknown(s, ct.y_minus) * inv_Vs, -err);
    } else if (ct.y_plus >= 0 && (!tracked || ct.any_active)) {
      const double err = (sum - scene.grip_force) * inv_Fs;
      res.force_balance = std::max(res.force_balance, std::abs(err));
      comp(Unknown(s, ct.y_plus) * inv_Vs, err);
      comp(Unknown(s, ct.y_minus) * inv_Vs, -err);
    }
  }
  SupportResiduals(s);
  return std::max({res.force_balance, res.complementarity, res.cone});
}

// Phase 10. Bad values: a step whose forces, twist or next pose is not
// finite is refused (typed kNonFinite, naming the quantity) before anything
// of the state changes. The residual checks refuse a NaN residual; this
// catches what they do not read (forces of points without rows, the pose).
bool ContactModel::Impl::CheckValues(StepScratch& s, StepReport& rep) {
  const char* bad = nullptr;
  if (!AllFiniteEntries(s.forces)) {
    bad = "contact forces";
  } else if (!s.v_new.allFinite() || !s.w_new.allFinite()) {
    bad = "object twist";
  } else if (!(c + dt * s.v_new).allFinite()) {
    bad = "object position";
  }
  if (bad == nullptr) return true;
  return Refuse(rep, std::string("non-finite ") + bad + " after the solve");
}

bool ContactModel::Impl::Refuse(StepReport& rep, const std::string& why) {
  rep.ok = false;
  rep.failure = StepFailure::kNonFinite;
  rep.error = why;
  basis.clear();
  return false;
}

// Phase 11. Contact states (on the object, gripper frame) and modes; the
// pusher's force.
// One sliding point's friction f_t against its slip u_t (both tangent):
// its part across the slip and its angle from the slip's opposite
// (SlipSteering). A friction below 1e-9 of the force scale (a frictionless
// point) has no direction to judge.
void ContactModel::Impl::AddSteering(const Eigen::Vector3d& ft, const Eigen::Vector3d& ut,
                                     SlipSteering& steering) const {
  const double f = ft.norm();
  if (!(f > 1e-9 * Fs)) return;
  const Eigen::Vector3d u = ut.normalized();
  const double across = ft.cross(u).norm();
  steering.sliding_friction += f;
  steering.across += across;
  steering.max_rad = std::max(steering.max_rad, std::atan2(across, -ft.dot(u)));
}

void ContactModel::Impl::ReportContacts(StepScratch& s, SlipSteering& steering) {
  steering = SlipSteering{};
  pusher_force.setZero();
  const Eigen::Vector3d origin = c - s.R * com_O;  // ObjectOrigin(), q unchanged since R
  for (size_t ci = 0; ci < contacts.size(); ++ci) {
    Contact& ct = contacts[ci];
    ContactState st;
    Eigen::Vector3d force = Eigen::Vector3d::Zero();
    Eigen::Vector3d weighted = Eigen::Vector3d::Zero(), plain = Eigen::Vector3d::Zero();
    int n_plain = 0;
    if (ct.active) {
      bool sliding = false;
      for (Point& pt : ct.points) {
        if (!Live(pt)) continue;
        const double lam = pt.lambda >= 0 ? Unknown(s, pt.lambda) : ct.known_normal;
        const Eigen::Vector3d& nrm = NormalOf(ct, pt);
        Eigen::Vector3d ft = Eigen::Vector3d::Zero();
        if (pt.beta0 >= 0) {
          for (int e = 0; e < edges_per_point; ++e)
            ft += Unknown(s, pt.beta0 + e) * EdgeOf(ct, pt, e);
        }
        const Eigen::Vector3d urel =
            pt.urel_step == steps_taken
                ? pt.urel
                : Eigen::Vector3d(ObjectVelocity(s, pt.p) - BodyVelocity(s, ct, pt));
        // The slip damper's force is friction too (ApplySlipDampers).
        if (s.D.size() > 0 && pt.damp_c > 0 && pt.beta0 >= 0 && !pt.edges.empty()) {
          const Eigen::Vector3d d = SlipDamperDirection(ct, pt);
          ft -= pt.damp_c * d.dot(urel) * d;
        }
        const Eigen::Vector3d fp = lam * nrm + ft;
        force += fp;
        st.normal_force += lam;
        st.tangential_force += ft;
        st.torque += (pt.p - ct.position).cross(fp);
        const Eigen::Vector3d ut = urel - nrm.dot(urel) * nrm;
        if (lam > 1e-9 * Fs && ut.squaredNorm() > slip_floor * slip_floor) {
          sliding = true;
          AddSteering(ft, ut, steering);
          if (tracked && !planar && pt.beta0 >= 0)
            pt.slip = aligned && ft.squaredNorm() > 0 ? Eigen::Vector3d(-ft.normalized())
                                                      : Eigen::Vector3d(ut.normalized());
        }
        const bool close = pt.gap <= (tracked ? gap_tolerance : 0.0) || lam > 1e-9 * Fs;
        if (close) {
          ++st.touching_points;
          weighted += lam * pt.p;
          plain += pt.p;
          ++n_plain;
        }
      }
      st.mode = st.normal_force <= 1e-9 * Fs
                    ? ContactMode::kSeparate
                    : (sliding ? ContactMode::kSlide : ContactMode::kStick);
    }
    st.touching = st.touching_points > 0;
    // Where it touches, in the object frame: the force-weighted centre of its
    // touching points (their plain centre without force; where it is, if none).
    Eigen::Vector3d at_G = ct.position;
    if (st.normal_force > 1e-9 * Fs) {
      at_G = weighted / st.normal_force;
    } else if (n_plain > 0) {
      at_G = plain / n_plain;
    }
    st.point = s.R.transpose() * (at_G - origin);
    ReportAlongSceneNormal(ct, tracked, force, &st);
    if (ct.pusher) pusher_force = force;
    states[ci] = st;
  }
}

// Phase 12. Integrate (semi-implicit Euler on the new twist). Pressing
// fingers' pads follow the object along their normals; the pusher tracks its
// gaps (fixed geometry; tracked geometry measures them every step).
void ContactModel::Impl::Integrate(StepScratch& s) {
  for (Contact& ct : contacts) {
    if (ct.pusher) {
      if (!tracked) {
        for (Point& pt : ct.points)
          pt.gap += dt * ct.normal.dot(ObjectVelocity(s, pt.p) - pt.body_velocity);
      }
    } else if (tracked && ct.known_normal >= 0) {
      // A point pad is re-seated on the surface by TrackedGeometry().
    } else if (ct.active) {
      const double vf = ct.y_plus >= 0 ? Unknown(s, ct.y_plus) - Unknown(s, ct.y_minus)
                                       : ct.normal.dot(ObjectVelocity(s, ct.points[0].p));
      ct.pad += dt * vf;
      // An elastic pad in fixed geometry keeps its points' penetration (the
      // spring's extension); without it the compliance row acted as a damper
      // (λ = -k dt v_n), which resists no tilt, and a push along a line
      // pad's axis turned the object.
      if (!tracked && ct.spec.stiffness > 0) {
        for (Point& pt : ct.points) pt.gap += dt * (ct.normal.dot(ObjectVelocity(s, pt.p)) - vf);
      }
    }
  }
  if (support_xi >= 0) support_twist = Eigen::Vector3d(s.vr_new[0], s.vr_new[1], s.vr_new[2]);
  v = s.v_new;
  w = s.w_new;
  c += dt * s.v_new;
  const double angle = s.w_new.norm() * dt;
  if (angle > 0)
    q = (Eigen::Quaterniond(Eigen::AngleAxisd(angle, s.w_new.normalized())) * q).normalized();
  t += dt;
}

}  // namespace arena::mechanics

namespace arena::mechanics {

bool ContactModelTester::BeginStep(StepReport& rep) { return model_.impl_->BeginStep(rep); }
bool ContactModelTester::Run(StepPhase phase, StepReport& rep) {
  return model_.impl_->RunPhase(phase, rep);
}
int ContactModelTester::reduced_coordinates() const { return model_.impl_->nd; }
int ContactModelTester::force_unknowns() const { return model_.impl_->nf; }
int ContactModelTester::lcp_size() const { return model_.impl_->n; }
Eigen::MatrixXd ContactModelTester::mass_matrix() const { return model_.impl_->scratch.Mr; }
Eigen::VectorXd ContactModelTester::known_wrench() const { return model_.impl_->scratch.Q; }
Eigen::VectorXd ContactModelTester::free_twist() const { return model_.impl_->scratch.vfree; }
Eigen::MatrixXd ContactModelTester::grasp_map() const { return model_.impl_->scratch.Jc; }
Eigen::MatrixXd ContactModelTester::lcp_matrix() const { return model_.impl_->scratch.A.Dense(); }
Eigen::VectorXd ContactModelTester::lcp_vector() const { return model_.impl_->scratch.b; }
Eigen::VectorXd ContactModelTester::forces() const { return model_.impl_->scratch.forces; }
Eigen::Matrix<double, 6, 1> ContactModelTester::new_twist() const {
  Eigen::Matrix<double, 6, 1> tw;
  tw << model_.impl_->scratch.v_new, model_.impl_->scratch.w_new;
  return tw;
}
void ContactModelTester::SetTwist(const Eigen::Vector3d& v, const Eigen::Vector3d& w) {
  model_.impl_->v = v;
  model_.impl_->w = w;
}

}  // namespace arena::mechanics
