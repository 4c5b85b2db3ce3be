// LCP solver comparison (issue 7): arena's Lemke (mechanics/src/lcp.cpp)
// against Siconos numerics' lcp_lexicolemke, Bullet's btLemkeAlgorithm
// (double precision build) and DART's Lemke (when libdart-dev is installed),
// on the same problems: the per-step LCPs of
// arena's own scenes (ContactModel::SetLcpObserver) in families that are hard
// for pivoting solvers. All solvers are cold-started. Success = the solver
// says ok AND the natural residual ‖min(z, Mz + q)‖∞ (computed here, the
// same way for all) is ≤ 1e-8 (1 + ‖q‖∞). Prints Markdown (bench/README.md,
// section "LCP solvers"). Benchmark-only dependencies (bench/eval.cmake).
//
//   build/bench/lcp_solvers_bench [scenes per family, default 20] [family name part]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <siconos/numerics/LCP_Solvers.h>
#include <siconos/numerics/LinearComplementarityProblem.h>
#include <siconos/numerics/NumericsMatrix.h>
#include <siconos/numerics/SolverOptions.h>
#include <siconos/numerics/lcp_cst.h>

#include <BulletDynamics/MLCPSolvers/btLemkeAlgorithm.h>

#ifdef ARENA_HAVE_DART
#include <dart/lcpsolver/Lemke.hpp>
#endif

#include "arena/mechanics/lcp.hpp"
#include "arena/mechanics/model.hpp"
#include "extremes_suite.hpp"
#include "scenes.hpp"

namespace m = arena::mechanics;

namespace {

struct Problem {
  Eigen::MatrixXd M;
  Eigen::VectorXd q;
};

struct Outcome {
  bool ok = false;  // solver said ok
  Eigen::VectorXd z;
  int pivots = 0;
  double seconds = 0;
};

double NaturalResidual(const Problem& p, const Eigen::VectorXd& z) {
  if (z.size() != p.q.size() || !z.allFinite()) return INFINITY;
  const Eigen::VectorXd w = p.M * z + p.q;
  double r = 0;
  for (Eigen::Index i = 0; i < z.size(); ++i) r = std::max(r, std::abs(std::min(z[i], w[i])));
  return r;
}

using Clock = std::chrono::steady_clock;

Outcome SolveArena(const Problem& p) {
  Outcome o;
  const auto t0 = Clock::now();
  const m::LcpResult r = m::SolveLcp(p.M, p.q);
  o.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  o.ok = r.ok;
  o.z = r.z;
  o.pivots = r.pivots;
  return o;
}

Outcome SolveSiconos(const Problem& p) {
  Outcome o;
  const int n = static_cast<int>(p.q.size());
  auto* data = static_cast<double*>(std::malloc(sizeof(double) * n * n));
  std::memcpy(data, p.M.data(), sizeof(double) * n * n);  // both column-major
  NumericsMatrix* M = NM_create_from_data(NM_DENSE, n, n, data);
  std::vector<double> q(p.q.data(), p.q.data() + n), z(n, 0.0), w(n, 0.0);
  LinearComplementarityProblem problem;
  problem.size = n;
  problem.M = M;
  problem.q = q.data();
  SolverOptions* options = solver_options_create(SICONOS_LCP_LEMKE);
  options->iparam[SICONOS_IPARAM_MAX_ITER] = 50 * n + 200;  // arena's pivot bound
  int info = -1;
  const auto t0 = Clock::now();
  lcp_lexicolemke(&problem, z.data(), w.data(), &info, options);
  o.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  o.ok = info == 0;
  o.pivots = options->iparam[SICONOS_IPARAM_ITER_DONE];
  o.z = Eigen::Map<Eigen::VectorXd>(z.data(), n);
  solver_options_delete(options);
  NM_free(M);
  return o;
}

Outcome SolveBullet(const Problem& p) {
  Outcome o;
  const int n = static_cast<int>(p.q.size());
  btMatrixXu M(n, n);
  M.setZero();
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      if (p.M(i, j) != 0) M.setElem(i, j, p.M(i, j));
  btVectorXu q(n);
  for (int i = 0; i < n; ++i) q[i] = p.q[i];
  const auto t0 = Clock::now();
  btLemkeAlgorithm lemke(M, q, 0);
  btVectorXu solution = lemke.solve(50 * n + 200);
  o.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  o.ok = lemke.getInfo() == 0 && solution.size() == 2 * n;
  o.pivots = lemke.getSteps();
  o.z = Eigen::VectorXd::Zero(n);
  if (solution.size() == 2 * n) {
    for (int i = 0; i < n; ++i) o.z[i] = solution[n + i];  // [w; z]
  }
  return o;
}

#ifdef ARENA_HAVE_DART
// DART 6.12's Lemke (dart/lcpsolver/Lemke.hpp): its own pivot bound
// (min(1000, 50 n)) and no pivot count in its interface; 0 = success.
Outcome SolveDart(const Problem& p) {
  Outcome o;
  Eigen::VectorXd z(p.q.size());
  const auto t0 = Clock::now();
  const int info = dart::lcpsolver::Lemke(p.M, p.q, &z);
  o.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  o.ok = info == 0;
  o.pivots = -1;  // not reported by DART
  o.z = z;
  return o;
}
#endif

// Simulates the scene with arena's model and keeps every step's LCP.
void Collect(const m::Scene& scene, std::vector<Problem>* out) {
  m::ContactModel model(scene);
  if (model.status() != m::SimulationStatus::kOk) return;
  model.SetLcpObserver([out](const Eigen::MatrixXd& A, const Eigen::VectorXd& b) {
    out->push_back({A, b});
  });
  const int steps = static_cast<int>(std::lround(scene.duration / scene.model.dt));
  for (int i = 0; i < steps; ++i) {
    if (!model.Step().ok) break;
  }
}

m::PusherSpec Pusher(Eigen::Vector3d position, Eigen::Vector3d normal, Eigen::Vector3d velocity,
                     double mu) {
  m::PusherSpec p;
  p.name = "pusher";
  p.position = position;
  p.normal = normal;
  p.mu = mu;
  p.motion.velocity = velocity;
  return p;
}

struct Family {
  std::string name;
  std::function<m::Scene(std::mt19937&)> make;  // one random scene of the family
};

double U(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

std::vector<Family> Families() {
  std::vector<Family> f;
  auto canonical = [](std::mt19937& rng) {
    m::Scene s = m::testing::CanonicalScene();
    s.duration = 0.2;
    s.grip_force = U(rng, 5, 15);
    s.pusher->motion.velocity = Eigen::Vector3d(U(rng, -0.005, 0.005), 0, U(rng, 0.005, 0.02));
    return s;
  };
  f.push_back({"arena scenes (canonical, point+line)", canonical});
  f.push_back({"arena scenes (patch fingers)", [](std::mt19937& rng) {
                 m::Scene s = m::testing::PatchScene();
                 s.duration = 0.2;
                 s.grip_force = U(rng, 5, 15);
                 s.pusher->motion.velocity = Eigen::Vector3d(0, 0, U(rng, 0.005, 0.02));
                 return s;
               }});
  f.push_back({"box sliding (linear push, fingers slide)", [](std::mt19937& rng) {
                 m::Scene s = m::testing::HeldBox(0.2, U(rng, 5, 15), U(rng, 0.2, 0.8));
                 s.pusher = Pusher({0, 0, -0.05}, {0, 0, 1}, {0, 0, U(rng, 0.005, 0.05)}, 0.3);
                 return s;
               }});
  f.push_back({"3x3 contact patch (9 points)", [](std::mt19937& rng) {
                 m::Scene s = m::testing::PatchScene();
                 s.duration = 0.2;
                 s.model.points = 9;
                 s.grip_force = U(rng, 5, 15);
                 s.pusher->motion.velocity = Eigen::Vector3d(0, 0, U(rng, 0.005, 0.02));
                 return s;
               }});
  for (double mu : {1e-3, 10.0}) {
    char name[64];
    std::snprintf(name, sizeof name, "mu = %g", mu);
    f.push_back({name, [mu, canonical](std::mt19937& rng) {
                   m::Scene s = canonical(rng);
                   for (auto& finger : s.fingers) finger.mu = mu * U(rng, 0.9, 1.1);
                   s.pusher->mu = mu;
                   return s;
                 }});
  }
  // arena's model has one dynamic body (the object; fingers and pusher are
  // kinematic), so "a light body on a heavy one" is a light object in a
  // strong grip: grip force / object weight = ratio.
  for (double ratio : {1e2, 1e4, 1e6}) {
    char name[64];
    std::snprintf(name, sizeof name, "mass ratio %g (grip / weight)", ratio);
    f.push_back({name, [ratio, canonical](std::mt19937& rng) {
                   m::Scene s = canonical(rng);
                   s.object.mass = s.grip_force / (9.81 * ratio);
                   return s;
                 }});
  }
  f.push_back({"redundant contacts (each finger doubled)", [canonical](std::mt19937& rng) {
                 m::Scene s = canonical(rng);
                 auto left = s.fingers[0], right = s.fingers[1];
                 left.name = "left2";
                 right.name = "right2";
                 s.fingers.push_back(left);
                 s.fingers.push_back(right);
                 return s;
               }});
  return f;
}

struct Stats {
  int n = 0, success = 0, said_ok = 0;
  std::vector<double> times, pivots;
};

double Quantile(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double h = (static_cast<double>(v.size()) - 1) * p;
  const auto lo = static_cast<std::size_t>(h);
  const std::size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

constexpr int kBulletMaxSize = 60;
constexpr int kDartFullSize = 120;

}  // namespace

int main(int argc, char** argv) {
  const int scenes = argc > 1 ? std::max(1, std::atoi(argv[1])) : 20;
  std::mt19937 rng(20261122);
  std::vector<const char*> solvers = {"arena", "siconos lexicolemke", "bullet lemke"};
  std::vector<std::function<Outcome(const Problem&)>> solve = {SolveArena, SolveSiconos,
                                                               SolveBullet};
#ifdef ARENA_HAVE_DART
  solvers.push_back("dart lemke");
  solve.push_back(SolveDart);
#else
  std::fprintf(stderr, "DART not found at build time (libdart-dev): its rows are left out\n");
#endif
  // Optional: only the families whose name contains argv[2] (profiling).
  const char* only = argc > 2 ? argv[2] : nullptr;
  std::printf(
      "| family | problems | n (median) | solver | success | said ok | median µs | p99 µs | median "
      "pivots | p99 pivots |\n");
  std::printf("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|\n");
  for (const Family& family : Families()) {
    if (only != nullptr && family.name.find(only) == std::string::npos) continue;
    std::vector<Problem> problems;
    for (int i = 0; i < scenes; ++i) {
      try {
        Collect(family.make(rng), &problems);
      } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: scene refused: %s\n", family.name.c_str(), e.what());
      }
    }
    std::vector<double> sizes;
    for (const auto& p : problems) sizes.push_back(static_cast<double>(p.q.size()));
    for (std::size_t s = 0; s < solvers.size(); ++s) {
      // Bullet's dense Lemke takes ~1 s per solve at n = 94 (and never
      // succeeds there): it is run only on the small families.
      if (s == 2 && Quantile(sizes, 0.5) > kBulletMaxSize) {
        std::printf("| %s | %zu | %.0f | %s | not run (n > %d: ~1 s per solve) | | | | | |\n",
                    family.name.c_str(), problems.size(), Quantile(sizes, 0.5), solvers[s],
                    kBulletMaxSize);
        continue;
      }
      // DART re-factorises its basis on every pivot (seconds per failing
      // solve at n = 194): on the large families it gets every 10th problem.
      const bool dart = std::string(solvers[s]) == "dart lemke";
      const std::size_t stride = dart && Quantile(sizes, 0.5) > kDartFullSize ? 10 : 1;
      Stats st;
      for (std::size_t k = 0; k < problems.size(); k += stride) {
        const Problem& p = problems[k];
        const Outcome o = solve[s](p);
        ++st.n;
        st.said_ok += o.ok;
        const double tol = 1e-8 * (1 + p.q.cwiseAbs().maxCoeff());
        st.success += o.ok && NaturalResidual(p, o.z) <= tol;
        st.times.push_back(o.seconds * 1e6);
        if (o.pivots >= 0) st.pivots.push_back(o.pivots);
      }
      char pivots[64] = "— | —";  // DART does not report its pivots
      if (!st.pivots.empty()) {
        std::snprintf(pivots, sizeof pivots, "%.0f | %.0f", Quantile(st.pivots, 0.5),
                      Quantile(st.pivots, 0.99));
      }
      std::printf("| %s | %d | %.0f | %s | %.2f %% | %.2f %% | %.1f | %.1f | %s |\n",
                  family.name.c_str(), st.n, Quantile(sizes, 0.5), solvers[s],
                  st.n ? 100.0 * st.success / st.n : 0.0, st.n ? 100.0 * st.said_ok / st.n : 0.0,
                  Quantile(st.times, 0.5), Quantile(st.times, 0.99), pivots);
      std::fflush(stdout);
    }
  }
  return 0;
}
