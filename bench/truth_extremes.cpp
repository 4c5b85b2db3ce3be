// The extremes table per simulator (issue 31): every parameter of the
// canonical scene swept over decades, one at a time, through arena's model
// and MuJoCo at their default settings, each run judged against the closed
// form it has. A row is
//   right         status ok and the closed form holds (below);
//   typed error   a typed failure (solver_failure, invalid_scene) with its reason;
//   SILENT WRONG  status ok but the closed form does not hold.
// A truth must never be silently wrong: exit 1 when any row is.
//
// The closed form (the canonical scene: a 0.05 x 0.03 x 0.1 m box of mass m
// between a point and a line finger along x pressing N each with friction mu,
// a point pusher under the bottom face moving +z at v, gravity -z): the
// pusher carries the object up through the grasp, both fingers slide
// (kinetic friction mu N each, opposing the motion), so
//   position(t) = (0, 0, v t), no rotation, pusher force 2 mu N + m g,
// while the fingers are on the object (t < h / 2v); after that the object
// rides on the pusher (z = v t still). Checked: the final centre of mass
// within 1 % of the travel plus 1e-3 of the object's extent; every angle of
// the final pose within 0.01 rad; the mean pusher force over the samples in
// [T/4, min(T, 0.9 h / 2v)] within 2 % of 2 mu N + m g (when there are any).
//
//   build/bench/truth_extremes                  # the table
//   build/bench/truth_extremes --mujoco '{...}'  # MuJoCo at other settings
//   build/bench/truth_extremes --parallel-jaw    # every row in a parallel jaw
//   build/bench/truth_extremes --only "grip"     # rows whose name has this
//   build/bench/truth_extremes --only pivot      # the pivot comparison only
// After the table: a planar pivot through both simulators, with MuJoCo's
// fingers independent and in a jaw (bench/README.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "arena/mechanics/model.hpp"
#include "arena/simulators/simulator.hpp"
#include "extremes_suite.hpp"

namespace m = arena::mechanics;
namespace s = arena::simulators;

namespace {

struct Row {
  std::string name;
  m::Scene scene;
};

std::string Sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::vector<Row> Rows() {
  m::Scene base = m::testing::CanonicalScene();
  base.duration = 0.2;
  std::vector<Row> rows;
  for (double g : {1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3, 1e4}) {
    Row r{"grip " + Sci(g) + " N", base};
    r.scene.grip_force = g;
    rows.push_back(r);
  }
  for (double mass : {1e-4, 1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3}) {
    Row r{"mass " + Sci(mass) + " kg", base};
    r.scene.object.mass = mass;
    rows.push_back(r);
  }
  for (double size : {1e-3, 1e-2, 1e-1, 1.0, 10.0}) {
    Row r{"size " + Sci(size) + " m", base};
    m::testing::ScaleLength(r.scene, size / r.scene.object.size.maxCoeff());
    rows.push_back(r);
  }
  for (double v : {1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0}) {
    Row r{"speed " + Sci(v) + " m/s", base};
    r.scene.pusher->motion.velocity = {0, 0, v};
    rows.push_back(r);
  }
  for (double mu : {1e-3, 1e-2, 1e-1, 1.0, 10.0}) {
    Row r{"mu " + Sci(mu), base};
    for (auto& f : r.scene.fingers) f.mu = mu;
    r.scene.pusher->mu = mu;
    rows.push_back(r);
  }
  return rows;
}

enum class Verdict { kRight, kTyped, kSilent };

struct Judged {
  Verdict verdict = Verdict::kRight;
  std::string why;
};

Judged Judge(const m::Scene& scene, const m::SimulationResult& r) {
  char buf[200];
  if (r.status != m::SimulationStatus::kOk)
    return {Verdict::kTyped, std::string(m::ToString(r.status)) + ": " + r.error};
  if (r.samples.empty()) return {Verdict::kSilent, "no samples"};
  const double v = scene.pusher->motion.velocity.z();
  const double h = scene.object.size.z(), extent = scene.object.size.maxCoeff();
  const double mg = scene.object.mass * scene.gravity.norm();
  const double mu = scene.fingers[0].mu;
  const double force = 2 * mu * scene.grip_force + mg;
  // The last sample with the object still in the grasp: out of it, a box
  // balanced on a point pusher topples, which no closed form here follows.
  const double T = r.samples.back().t;
  const double until = std::min(T, 0.9 * h / (2 * v));
  const m::TrajectorySample* held = &r.samples.front();
  for (const auto& smp : r.samples)
    if (smp.t <= until) held = &smp;
  const auto& last = *held;
  const Eigen::Vector3d expected(0, 0, v * last.t);
  const double tol = 0.01 * v * last.t + 1e-3 * extent;
  const Eigen::Vector3d error = last.position - expected;
  const double off = error.norm();
  if (!(off <= tol)) {
    std::snprintf(
        buf, sizeof buf,
        "position at t = %.3g s off (0, 0, vt) by (%.2g, %.2g, %.2g) m (tolerance %.2g m)", last.t,
        error.x(), error.y(), error.z(), tol);
    return {Verdict::kSilent, buf};
  }
  const Eigen::AngleAxisd turn(last.orientation);
  if (!(std::abs(turn.angle()) <= 0.01)) {
    std::snprintf(buf, sizeof buf, "turned %.3g rad at t = %.3g s (expected 0)",
                  std::abs(turn.angle()), last.t);
    return {Verdict::kSilent, buf};
  }
  double sum = 0;
  int n = 0;
  for (const auto& smp : r.samples) {
    if (smp.t >= T / 4 && smp.t <= until) sum += smp.pusher_force.z(), ++n;
  }
  if (n > 0) {
    const double mean = sum / n;
    if (!(std::abs(mean - force) <= 0.02 * force)) {
      std::snprintf(buf, sizeof buf,
                    "pusher force %.4g N, expected 2 mu N + m g = %.4g N (%+.1f %%)", mean, force,
                    100 * (mean / force - 1));
      return {Verdict::kSilent, buf};
    }
  }
  std::snprintf(buf, sizeof buf, "%.2g m off at t = %.3g s; force over %d samples", off, last.t, n);
  return {Verdict::kRight, buf};
}

// A benign planar pivot: the canonical scene (a point and a line finger,
// 10 N, mu 0.5, 0.2 kg, gravity) with the pusher 1 cm off the grip axis
// (along y), 1 cm/s up, 0.5 s: where arena's model and MuJoCo end, each
// with the fingers independent (the scene's default) and in a jaw.
void PivotComparison() {
  m::Scene s = m::testing::CanonicalScene();
  s.pusher->position.y() = 0.01;
  s.duration = 0.5;
  std::printf("\nPlanar pivot, final pose of MuJoCo against arena's model:\n\n");
  std::printf(
      "| arena's fingers | MuJoCo fingers | status | position apart | angle apart |\n"
      "|---|---|---|---:|---:|\n");
  const auto couplings = {m::GripperCoupling::kIndependent, m::GripperCoupling::kParallelJaw};
  for (const auto arena_coupling : couplings) {
    m::Scene a_scene = s;
    a_scene.gripper.coupling = arena_coupling;
    const auto arena = s::MakeSimulator("arena", "")->Simulate(a_scene);
    for (const auto coupling : couplings) {
      m::Scene c = s;
      c.gripper.coupling = coupling;
      const auto r = s::MakeSimulator("mujoco", "")->Simulate(c);
      if (r.status != m::SimulationStatus::kOk || arena.status != m::SimulationStatus::kOk) {
        std::printf("| %s | %s | %s: %s %s | | |\n", m::ToString(arena_coupling),
                    m::ToString(coupling), m::ToString(r.status), r.error.c_str(),
                    arena.error.c_str());
        continue;
      }
      const auto &a = arena.samples.back(), &b = r.samples.back();
      std::printf("| %s | %s | ok | %.3f mm | %.1f mrad |\n", m::ToString(arena_coupling),
                  m::ToString(coupling), 1e3 * (a.position - b.position).norm(),
                  1e3 * a.orientation.angularDistance(b.orientation));
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string mujoco_settings;
  std::string only;  // rows whose name contains this
  bool arena = true, jaw = false;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--mujoco") == 0 && i + 1 < argc) mujoco_settings = argv[++i];
    if (std::strcmp(argv[i], "--only") == 0 && i + 1 < argc) only = argv[++i];
    if (std::strcmp(argv[i], "--no-arena") == 0) arena = false;
    if (std::strcmp(argv[i], "--parallel-jaw") == 0) jaw = true;
  }
  auto rows = Rows();
  for (auto& row : rows)
    if (jaw) row.scene.gripper.coupling = m::GripperCoupling::kParallelJaw;
  std::vector<std::pair<std::string, std::string>> engines = {{"arena", ""},
                                                              {"mujoco", mujoco_settings}};
  if (!arena) engines.erase(engines.begin());
  std::printf("| case | simulator | verdict | detail |\n|---|---|---|---|\n");
  int silent = 0;
  std::vector<std::string> totals;
  for (const auto& [name, settings] : engines) {
    const auto sim = s::MakeSimulator(name, settings);
    int right = 0, typed = 0, wrong = 0;
    for (const auto& row : rows) {
      if (row.name.find(only) == std::string::npos) continue;
      const auto r = sim->Simulate(row.scene);
      const Judged j = Judge(row.scene, r);
      std::string why = j.why;
      for (auto& ch : why)
        if (ch == '|') ch = '/';
      if (why.size() > 160) why = why.substr(0, 157) + "...";
      const char* verdict = j.verdict == Verdict::kRight   ? "right"
                            : j.verdict == Verdict::kTyped ? "typed error"
                                                           : "SILENT WRONG";
      (j.verdict == Verdict::kRight ? right : j.verdict == Verdict::kTyped ? typed : wrong)++;
      std::printf("| %s | %s | %s | %s |\n", row.name.c_str(), name.c_str(), verdict, why.c_str());
    }
    silent += wrong;
    char buf[160];
    std::snprintf(buf, sizeof buf, "%s: %zu rows, %d right, %d typed errors, %d silent wrong",
                  name.c_str(), rows.size(), right, typed, wrong);
    totals.push_back(buf);
  }
  std::printf("\n");
  for (const auto& t : totals) std::printf("%s\n", t.c_str());
  if (only.empty() || only == "pivot") PivotComparison();
  return silent == 0 ? 0 : 1;
}
