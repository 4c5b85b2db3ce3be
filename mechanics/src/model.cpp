// The contact model: geometry helpers, planarity, and one time step as a
// nondimensional mixed LCP (model.hpp explains the formulation).
#include "arena/mechanics/model.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numbers>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "arena/mechanics/lcp.hpp"

namespace arena::mechanics {

Eigen::Vector3d FirstTangent(const Eigen::Vector3d& normal) {
  const Eigen::Vector3d n = normal.normalized();
  for (const Eigen::Vector3d& axis :
       {Eigen::Vector3d::UnitZ().eval(), Eigen::Vector3d::UnitY().eval(),
        Eigen::Vector3d::UnitX().eval()}) {
    if (std::abs(n.dot(axis)) < 0.9) return (axis - n.dot(axis) * n).normalized();
  }
  // Unreachable for a unit normal: some axis has |n·axis| <= 1/sqrt(3).
  return (Eigen::Vector3d::UnitX() - n.x() * n).normalized();
}

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

Eigen::Matrix3d RotationFromRpy(const Eigen::Vector3d& rpy) {
  return (Eigen::AngleAxisd(rpy.z(), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(rpy.y(), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(rpy.x(), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Matrix3d ObjectInertia(const ObjectSpec& object) {
  if (object.inertia) return *object.inertia;
  const double m = object.mass;
  Eigen::Matrix3d I = Eigen::Matrix3d::Zero();
  if (object.shape == ObjectShape::kBox) {
    const Eigen::Vector3d s2 = object.size.cwiseProduct(object.size);
    I.diagonal() << m * (s2.y() + s2.z()) / 12.0, m * (s2.x() + s2.z()) / 12.0,
        m * (s2.x() + s2.y()) / 12.0;
  } else {
    const double r2 = object.radius * object.radius;
    const double h2 = object.height * object.height;
    I.diagonal() << m * (3 * r2 + h2) / 12.0, m * (3 * r2 + h2) / 12.0, m * r2 / 2.0;
  }
  return I;
}

namespace {

constexpr double kPlaneTolerance = 1e-9;
// Reduced-coordinate quantities (3 or 6 rows) without heap allocation.
using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 6, 6>;
using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6, 1>;
// A step whose physical residuals (relative to the force scale) exceed this
// is a solver failure, not a result.
constexpr double kAcceptedResidual = 1e-8;
// Solves of one step before an inaccurate answer is reported as a failure.
constexpr int kAccuracyAttempts = 4;

double LengthScale(const ObjectSpec& object) {
  double L = object.shape == ObjectShape::kBox ? object.size.maxCoeff()
                                               : std::max(2 * object.radius, object.height);
  return L > 0 && std::isfinite(L) ? L : 1.0;
}

// Checks one candidate plane normal; returns the first failed condition
// (empty when the scene is planar about p) and counts passed conditions.
std::string CheckPlane(const Scene& scene, const Eigen::Vector3d& p, int& passed) {
  const double L = LengthScale(scene.object);
  const Eigen::Vector3d c = scene.object.pose.position;
  const Eigen::Matrix3d R = RotationFromRpy(scene.object.pose.rpy);
  const Eigen::Matrix3d I = R * ObjectInertia(scene.object) * R.transpose();
  passed = 0;
  const double gn = scene.gravity.norm();
  if (gn > 0 && std::abs(scene.gravity.dot(p)) > kPlaneTolerance * gn)
    return "gravity leaves the plane";
  ++passed;
  const Eigen::Vector3d Ip = I * p;
  if ((Ip - p.dot(Ip) * p).norm() > kPlaneTolerance * I.norm()) {
    return "the plane normal is not a principal axis of the object's inertia";
  }
  ++passed;
  auto check_contact = [&](const ContactSpec& s, const std::string& name) -> std::string {
    const Eigen::Vector3d n = s.normal.normalized();
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
    const double v = s.motion.velocity.norm();
    if (std::abs(s.motion.velocity.dot(p)) > kPlaneTolerance * v)
      return "pusher velocity leaves the plane";
    const Eigen::Vector3d& w = s.motion.angular_velocity;
    if (w.cross(p).norm() > kPlaneTolerance * w.norm()) return "pusher turns out of the plane";
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
  for (const Eigen::Vector3d& p : candidates) {
    int passed = 0;
    const std::string e = CheckPlane(scene, p.normalized(), passed);
    if (e.empty()) {
      out.planar = true;
      out.normal = p.normalized();
      out.reason.clear();
      return out;
    }
    if (passed > best) {
      best = passed;
      out.reason = e;
    }
  }
  return out;
}

// ---------------------------------------------------------------------------

namespace {

struct Point {
  Eigen::Vector3d offset0 = Eigen::Vector3d::Zero();  // from the contact position at t = 0
  int lambda = -1;  // LCP index of λ_n; -1 for a point finger (λ_n = grip force)
  int beta0 = -1;   // first friction index (edges of them); -1 without friction
  int xi = -1;      // LCP index of ξ
  double gap = 0;   // pusher only (m)
  // This step's geometry.
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Vector3d body_velocity = Eigen::Vector3d::Zero();  // of the contacting body (pusher)
};

struct Contact {
  ContactSpec spec;
  bool pusher = false;
  bool active = false;       // has rows (a finger with zero grip force has none)
  double known_normal = -1;  // point finger: its normal force (N), else -1
  int y_plus = -1, y_minus = -1;
  double pad = 0;  // finger: how far its pad has followed the object along n (m)
  std::vector<Point> points;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitX();
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> edges;  // friction directions this step
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
  int nd = 6;
  int edges_per_point = 0;

  double mass = 0, L = 1, Fs = 1, Vs = 1, dt = 0;
  Eigen::Matrix3d inertia_body = Eigen::Matrix3d::Identity();
  std::vector<Contact> contacts;
  int nf = 0;                        // force unknowns (λ, β) come first in the LCP
  int n = 0;                         // LCP size
  std::vector<int> force_point;      // per force unknown: contact index
  std::vector<int> force_point_sub;  // per force unknown: point index
  std::vector<int> force_dir;        // per force unknown: -1 normal, else edge index

  // State.
  double t = 0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  Eigen::Vector3d w = Eigen::Vector3d::Zero();
  std::vector<ContactState> states;
  Eigen::Vector3d pusher_force = Eigen::Vector3d::Zero();
  std::vector<char> basis;

  // Work space.
  Eigen::MatrixXd Jc, K, A;
  Eigen::VectorXd b;

  void Setup();
  void Geometry();
  StepReport Step();
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
double ContactModel::velocity_scale() const { return impl_->Vs; }
Eigen::Vector3d ContactModel::pusher_position() const {
  if (!impl_->scene.pusher) return Eigen::Vector3d::Zero();
  return impl_->scene.pusher->position + impl_->scene.pusher->motion.velocity * impl_->t;
}
// Geometry() places the pusher at position + velocity t: rebasing the
// position keeps it where it is when the velocity changes.
bool ContactModel::SetPusherMotion(const PusherMotion& motion) {
  auto& pusher = impl_->scene.pusher;
  if (!pusher || motion.angular_velocity != pusher->motion.angular_velocity) return false;
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
  c = scene.object.pose.position;
  q = Eigen::Quaterniond(RotationFromRpy(scene.object.pose.rpy));

  if (opt.reduce != Reduce::kFull) {
    const PlaneCheck plane = FindPlane(scene);
    if (plane.planar) {
      planar = true;
      plane_normal = plane.normal;
    } else if (opt.reduce == Reduce::kPlanar) {
      status = SimulationStatus::kInvalidScene;
      error = "model.reduce: planar, but the scene is not planar (" + plane.reason + ")";
      return;
    }
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
    edges_per_point = 2;
  } else {
    nd = 6;
    P = Eigen::Matrix<double, 6, Eigen::Dynamic>::Identity(6, 6);
    edges_per_point = opt.facets;
  }

  // Force scale: the largest of the forces the scene names (grip, weight,
  // the impulse that brings the object to the pusher's speed in one step).
  const double g = scene.gravity.norm();
  Fs = std::max(scene.grip_force, mass * g);
  if (scene.pusher) {
    Fs = std::max({Fs, mass * scene.pusher->motion.velocity.norm() / dt,
                   mass * scene.pusher->motion.angular_velocity.norm() * L / dt});
  }
  if (!(Fs > 0)) Fs = mass * L / (dt * dt);
  Vs = Fs * dt / mass;

  // Unknowns: forces first (λ, β per point), then velocities (ξ, pad y±).
  std::vector<ContactSpec> specs(scene.fingers.begin(), scene.fingers.end());
  if (scene.pusher) specs.push_back(*scene.pusher);
  for (size_t i = 0; i < specs.size(); ++i) {
    Contact ct;
    ct.spec = specs[i];
    ct.spec.normal.normalize();
    if (ct.spec.type == ContactType::kLine) ct.spec.axis.normalize();
    ct.pusher = scene.pusher && i + 1 == specs.size();
    ct.active = ct.pusher || scene.grip_force > 0;
    for (const Eigen::Vector3d& o : ConstituentOffsets(ct.spec, opt.points)) {
      Point pt;
      pt.offset0 = o;
      ct.points.push_back(pt);
    }
    if (!ct.pusher && ct.points.size() == 1) ct.known_normal = scene.grip_force;
    contacts.push_back(std::move(ct));
  }
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
  n = nf;
  for (Contact& ct : contacts) {
    if (!ct.active) continue;
    for (Point& pt : ct.points) {
      if (pt.beta0 >= 0) pt.xi = n++;
    }
    if (!ct.pusher && ct.known_normal < 0) {
      ct.y_plus = n++;
      ct.y_minus = n++;
    }
  }
  info.dof = nd;
  info.facets = opt.facets;
  info.points = opt.points;
  info.dt = dt;
  info.unknowns = n;
  states.assign(contacts.size(), ContactState{});
  basis.clear();
  Geometry();
}

// Contact geometry at time t: fingers are fixed in the gripper frame but for
// their pads' travel along the normal; the pusher translates with its
// velocity and turns about its contact point.
void ContactModel::Impl::Geometry() {
  for (Contact& ct : contacts) {
    Eigen::Matrix3d Rp = Eigen::Matrix3d::Identity();
    Eigen::Vector3d vp = Eigen::Vector3d::Zero(), wp = Eigen::Vector3d::Zero();
    ct.position = ct.spec.position + ct.pad * ct.spec.normal;
    if (ct.pusher) {
      vp = scene.pusher->motion.velocity;
      wp = scene.pusher->motion.angular_velocity;
      ct.position = ct.spec.position + vp * t;
      const double a = wp.norm() * t;
      if (a > 0) Rp = Eigen::AngleAxisd(a, wp.normalized()).toRotationMatrix();
    }
    const Eigen::Vector3d n = Rp * ct.spec.normal;
    const bool recompute = ct.edges.empty() || (ct.pusher && wp.norm() > 0);
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
      pt.body_velocity = vp + wp.cross(o);
    }
  }
}

StepReport ContactModel::Impl::Step() {
  StepReport rep;
  if (status != SimulationStatus::kOk) {
    rep.ok = false;
    rep.error = error;
    return rep;
  }
  Geometry();
  const Eigen::Matrix3d R = q.toRotationMatrix();
  const Eigen::Matrix3d Iw = R * inertia_body * R.transpose();

  // Reduced mass matrix and its inverse.
  Eigen::Matrix<double, 6, 6> M6 = Eigen::Matrix<double, 6, 6>::Zero();
  M6.topLeftCorner<3, 3>() = mass * Eigen::Matrix3d::Identity();
  M6.bottomRightCorner<3, 3>() = Iw;
  const SmallMatrix Mr = P.transpose() * M6 * P;
  const SmallMatrix Minv = Mr.llt().solve(SmallMatrix::Identity(nd, nd));

  Eigen::Matrix<double, 6, 1> tw;
  tw << v, w;
  const SmallVector vr = P.transpose() * tw;

  // Known wrench: gravity and point fingers' normal forces. The gyroscopic
  // torque -ω × Iω is left out: it is second order in the slow turning rates
  // of pushing (the quasi-dynamic regime of the model), and its explicit
  // integration pumps energy into a spinning body.
  Eigen::Matrix<double, 6, 1> known = Eigen::Matrix<double, 6, 1>::Zero();
  known.head<3>() = mass * scene.gravity;
  for (const Contact& ct : contacts) {
    if (ct.known_normal > 0) {
      const Eigen::Vector3d f = ct.known_normal * ct.normal;
      known.head<3>() += f;
      known.tail<3>() += (ct.points[0].p - c).cross(f);
    }
  }
  const SmallVector Q = P.transpose() * known;
  const SmallVector vfree = vr + dt * Minv * Q;

  // Columns of the grasp map for every force unknown, in reduced coordinates.
  Jc.resize(nd, nf);
  for (int k = 0; k < nf; ++k) {
    const Contact& ct = contacts[static_cast<size_t>(force_point[static_cast<size_t>(k)])];
    const Point& pt = ct.points[static_cast<size_t>(force_point_sub[static_cast<size_t>(k)])];
    const int e = force_dir[static_cast<size_t>(k)];
    const Eigen::Vector3d d = e < 0 ? ct.normal : ct.edges[static_cast<size_t>(e)];
    Eigen::Matrix<double, 6, 1> col;
    col << d, (pt.p - c).cross(d);
    if (planar) {
      Jc.col(k) = Pt3 * col;  // fixed-size 3x6 projection
    } else {
      Jc.col(k) = col;
    }
  }
  K.noalias() = Minv * Jc;

  // Nondimensional LCP: force unknowns scale with Fs, velocity unknowns with
  // Vs = Fs dt / m; velocity rows are divided by Vs, force rows by Fs.
  A.setZero(n, n);
  b.setZero(n);
  A.topLeftCorner(nf, nf).noalias() = mass * Jc.transpose() * K;
  b.head(nf).noalias() = Jc.transpose() * vfree;
  for (int k = 0; k < nf; ++k) {
    const Contact& ct = contacts[static_cast<size_t>(force_point[static_cast<size_t>(k)])];
    const Point& pt = ct.points[static_cast<size_t>(force_point_sub[static_cast<size_t>(k)])];
    const int e = force_dir[static_cast<size_t>(k)];
    const Eigen::Vector3d d = e < 0 ? ct.normal : ct.edges[static_cast<size_t>(e)];
    double bk = b[k] - d.dot(pt.body_velocity);
    if (e < 0) {
      bk += pt.gap / dt;
      if (ct.y_plus >= 0) {
        A(k, ct.y_plus) = -1;
        A(k, ct.y_minus) = 1;
      }
    } else {
      A(k, pt.xi) = 1;
    }
    b[k] = bk / Vs;
  }
  for (const Contact& ct : contacts) {
    if (!ct.active) continue;
    for (const Point& pt : ct.points) {
      if (pt.xi < 0) continue;
      if (pt.lambda >= 0) A(pt.xi, pt.lambda) = ct.spec.mu;
      for (int e = 0; e < edges_per_point; ++e) A(pt.xi, pt.beta0 + e) = -1;
      b[pt.xi] = ct.known_normal > 0 ? ct.spec.mu * ct.known_normal / Fs : 0.0;
    }
    if (ct.y_plus >= 0) {
      for (const Point& pt : ct.points) {
        A(ct.y_plus, pt.lambda) = 1;
        A(ct.y_minus, pt.lambda) = -1;
      }
      b[ct.y_plus] = -scene.grip_force / Fs;
      b[ct.y_minus] = scene.grip_force / Fs;
    }
  }

  // Solve (warm from the last basis), then check the physical residuals; a
  // warm-started answer that fails them is solved again cold.
  LcpResult sol;
  Eigen::VectorXd f;
  SmallVector vr_new;
  Eigen::Vector3d v_new, w_new;
  Residuals res;
  auto object_velocity = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    return v_new + w_new.cross(p - c);
  };
  auto zv = [&](int i) { return i >= 0 ? sol.z[i] * (i < nf ? Fs : Vs) : 0.0; };
  if (lcp_observer) lcp_observer(A, b);
  int next_covering = 0;
  for (int attempt = 0;; ++attempt) {
    // Attempt 0 may start warm; later attempts start cold, each from another
    // covering vector, since Lemke's path (and its accuracy on an
    // ill-conditioned step) depends on it.
    LcpOptions lcp_options;
    const bool warm = attempt == 0 && !basis.empty();
    lcp_options.first_covering = next_covering;
    sol = SolveLcp(A, b, warm ? &basis : nullptr, lcp_options);
    if (!sol.warm_start_used) ++next_covering;
    rep.pivots += sol.pivots;
    rep.warm_start_used = sol.warm_start_used;
    if (!sol.ok) {
      DumpLcp(A, b);
      rep.ok = false;
      rep.error = "LCP (" + std::to_string(n) + " unknowns): " + sol.reason;
      basis.clear();
      return rep;
    }
    // A pad's velocity is y+ - y-; their common part is a free direction.
    for (const Contact& ct : contacts) {
      if (ct.y_plus < 0) continue;
      const double common = std::min(sol.z[ct.y_plus], sol.z[ct.y_minus]);
      sol.z[ct.y_plus] -= common;
      sol.z[ct.y_minus] -= common;
    }

    // Forces (N) and the new twist.
    f = Fs * sol.z.head(nf);
    vr_new = vfree + dt * (K * f);
    const Eigen::Matrix<double, 6, 1> tw_new = P * vr_new;
    v_new = tw_new.head<3>();
    w_new = tw_new.tail<3>();

    // Residuals, recomputed from the physical quantities (not the solver's w).
    res = Residuals{};
    {
      const SmallVector newton = Mr * (vr_new - vr) / dt - (Jc * f + Q);
      for (int i = 0; i < nd; ++i) {
        const bool torque = planar ? i == 2 : i >= 3;
        res.force_balance =
            std::max(res.force_balance, std::abs(newton[i]) / (Fs * (torque ? L : 1.0)));
      }
    }
    auto comp = [&](double z_nd, double w_nd) {
      res.complementarity = std::max(res.complementarity, std::abs(std::min(z_nd, w_nd)));
    };
    for (Contact& ct : contacts) {
      if (!ct.active) continue;
      const double vf = zv(ct.y_plus) - zv(ct.y_minus);
      double sum = 0;
      for (Point& pt : ct.points) {
        const Eigen::Vector3d urel =
            object_velocity(pt.p) -
            (ct.pusher ? pt.body_velocity : Eigen::Vector3d(vf * ct.normal));
        const double lam = pt.lambda >= 0 ? zv(pt.lambda) : ct.known_normal;
        sum += lam;
        if (pt.lambda >= 0) comp(lam / Fs, (ct.normal.dot(urel) + pt.gap / dt) / Vs);
        if (pt.beta0 >= 0) {
          const double xi = zv(pt.xi);
          double bsum = 0;
          for (int e = 0; e < edges_per_point; ++e) {
            const double be = zv(pt.beta0 + e);
            bsum += be;
            comp(be / Fs, (xi + ct.edges[static_cast<size_t>(e)].dot(urel)) / Vs);
          }
          const double slack = ct.spec.mu * lam - bsum;
          comp(xi / Vs, slack / Fs);
          res.cone = std::max(res.cone, -slack / Fs);
        }
      }
      if (ct.y_plus >= 0) {
        const double err = (sum - scene.grip_force) / Fs;
        res.force_balance = std::max(res.force_balance, std::abs(err));
        comp(zv(ct.y_plus) / Vs, err);
        comp(zv(ct.y_minus) / Vs, -err);
      }
    }
    const double worst = std::max({res.force_balance, res.complementarity, res.cone});
    if (std::isfinite(worst) && worst <= kAcceptedResidual) break;
    if (attempt < kAccuracyAttempts) continue;
    DumpLcp(A, b);
    char buf[128];
    std::snprintf(buf, sizeof buf,
                  "LCP (%d unknowns): inaccurate solution (relative residual %.3g)", n, worst);
    rep.ok = false;
    rep.error = buf;
    basis.clear();
    return rep;
  }
  basis = sol.basis;
  rep.residuals = res;

  // Contact states (on the object, gripper frame) and modes.
  pusher_force.setZero();
  for (size_t ci = 0; ci < contacts.size(); ++ci) {
    Contact& ct = contacts[ci];
    ContactState st;
    if (ct.active) {
      const double vf = zv(ct.y_plus) - zv(ct.y_minus);
      bool sliding = false;
      for (Point& pt : ct.points) {
        const double lam = pt.lambda >= 0 ? zv(pt.lambda) : ct.known_normal;
        Eigen::Vector3d ft = Eigen::Vector3d::Zero();
        if (pt.beta0 >= 0) {
          for (int e = 0; e < edges_per_point; ++e) {
            ft += zv(pt.beta0 + e) * ct.edges[static_cast<size_t>(e)];
          }
        }
        const Eigen::Vector3d fp = lam * ct.normal + ft;
        st.normal_force += lam;
        st.tangential_force += ft;
        st.torque += (pt.p - ct.position).cross(fp);
        const Eigen::Vector3d urel =
            object_velocity(pt.p) -
            (ct.pusher ? pt.body_velocity : Eigen::Vector3d(vf * ct.normal));
        const Eigen::Vector3d ut = urel - ct.normal.dot(urel) * ct.normal;
        if (lam > 1e-9 * Fs && ut.norm() > 1e-9 * Vs) sliding = true;
      }
      st.mode = st.normal_force <= 1e-9 * Fs
                    ? ContactMode::kSeparate
                    : (sliding ? ContactMode::kSlide : ContactMode::kStick);
    }
    if (ct.pusher) pusher_force = st.normal_force * ct.normal + st.tangential_force;
    states[ci] = st;
  }

  // Integrate (semi-implicit Euler on the new twist). Pressing fingers'
  // pads follow the object along their normals; the pusher tracks its gaps.
  for (Contact& ct : contacts) {
    if (ct.pusher) {
      for (Point& pt : ct.points)
        pt.gap += dt * ct.normal.dot(object_velocity(pt.p) - pt.body_velocity);
    } else if (ct.active) {
      const double vf = ct.y_plus >= 0 ? zv(ct.y_plus) - zv(ct.y_minus)
                                       : ct.normal.dot(object_velocity(ct.points[0].p));
      ct.pad += dt * vf;
    }
  }
  v = v_new;
  w = w_new;
  c += dt * v_new;
  const double angle = w_new.norm() * dt;
  if (angle > 0)
    q = (Eigen::Quaterniond(Eigen::AngleAxisd(angle, w_new.normalized())) * q).normalized();
  t += dt;
  return rep;
}

}  // namespace arena::mechanics
