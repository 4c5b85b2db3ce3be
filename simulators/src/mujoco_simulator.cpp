// The `mujoco` simulator: the scene rebuilt in MuJoCo 2.2 (soft contact,
// elliptic cones), an engine independent of arena's contact model.
//
// Model (MJCF, built in memory, loaded through MuJoCo's VFS):
//   world = the gripper frame; gravity as the scene's.
//   object: a body with a free joint (damping object_damping: a frictionless
//     pivot otherwise oscillates about its stall angle forever), a box or
//     cylinder geom and the scene's mass and inertia about the centre of mass.
//   finger i: a body on a slide joint along its normal, driven by a motor
//     whose force is the grip force (plus the finger's own weight along the
//     normal); two opposed fingers are coupled (each slide axis is its
//     normal, so joint1 = joint2 closes them symmetrically about a fixed
//     centre, as a parallel gripper's mechanism does: uncoupled, object and
//     fingers drift together in x). The gap stays free: the grip force holds.
//   pusher: a body on a free joint with a huge armature whose qpos and qvel
//     are written before every step (a mocap body would have zero velocity
//     to the solver, and contact damping then lags it by ~2·timeconst·v).
//   pads (fingers and pusher): spheres (r 1 mm): one for a point, 5 spread
//     over a line, 6 on the 2R/3 ring of arena's patch model for a patch
//     (they carry its torsion and tilt); every pad's surface touches the
//     object at t = 0.
//   contacts: explicit <pair>s only (pad with object), per-pair friction
//     (μ, torsion 0, rolling 0), condim 3, solref/solimp of the settings;
//     margin = gap = 1 mm so contacts are found before they touch.
//
// Truth per 250 Hz sample: the object's pose and twist from qpos/qvel; per
// finger / pusher the sum over its MuJoCo contacts of mj_contactForce in the
// gripper frame (force on the object), the torque about the pad's contact
// point, and the mode: separate without a loaded contact, slide when the
// tangential slip speed at a contact exceeds slip_speed, else stick.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <mujoco/mujoco.h>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/mechanics/model.hpp"
#include "arena/simulators/simulator.hpp"

namespace arena::simulators {
namespace {

constexpr double kPadRadius = 0.001;      // m: pad sphere radius
constexpr double kContactMargin = 0.001;  // m: contacts found this early (inactive: gap)

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
// ring of arena's patch model (which carry its torsion and tilt). A capsule
// (line) or a box (patch) gives MuJoCo 1, 2 or 4 contacts depending on the
// time step, and the final pose then moved 0.2 mm under a 4x finer step;
// spheres keep one contact each.
constexpr int kLinePads = 5;
constexpr int kPatchPads = 6;

int PadCount(const mechanics::ContactSpec& c) {
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

// Sphere centres (in the pad body's frame, whose origin is the contact point).
std::vector<Eigen::Vector3d> PadCentres(const mechanics::ContactSpec& c) {
  const Eigen::Vector3d n = c.normal.normalized();
  const Eigen::Vector3d back = -kPadRadius * n;
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

std::string PadGeoms(const std::string& base, const mechanics::ContactSpec& c) {
  std::ostringstream x;
  const auto centres = PadCentres(c);
  for (size_t j = 0; j < centres.size(); ++j) {
    x << "      <geom name=\"" << base << "_" << j
      << "\" type=\"sphere\" contype=\"0\" conaffinity=\"0\" mass=\"0\" size=\"" << Num(kPadRadius)
      << "\" pos=\"" << Vec(centres[j]) << "\"/>\n";
  }
  return x.str();
}

bool Opposed(const mechanics::Scene& s) {
  return s.fingers.size() == 2 &&
         (s.fingers[0].normal.normalized() + s.fingers[1].normal.normalized()).norm() < 1e-9;
}

std::string Pair(const std::string& pad, const mechanics::ContactSpec& c, const MujocoSettings& st);

std::string Pairs(const std::string& base, const mechanics::ContactSpec& c,
                  const MujocoSettings& st) {
  std::string all;
  for (int j = 0; j < PadCount(c); ++j) {
    all += "    " + Pair(base + "_" + std::to_string(j), c, st) + "\n";
  }
  return all;
}

std::string Pair(const std::string& pad, const mechanics::ContactSpec& c,
                 const MujocoSettings& st) {
  std::ostringstream x;
  x << "<pair geom1=\"" << pad << "\" geom2=\"object\" condim=\"3\" friction=\"" << Num(c.mu) << " "
    << Num(c.mu) << " 0 0 0\" solref=\"" << Num(st.solref_timeconst) << " "
    << Num(st.solref_damping) << "\" solimp=\"";
  for (int k = 0; k < 5; ++k) x << Num(st.solimp[k]) << (k < 4 ? " " : "");
  x << "\" margin=\"" << Num(kContactMargin) << "\" gap=\"" << Num(kContactMargin) << "\"/>";
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

// Owns a model and its data; frees them on every path.
struct MjHandles {
  mjModel* m = nullptr;
  mjData* d = nullptr;
  ~MjHandles() {
    if (d) mj_deleteData(d);
    if (m) mj_deleteModel(m);
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
                {"slip_speed", s.slip_speed}})
        .dump();
  }
  std::string CheckScene(const mechanics::Scene& scene) const override {
    if (scene.object.shape != mechanics::ObjectShape::kBox &&
        scene.object.shape != mechanics::ObjectShape::kCylinder)
      return "object.shape: the mujoco simulator models box and cylinder objects only";
    return "";
  }
  mechanics::SimulationResult Simulate(const mechanics::Scene& scene) const override;

 private:
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

  // Pusher contact point and orientation at time t (constant twist about the contact point).
  void PusherAt(double t, Eigen::Vector3d* p, Eigen::Quaterniond* q) const {
    const auto& ps = *scene.pusher;
    *p = ps.position + ps.motion.velocity * t;
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
    const Eigen::Vector3d w_local = q.conjugate() * scene.pusher->motion.angular_velocity;
    mjtNum* qv = d->qvel + pusher_qvel;
    for (int k = 0; k < 3; ++k) qv[k] = scene.pusher->motion.velocity[k], qv[3 + k] = w_local[k];
  }

  // Velocity of the pad carrying contact index `who` at world point p.
  Eigen::Vector3d PadVelocity(size_t who, const Eigen::Vector3d& p, double t) const {
    if (who < scene.fingers.size())
      return d->qvel[finger_qvel[who]] * scene.fingers[who].normal.normalized();
    Eigen::Vector3d c;
    Eigen::Quaterniond q;
    PusherAt(t, &c, &q);
    return scene.pusher->motion.velocity + scene.pusher->motion.angular_velocity.cross(p - c);
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
  Eigen::Vector3d PadNormal(size_t who, double t) const {
    if (who < scene.fingers.size()) return scene.fingers[who].normal.normalized();
    Eigen::Vector3d c;
    Eigen::Quaterniond q;
    PusherAt(t, &c, &q);
    return q * scene.pusher->normal.normalized();
  }

  mechanics::TrajectorySample Sample() const {
    mechanics::TrajectorySample s;
    s.t = d->time;
    const mjtNum* qp = d->qpos + object_qpos;
    const mjtNum* qv = d->qvel + object_qvel;
    s.position = Eigen::Vector3d(qp[0], qp[1], qp[2]);
    s.orientation = Eigen::Quaterniond(qp[3], qp[4], qp[5], qp[6]).normalized();
    s.velocity = Eigen::Vector3d(qv[0], qv[1], qv[2]);
    s.angular_velocity = s.orientation * Eigen::Vector3d(qv[3], qv[4], qv[5]);
    std::vector<Eigen::Vector3d> force(n_pads, Eigen::Vector3d::Zero()),
        torque(n_pads, Eigen::Vector3d::Zero());
    std::vector<bool> touching(n_pads, false), sliding(n_pads, false);
    for (int i = 0; i < d->ncon; ++i) {
      const mjContact& c = d->contact[i];
      if (c.exclude != 0 || c.efc_address < 0) continue;  // found in the margin, not active
      const int other = c.geom1 == object_geom ? c.geom2 : c.geom2 == object_geom ? c.geom1 : -1;
      if (other < 0 || pad_of_geom[static_cast<size_t>(other)] < 0) continue;
      const size_t who = static_cast<size_t>(pad_of_geom[static_cast<size_t>(other)]);
      mjtNum f6[6];
      mj_contactForce(m, d, i, f6);
      // Contact frame rows: normal (from geom1 to geom2), tangents. The force is
      // geom1's on geom2; our pairs put the pad first, so it is the pad's on the object.
      Eigen::Vector3d f_W = Eigen::Vector3d::Zero(), tau_W = Eigen::Vector3d::Zero();
      for (int r = 0; r < 3; ++r) {
        const Eigen::Vector3d axis(c.frame[3 * r], c.frame[3 * r + 1], c.frame[3 * r + 2]);
        f_W += f6[r] * axis;
        tau_W += f6[3 + r] * axis;
      }
      if (c.geom1 == object_geom) f_W = -f_W, tau_W = -tau_W;
      const Eigen::Vector3d p(c.pos[0], c.pos[1], c.pos[2]);
      const Eigen::Vector3d ref = PadPoint(who, s.t);
      force[who] += f_W;
      torque[who] += tau_W + (p - ref).cross(f_W);
      if (f_W.norm() > 0) touching[who] = true;
      const Eigen::Vector3d n(c.frame[0], c.frame[1], c.frame[2]);
      Eigen::Vector3d u =
          s.velocity + s.angular_velocity.cross(p - s.position) - PadVelocity(who, p, s.t);
      u -= u.dot(n) * n;
      if (u.norm() > st.slip_speed) sliding[who] = true;
    }
    for (size_t k = 0; k < n_pads; ++k) {
      mechanics::ContactState cs;
      const Eigen::Vector3d n = PadNormal(k, s.t);
      cs.normal_force = force[k].dot(n);
      cs.tangential_force = force[k] - cs.normal_force * n;
      cs.torque = torque[k];
      cs.mode = !touching[k] ? mechanics::ContactMode::kSeparate
                : sliding[k] ? mechanics::ContactMode::kSlide
                             : mechanics::ContactMode::kStick;
      s.contacts.push_back(cs);
    }
    if (scene.pusher) {
      Eigen::Quaterniond q;
      PusherAt(s.t, &s.pusher_position, &q);
      s.pusher_force = force.back();
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

mechanics::SimulationResult MujocoSimulator::Simulate(const mechanics::Scene& scene) const {
  const auto start = std::chrono::steady_clock::now();
  mechanics::SimulationResult result;
  const auto finish = [&]() -> mechanics::SimulationResult {
    result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };
  const int per_sample = StepsPerSample(settings_);
  const double dt = 1.0 / (mechanics::kSampleRateHz * per_sample);
  result.model.dof = 6;
  result.model.dt = dt;
  if (std::string why = CheckScene(scene); !why.empty()) {
    result.status = mechanics::SimulationStatus::kInvalidScene;
    result.error = why;
    return finish();
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
      return finish();
    }
    if (cache_) {
      WriteOptions(h.m, scene, settings_);
      if (h.d) mj_resetData(h.m, h.d);
    }
    if (!h.d) h.d = mj_makeData(h.m);
    Run run{scene, settings_, h.m, h.d, -1, -1, -1, -1, -1, -1, {}, {}, {}, 0, -1};
    run.pad_of_geom.assign(static_cast<size_t>(h.m->ngeom), -1);
    run.n_pads = scene.fingers.size() + (scene.pusher ? 1 : 0);
    run.object_body = mj_name2id(h.m, mjOBJ_BODY, "object");
    run.object_geom = mj_name2id(h.m, mjOBJ_GEOM, "object");
    const int oj = h.m->body_jntadr[run.object_body];
    run.object_qpos = h.m->jnt_qposadr[oj];
    run.object_qvel = h.m->jnt_dofadr[oj];
    for (size_t i = 0; i < scene.fingers.size(); ++i) {
      const std::string k = std::to_string(i);
      const int j = mj_name2id(h.m, mjOBJ_JOINT, ("finger" + k).c_str());
      run.finger_qpos.push_back(h.m->jnt_qposadr[j]);
      run.finger_qvel.push_back(h.m->jnt_dofadr[j]);
      for (int j = 0; j < PadCount(scene.fingers[i]); ++j) {
        const int g = mj_name2id(h.m, mjOBJ_GEOM, ("pad" + k + "_" + std::to_string(j)).c_str());
        run.pad_of_geom[static_cast<size_t>(g)] = static_cast<int>(i);
      }
    }
    if (scene.pusher) {
      run.pusher_body = mj_name2id(h.m, mjOBJ_BODY, "pusher");
      const int j = h.m->body_jntadr[run.pusher_body];
      run.pusher_qpos = h.m->jnt_qposadr[j];
      run.pusher_qvel = h.m->jnt_dofadr[j];
      for (int j = 0; j < PadCount(*scene.pusher); ++j) {
        const int g = mj_name2id(h.m, mjOBJ_GEOM, ("pusher_pad_" + std::to_string(j)).c_str());
        run.pad_of_geom[static_cast<size_t>(g)] = static_cast<int>(scene.fingers.size());
      }
    }
    // Grip force along each finger's normal, plus the finger's weight along it.
    for (size_t i = 0; i < scene.fingers.size(); ++i) {
      const double weight =
          settings_.finger_mass * scene.gravity.dot(scene.fingers[i].normal.normalized());
      h.d->ctrl[i] = scene.grip_force - weight;
    }
    const long n_samples =
        static_cast<long>(std::floor(scene.duration * mechanics::kSampleRateHz + 1e-9)) + 1;
    result.samples.reserve(static_cast<size_t>(n_samples));
    run.DrivePusher(0);
    mj_forward(h.m, h.d);
    for (long k = 0; k < n_samples; ++k) {
      if (k > 0) {
        for (int j = 0; j < per_sample; ++j) {
          run.DrivePusher(h.d->time);
          mj_step(h.m, h.d);
          ++result.solver.steps;
        }
        // Pusher and time exactly on the sample instant; forces of that state.
        h.d->time = static_cast<double>(k) / mechanics::kSampleRateHz;
        run.DrivePusher(h.d->time);
        mj_forward(h.m, h.d);
      }
      mechanics::TrajectorySample s = run.Sample();
      s.t = static_cast<double>(k) / mechanics::kSampleRateHz;
      if (!Finite(s) || h.d->warning[mjWARN_BADQACC].number > 0) {
        result.status = mechanics::SimulationStatus::kSolverFailure;
        result.failed_step = result.solver.steps;
        result.solver.failures = 1;
        result.error =
            "MuJoCo diverged at t = " + Num(s.t) + " s (non-finite state or acceleration)";
        return finish();
      }
      result.samples.push_back(std::move(s));
    }
  } catch (const std::exception& e) {
    result.status = mechanics::SimulationStatus::kSolverFailure;
    result.error = e.what();
    result.samples.clear();
  }
  return finish();
}

}  // namespace

std::string MujocoModelXml(const mechanics::Scene& scene, const MujocoSettings& st) {
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
    << "  <size nconmax=\"200\" njmax=\"1200\"/>\n"
    << "  <worldbody>\n";
  // Object.
  const Eigen::Quaterniond q_WO(mechanics::RotationFromRpy(o.pose.rpy));
  const Eigen::Matrix3d I = mechanics::ObjectInertia(o);
  x << "    <body name=\"object\" pos=\"" << Vec(o.pose.position) << "\" quat=\"" << Quat(q_WO)
    << "\">\n"
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
    default:
      throw SimulatorError("object.shape", "the mujoco simulator models box and cylinder only");
  }
  x << "    </body>\n";
  // Fingers: the body origin is the contact point; the slide axis the normal.
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    const auto& f = scene.fingers[i];
    const std::string k = std::to_string(i);
    x << "    <body name=\"finger" << k << "\" pos=\"" << Vec(f.position) << "\">\n"
      << "      <joint name=\"finger" << k << "\" type=\"slide\" axis=\""
      << Vec(f.normal.normalized()) << "\"/>\n"
      << "      <inertial pos=\"0 0 0\" mass=\"" << Num(st.finger_mass)
      << "\" diaginertia=\"1e-6 1e-6 1e-6\"/>\n"
      << PadGeoms("pad" + k, f) << "    </body>\n";
  }
  if (scene.pusher) {
    const auto& p = *scene.pusher;
    x << "    <body name=\"pusher\" pos=\"" << Vec(p.position) << "\">\n"
      << "      <joint name=\"pusher\" type=\"free\" armature=\"1e6\"/>\n"
      << "      <inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"1e-3 1e-3 1e-3\"/>\n"
      << PadGeoms("pusher_pad", p) << "    </body>\n";
  }
  x << "  </worldbody>\n  <contact>\n";
  for (size_t i = 0; i < scene.fingers.size(); ++i)
    x << Pairs("pad" + std::to_string(i), scene.fingers[i], st);
  if (scene.pusher) x << Pairs("pusher_pad", *scene.pusher, st);
  x << "  </contact>\n";
  if (Opposed(scene)) {
    x << "  <equality>\n    <joint joint1=\"finger0\" joint2=\"finger1\" polycoef=\"0 1 0 0 0\"/>\n"
      << "  </equality>\n";
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
