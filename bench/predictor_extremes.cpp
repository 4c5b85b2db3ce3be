// Stability at the extremes, per predictor (issue 14): the extremes of the
// issue (mu 1e-3..10, mass 1e-6..1e3 kg, object size 1e-4..10 m, grip
// 1e-3..1e3 N, pusher speed 1e-4..10 m/s; one at a time and in pairs, 50
// cases on the canonical scene, 0.2 s) through every predictor at its
// default and its coarsest setting. Each run is counted as
//   solved        status ok and none of the checks below fired;
//   typed error   a typed failure (solver_failure, invalid_scene), no NaN;
//   silent wrong  status ok but: a residual above 1e-6 of the force scale
//                 (arena), an energy gain (the object faster than twice the
//                 pusher plus 1 cm/s plus gravity's kick over one 4 ms
//                 sample), or a divergence (non-finite state,
//                 moved beyond the pusher's travel plus its extent, turned
//                 more than 90 degrees: assessment::DivergenceReason).
// A drop (every finger separated over the last quarter) is counted apart: it
// is not wrong when the grip cannot hold the weight.
//
//   build/bench/predictor_extremes            # counts per predictor and setting
//   build/bench/predictor_extremes --cases    # and one line per case
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "arena/assessment/prediction.hpp"
#include "arena/assessment/predictor.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "extremes_suite.hpp"

namespace m = arena::mechanics;
namespace a = arena::assessment;

namespace {

struct Dim {
  const char* name;
  double lo, hi;
  void (*apply)(m::Scene&, double);
};

const Dim kDims[] = {
    {"mu", 1e-3, 10,
     [](m::Scene& s, double v) {
       for (auto& f : s.fingers) f.mu = v;
       s.pusher->mu = v;
     }},
    {"mass", 1e-6, 1e3, [](m::Scene& s, double v) { s.object.mass = v; }},
    {"size", 1e-4, 10,
     [](m::Scene& s, double v) { m::testing::ScaleLength(s, v / s.object.size.maxCoeff()); }},
    {"grip", 1e-3, 1e3, [](m::Scene& s, double v) { s.grip_force = v; }},
    {"speed", 1e-4, 10,
     [](m::Scene& s, double v) {
       s.pusher->motion.velocity = s.pusher->motion.velocity.normalized() * v;
     }},
};

struct Case {
  std::string name;
  m::Scene scene;
};

std::vector<Case> Cases() {
  std::vector<Case> out;
  const m::Scene base = [] {
    m::Scene s = m::testing::CanonicalScene();
    s.duration = 0.2;
    return s;
  }();
  char buf[96];
  for (const auto& d : kDims) {
    for (double v : {d.lo, d.hi}) {
      Case c{"", base};
      d.apply(c.scene, v);
      std::snprintf(buf, sizeof buf, "%s %g", d.name, v);
      c.name = buf;
      out.push_back(c);
    }
  }
  for (std::size_t i = 0; i < std::size(kDims); ++i) {
    for (std::size_t j = i + 1; j < std::size(kDims); ++j) {
      for (double vi : {kDims[i].lo, kDims[i].hi}) {
        for (double vj : {kDims[j].lo, kDims[j].hi}) {
          Case c{"", base};
          kDims[i].apply(c.scene, vi);
          kDims[j].apply(c.scene, vj);
          std::snprintf(buf, sizeof buf, "%s %g + %s %g", kDims[i].name, vi, kDims[j].name, vj);
          c.name = buf;
          out.push_back(c);
        }
      }
    }
  }
  return out;
}

enum class Verdict { kSolved, kTyped, kSilent };

struct Outcome {
  Verdict verdict = Verdict::kSolved;
  bool dropped = false;
  std::string why;
};

Outcome Judge(const m::Scene& scene, const m::SimulationResult& r, bool check_residuals) {
  Outcome o;
  if (r.status != m::SimulationStatus::kOk) {
    o.verdict = Verdict::kTyped;
    o.why = std::string(m::ToString(r.status)) + ": " + r.error.substr(0, 80);
    return o;
  }
  if (check_residuals && (r.residuals.force_balance > 1e-6 || r.residuals.complementarity > 1e-6 ||
                          r.residuals.cone > 1e-6)) {
    o.verdict = Verdict::kSilent;
    o.why = "residual above 1e-6";
    return o;
  }
  if (const auto why = a::DivergenceReason(scene, r.samples, {})) {
    o.verdict = Verdict::kSilent;
    o.why = *why;
    return o;
  }
  // Gravity's kick over one 250 Hz sample before the contacts take the
  // weight is a start transient, not a gain: it is allowed for.
  const double v_pusher = scene.pusher ? scene.pusher->motion.velocity.norm() : 0;
  const double allowed = 2 * v_pusher + 0.01 + scene.gravity.norm() * 0.004;
  for (const auto& s : r.samples) {
    if (s.velocity.norm() > allowed) {
      o.verdict = Verdict::kSilent;
      char buf[96];
      std::snprintf(buf, sizeof buf, "energy gain: object at %.3g m/s, pusher %.3g m/s",
                    s.velocity.norm(), v_pusher);
      o.why = buf;
      return o;
    }
  }
  const std::size_t n = r.samples.size(), tail = std::max<std::size_t>(2, n / 4);
  if (n >= tail) {
    bool dropped = true;
    for (std::size_t i = n - tail; i < n; ++i)
      for (std::size_t f = 0; f < scene.fingers.size() && f < r.samples[i].contacts.size(); ++f)
        dropped = dropped && r.samples[i].contacts[f].mode == m::ContactMode::kSeparate;
    o.dropped = dropped;
  }
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  const bool per_case = argc > 1 && std::strcmp(argv[1], "--cases") == 0;
  const auto cases = Cases();
  struct Run {
    std::string predictor, label;
    std::unique_ptr<a::Predictor> p;
    bool residuals;
  };
  std::vector<Run> runs;
  runs.push_back({"arena", "default g8_k3_dt0.004",
                  a::MakeArenaPredictor({m::ModelOptions{8, 3, 0.004, m::Reduce::kAuto}}), true});
  runs.push_back({"arena", "coarsest g4_k3_dt0.008",
                  a::MakeArenaPredictor({m::ModelOptions{4, 3, 0.008, m::Reduce::kAuto}}), true});
  runs.push_back({"mujoco", "default ts0.0005",
                  a::MakeMujocoPredictor(a::MujocoGrid{{0.0005}, {"elliptic"}, {10}}), false});
  runs.push_back({"mujoco", "coarsest ts0.004",
                  a::MakeMujocoPredictor(a::MujocoGrid{{0.004}, {"elliptic"}, {10}}), false});
  std::printf("| predictor | setting | cases | solved | typed error | silent wrong | dropped |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|\n");
  std::vector<std::string> lines;
  int arena_silent = 0;
  for (const auto& run : runs) {
    int solved = 0, typed = 0, silent = 0, dropped = 0;
    for (const auto& c : cases) {
      m::Scene s = c.scene;
      std::string verdict;
      try {
        m::ValidateScene(s);
      } catch (const std::exception& e) {
        ++typed;
        if (per_case)
          lines.push_back(run.predictor + " " + run.label + " | " + c.name +
                          " | typed (scene refused: " + std::string(e.what()).substr(0, 60) + ")");
        continue;
      }
      const auto r = run.p->Run(s, 0);
      const Outcome o = Judge(s, r, run.residuals);
      switch (o.verdict) {
        case Verdict::kSolved:
          ++solved;
          verdict = o.dropped ? "solved, dropped" : "solved";
          break;
        case Verdict::kTyped:
          ++typed;
          verdict = "typed (" + o.why + ")";
          break;
        case Verdict::kSilent:
          ++silent;
          verdict = "SILENT WRONG (" + o.why + ")";
          break;
      }
      dropped += o.dropped;
      if (per_case)
        lines.push_back(run.predictor + " " + run.label + " | " + c.name + " | " + verdict);
    }
    if (run.predictor == "arena") arena_silent += silent;
    std::printf("| %s | %s | %zu | %d | %d | %d | %d |\n", run.predictor.c_str(), run.label.c_str(),
                cases.size(), solved, typed, silent, dropped);
  }
  for (const auto& l : lines) std::printf("%s\n", l.c_str());
  return arena_silent == 0 ? 0 : 1;
}
