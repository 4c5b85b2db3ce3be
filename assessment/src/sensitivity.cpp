#include "arena/assessment/sensitivity.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/pusher_motion.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "number_text.hpp"

namespace arena::assessment {
namespace {

using mechanics::Scene;

constexpr double kNormalisedFloor = 1e-3;  // normalised derivatives closer than this agree
constexpr double kNonlinearFloor = 1e-2;   // of a quantity's scale: never "nonlinear" below

// Reference scale of each quantity: |nominal|, or a floor that makes "1 %"
// meaningful when the nominal is near zero (docs/sensitivity.md).
std::array<double, kQuantityCount> QuantityScales(const Scene& scene, const Outcome& o) {
  double travel = 0;
  if (scene.pusher) {
    // How far the pusher's reference point moves: |v| T, or a path's length.
    const auto& pusher = *scene.pusher;
    travel = pusher.motion.velocity.norm() * scene.duration;
    if (pusher.path) {
      travel = 0;
      Eigen::Vector3d last = mechanics::PusherPoseAt(pusher, 0).position;
      for (double t : pusher.path->t) {
        if (t > scene.duration) break;
        const Eigen::Vector3d here = mechanics::PusherPoseAt(pusher, t).position;
        travel += (here - last).norm();
        last = here;
      }
      travel += (mechanics::PusherPoseAt(pusher, scene.duration).position - last).norm();
    }
  }
  const double length = std::max({o.value(Quantity::kDisplacement), travel, 1e-3});
  const double angle = std::max(o.value(Quantity::kRotation), 1e-2);
  const double force = std::max({o.value(Quantity::kPusherForce), scene.grip_force * 1e-2, 1e-3});
  std::array<double, kQuantityCount> s{};
  for (int q = 0; q < kQuantityCount; ++q) {
    const auto kind = KindOf(static_cast<Quantity>(q));
    const double floor = kind == QuantityKind::kLength  ? length
                         : kind == QuantityKind::kAngle ? angle
                                                        : force;
    s[static_cast<size_t>(q)] = std::max(std::abs(o.values[static_cast<size_t>(q)]), floor);
  }
  return s;
}

// Model runs of perturbed scenes, counted, on the worker pool.
class Runner {
 public:
  Runner(const SensitivityOptions& o)
      : simulate_(o.simulate ? o.simulate : DefaultSimulate()),
        threads_(ThreadCount(o.threads)),
        progress_(o.progress) {}

  // Outcome at `delta`; nullopt when the perturbed scene is not valid.
  std::optional<Outcome> Run(const Scene& scene, const Parameter& p, double delta) {
    Scene s;
    try {
      s = delta == 0 ? scene : PerturbScene(scene, p, delta);
    } catch (const mechanics::SceneError&) {
      return std::nullopt;
    }
    Outcome o = MeasureOutcome(s, simulate_(s));
    const long done = ++runs_;
    if (progress_) {
      std::lock_guard<std::mutex> lock(mutex_);
      progress_(done, planned_);
    }
    return o;
  }
  void Plan(long more) { planned_ += more; }
  long runs() const { return runs_; }
  int threads() const { return threads_; }

 private:
  SimulateFn simulate_;
  int threads_;
  std::function<void(long, long)> progress_;
  std::atomic<long> runs_{0};
  std::atomic<long> planned_{0};
  std::mutex mutex_;
};

// A norm (rotation angle, displacement) at zero has a kink: its change is
// not judged against a derivative there (its signed components are).
bool AtKink(Quantity q, const Outcome& nominal, const std::array<double, kQuantityCount>& scales) {
  if (q != Quantity::kRotation && q != Quantity::kDisplacement) return false;
  const auto i = static_cast<size_t>(q);
  return std::abs(nominal.values[i]) < kNonlinearFloor * scales[i];
}

// ---------------------------------------------------------------- derivatives

struct Probes {
  bool central = true;
  std::optional<Outcome> plus_h, minus_h, plus_half, minus_half;
};

ParameterSensitivity Differentiate(const Scene& scene, const Parameter& p, double h,
                                   const Outcome& nominal,
                                   const std::array<double, kQuantityCount>& scales,
                                   const Probes& probes, double agreement) {
  ParameterSensitivity out;
  out.parameter = p;
  out.parameter.step = h;
  std::vector<const std::optional<Outcome>*> all = {&probes.plus_h, &probes.plus_half};
  if (probes.central) {
    all.push_back(&probes.minus_h);
    all.push_back(&probes.minus_half);
  }
  for (const auto* o : all) {
    if (!o->has_value()) {
      out.differentiable = false;
      out.note = "a probe leaves the valid scenes (step too large here)";
      return out;
    }
    if (!(*o)->ok) {
      out.differentiable = false;
      out.note = "the model fails within one step: " + (*o)->error;
      return out;
    }
    if (!SameDiscreteOutcome(nominal, **o)) {
      out.differentiable = false;
      out.note = "a contact mode or the grasp changes within one step (" +
                 DescribeDiscreteChange(scene, nominal, **o) + ")";
    }
  }
  std::string disagree;
  for (int q = 0; q < kQuantityCount; ++q) {
    const auto i = static_cast<size_t>(q);
    double d1, d2;
    if (probes.central) {
      d1 = (probes.plus_h->values[i] - probes.minus_h->values[i]) / (2 * h);
      d2 = (probes.plus_half->values[i] - probes.minus_half->values[i]) / h;
    } else {
      d1 = (probes.plus_h->values[i] - nominal.values[i]) / h;
      d2 = (probes.plus_half->values[i] - nominal.values[i]) / (h / 2);
    }
    const double to_norm = p.scale / scales[i];
    const double n1 = d1 * to_norm, n2 = d2 * to_norm;
    Derivative& d = out.derivatives[i];
    d.value = d2;
    d.normalised = n2;
    if (probes.central) {
      const double big = std::abs(probes.plus_h->values[i] - probes.minus_h->values[i]);
      const double small = std::abs(probes.plus_half->values[i] - probes.minus_half->values[i]);
      if (big > kNonlinearFloor * scales[i] && small > 0.75 * big && big > out.jump) {
        out.jump = big;
        out.jump_quantity = Name(Quantity(q));
      }
    }
    // Central differences converge as h^2, forward ones only as h.
    const double tol = probes.central ? agreement : 2 * agreement;
    d.agrees = AtKink(Quantity(q), nominal, scales) ||
               std::abs(n1 - n2) <= tol * std::max(std::abs(n1), std::abs(n2)) + kNormalisedFloor;
    if (!d.agrees) disagree += (disagree.empty() ? "" : ", ") + std::string(Name(Quantity(q)));
    out.score = std::max(out.score, std::abs(n2));
  }
  if (!disagree.empty()) {
    out.differentiable = false;
    if (!out.note.empty()) out.note += "; ";
    out.note += "steps h and h/2 disagree for " + disagree;
  }
  return out;
}

// ---------------------------------------------------------------- stability

struct Probe {
  size_t param = 0;
  int side = 1;  // +1 / -1
  int level = 0;
  double delta = 0;
  std::optional<Outcome> outcome;
};

void AddReason(Stability* s, const std::string& r) { s->reasons.push_back(r); }

const char* UnitOf(const std::string& quantity) {
  for (int q = 0; q < kQuantityCount; ++q) {
    if (quantity == Name(Quantity(q))) return Unit(Quantity(q));
  }
  return "";
}

using internal::Num;

// "0.2 mm" for 0.0002 in "m": a reason is read by a person, in human units.
std::string Human(double v, const std::string& si_unit) {
  const HumanUnit h = HumanUnitOf(si_unit);
  return Num(v * h.factor) + (h.unit == "1" || h.unit.empty() ? "" : " " + h.unit);
}

// Why the push is unstable, per parameter: the model fails or the outcome
// changes within its tolerance, a jump within it, a nonlinear response.
void AddStabilityReasons(const std::vector<Parameter>& params,
                         const std::vector<ParameterSensitivity>& sens, const StabilityOptions& o,
                         Stability* st_out) {
  Stability& st = *st_out;
  for (size_t i = 0; i < params.size(); ++i) {
    const ParameterStability& ps = st.parameters[i];
    // "0.02 N", "0.2 mm"; a dimensionless parameter (unit "1") gets no unit.
    const std::string& unit = params[i].unit;
    const std::string tol_text = Human(ps.tolerance, unit);
    if (ps.failed) {
      AddReason(&st, "the model fails within " + params[i].name + " +- " + tol_text);
    } else if (ps.flips) {
      AddReason(&st, params[i].name + " within +- " + tol_text + " changes the outcome (" +
                         ps.change + ") at " + Human(ps.boundary.value_or(0), unit));
    }
    const ParameterSensitivity& ds = sens[i];
    if (!ds.jump_quantity.empty() && ps.tolerance > 0 && ds.parameter.step <= ps.tolerance) {
      AddReason(&st, params[i].name + " +- " + Human(ds.parameter.step, unit) +
                         " (within the tolerance " + tol_text + ") makes " + ds.jump_quantity +
                         " jump by " + Human(ds.jump, UnitOf(ds.jump_quantity)) +
                         ": discontinuous here");
    }
    if (ps.nonlinear) {
      AddReason(&st, params[i].name + " +- " + tol_text + " moves " + ps.nonlinear_quantity + " " +
                         Num(ps.linear_ratio) + "x its linearised estimate (limit " +
                         Num(o.linear_multiple) + "x)");
    }
  }
}

Stability CheckStability(const Scene& scene, const std::vector<Parameter>& params,
                         const std::vector<ParameterSensitivity>& sens, const Outcome& nominal,
                         const std::array<double, kQuantityCount>& scales,
                         const StabilityOptions& o, Runner& runner) {
  Stability st;
  st.checked = true;
  std::vector<Probe> probes;
  std::vector<double> tol(params.size(), 0);
  for (size_t i = 0; i < params.size(); ++i) {
    auto [delta, source] = ToleranceFor(params[i], o);
    tol[i] = delta;
    ParameterStability ps;
    ps.parameter = params[i].name;
    ps.tolerance = delta;
    ps.source = source;
    st.parameters.push_back(ps);
    if (!(delta > 0)) continue;
    for (int level = 0; level < o.search_levels; ++level) {
      for (int side : {1, -1}) {
        probes.push_back({i, side, level, side * delta * std::ldexp(1.0, level), std::nullopt});
      }
    }
  }
  runner.Plan(static_cast<long>(probes.size()));
  RunParallel(static_cast<long>(probes.size()), runner.threads(), [&](long k) {
    Probe& pr = probes[static_cast<size_t>(k)];
    pr.outcome = runner.Run(scene, params[pr.param], pr.delta);
  });

  // Per parameter and side: the first level whose discrete outcome differs.
  struct Crossing {
    size_t param;
    double inside, outside;  // offsets: same outcome at `inside`, changed at `outside`
  };
  std::vector<Crossing> crossings;
  for (size_t i = 0; i < params.size(); ++i) {
    if (!(tol[i] > 0)) continue;
    ParameterStability& ps = st.parameters[i];
    for (int side : {1, -1}) {
      double inside = 0;
      for (int level = 0; level < o.search_levels; ++level) {
        const Probe* pr = nullptr;
        for (const auto& p : probes) {
          if (p.param == i && p.side == side && p.level == level) pr = &p;
        }
        if (!pr || !pr->outcome) break;  // outside the admissible scenes: stop this side
        const Outcome& out = *pr->outcome;
        if (!out.ok && level == 0) ps.failed = true;
        if (!SameDiscreteOutcome(nominal, out)) {
          if (level == 0) ps.flips = true;
          crossings.push_back({i, inside, pr->delta});
          break;
        }
        if (level == 0 && out.ok) {
          // Linearised estimate against the model's own change.
          for (int q = 0; q < kQuantityCount; ++q) {
            const auto qi = static_cast<size_t>(q);
            if (AtKink(Quantity(q), nominal, scales)) continue;
            const double actual = std::abs(out.values[qi] - nominal.values[qi]);
            const double linear = std::abs(sens[i].derivatives[qi].value * pr->delta);
            const double ratio = actual / (linear + kNonlinearFloor * scales[qi]);
            if (ratio > ps.linear_ratio) {
              ps.linear_ratio = ratio;
              ps.nonlinear_quantity = Name(Quantity(q));
            }
          }
        }
        inside = pr->delta;
      }
    }
    ps.nonlinear = ps.linear_ratio > o.linear_multiple;
    if (!ps.nonlinear) ps.nonlinear_quantity.clear();
  }

  // Bisect each crossing to locate its boundary.
  std::vector<std::pair<double, std::string>> found(crossings.size());
  runner.Plan(static_cast<long>(crossings.size()) * o.bisections);
  RunParallel(static_cast<long>(crossings.size()), runner.threads(), [&](long k) {
    Crossing c = crossings[static_cast<size_t>(k)];
    const Parameter& p = params[c.param];
    std::string change;
    if (auto out = runner.Run(scene, p, c.outside)) {
      change = DescribeDiscreteChange(scene, nominal, *out);
    }
    for (int b = 0; b < o.bisections; ++b) {
      const double mid = 0.5 * (c.inside + c.outside);
      auto out = runner.Run(scene, p, mid);
      if (out && SameDiscreteOutcome(nominal, *out)) {
        c.inside = mid;
      } else {
        c.outside = mid;
        if (out) change = DescribeDiscreteChange(scene, nominal, *out);
      }
    }
    found[static_cast<size_t>(k)] = {0.5 * (c.inside + c.outside), change};
  });
  for (size_t k = 0; k < crossings.size(); ++k) {
    const size_t i = crossings[k].param;
    ParameterStability& ps = st.parameters[i];
    const double offset = found[k].first;
    if (!ps.boundary || std::abs(offset) < std::abs(*ps.boundary)) {
      ps.boundary = offset;
      ps.change = found[k].second;
    }
    const double in_tol = std::abs(offset) / tol[i];
    if (!st.nearest || in_tol < st.nearest->tolerances) {
      st.nearest = Boundary{params[i].name, offset, in_tol, found[k].second};
    }
  }
  AddStabilityReasons(params, sens, o, &st);
  st.unstable = !st.reasons.empty();
  return st;
}

}  // namespace

// ---------------------------------------------------------------- analysis

SensitivityReport AnalyseScene(const Scene& scene, const SensitivityOptions& o) {
  if (!(o.step_scale > 0) || !std::isfinite(o.step_scale)) {
    throw std::invalid_argument("step scale: must be a finite number > 0");
  }
  if (!(o.agreement > 0) || !std::isfinite(o.agreement)) {
    throw std::invalid_argument("agreement: must be a finite number > 0");
  }
  if (!(o.stability.linear_multiple > 1) || !std::isfinite(o.stability.linear_multiple)) {
    throw std::invalid_argument("--linear-multiple: must be a finite number > 1");
  }
  if (!(o.stability.relative_tolerance >= 0) || !std::isfinite(o.stability.relative_tolerance)) {
    throw std::invalid_argument("--tolerance: must be a finite number >= 0");
  }
  for (const auto& [name, t] : o.stability.tolerances) {
    if (!(t > 0) || !std::isfinite(t)) {
      throw std::invalid_argument("--tolerance " + name + ": must be a finite number > 0");
    }
  }
  if (o.stability.search_levels < 1 || o.stability.search_levels > 10 ||
      o.stability.bisections < 0 || o.stability.bisections > 30) {
    throw std::invalid_argument("search levels must be in [1, 10] and bisections in [0, 30]");
  }
  const auto start = std::chrono::steady_clock::now();
  const std::vector<Parameter> params = SelectParameters(SceneParameters(scene), o.params);
  for (const auto& [name, t] : o.stability.tolerances) {
    if (std::none_of(params.begin(), params.end(),
                     [&](const Parameter& p) { return p.name == name; })) {
      throw std::invalid_argument("--tolerance " + name +
                                  ": no such parameter among those analysed");
    }
  }
  Runner runner(o);
  SensitivityReport report;
  report.threads = runner.threads();
  // Four probes per parameter (two for one-sided ones), all in one batch.
  std::vector<Probes> probes(params.size());
  std::vector<double> steps(params.size());
  struct Job {
    size_t param;
    double delta;
    std::optional<Outcome>* into;
  };
  std::vector<Job> jobs;
  for (size_t i = 0; i < params.size(); ++i) {
    const double h = params[i].step * o.step_scale;
    steps[i] = h;
    probes[i].central = params[i].nominal - h >= params[i].lower;
    jobs.push_back({i, h, &probes[i].plus_h});
    jobs.push_back({i, h / 2, &probes[i].plus_half});
    if (probes[i].central) {
      jobs.push_back({i, -h, &probes[i].minus_h});
      jobs.push_back({i, -h / 2, &probes[i].minus_half});
    }
  }
  runner.Plan(1 + static_cast<long>(jobs.size()));
  report.nominal = *runner.Run(scene, Parameter{}, 0);
  auto finish = [&] {
    report.model_runs = runner.runs();
    report.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return report;
  };
  if (!report.nominal.ok) return finish();
  report.scales = QuantityScales(scene, report.nominal);

  RunParallel(static_cast<long>(jobs.size()), runner.threads(), [&](long k) {
    const Job& j = jobs[static_cast<size_t>(k)];
    *j.into = runner.Run(scene, params[j.param], j.delta);
  });
  for (size_t i = 0; i < params.size(); ++i) {
    report.parameters.push_back(Differentiate(scene, params[i], steps[i], report.nominal,
                                              report.scales, probes[i], o.agreement));
  }
  if (o.check_stability) {
    report.stability = CheckStability(scene, params, report.parameters, report.nominal,
                                      report.scales, o.stability, runner);
  }
  std::stable_sort(report.parameters.begin(), report.parameters.end(),
                   [](const ParameterSensitivity& a, const ParameterSensitivity& b) {
                     return a.score > b.score;
                   });
  return finish();
}

HumanUnit HumanUnitOf(const std::string& si_unit) {
  constexpr double kDeg = 180.0 / 3.14159265358979323846;
  if (si_unit == "m") return {"mm", 1e3};
  if (si_unit == "m/s") return {"mm/s", 1e3};
  if (si_unit == "rad") return {"deg", kDeg};
  if (si_unit == "rad/s") return {"deg/s", kDeg};
  if (si_unit == "s") return {"ms", 1e3};
  return {si_unit, 1};
}

nlohmann::json ToJson(const SensitivityReport& r, const Scene& scene) {
  using nlohmann::json;
  const auto names = ContactNames(scene);
  json nominal = {{"ok", r.nominal.ok}};
  if (!r.nominal.ok) {
    nominal["error"] = r.nominal.error;
  } else {
    json q = json::object(), modes = json::object();
    for (int i = 0; i < kQuantityCount; ++i) q[Name(Quantity(i))] = r.nominal.values[size_t(i)];
    for (size_t c = 0; c < r.nominal.modes.size() && c < names.size(); ++c) {
      modes[names[c]] = ModeSequenceText(r.nominal.modes[c]);
    }
    nominal["quantities"] = q;
    nominal["modes"] = modes;
    nominal["grasp_kept"] = r.nominal.grasp_kept;
  }
  json units = json::object(), scales = json::object();
  for (int i = 0; i < kQuantityCount; ++i) {
    units[Name(Quantity(i))] = Unit(Quantity(i));
    scales[Name(Quantity(i))] = r.scales[size_t(i)];
  }
  json params = json::array();
  for (const auto& p : r.parameters) {
    json d = json::object(), n = json::object();
    for (int i = 0; i < kQuantityCount; ++i) {
      d[Name(Quantity(i))] = p.derivatives[size_t(i)].value;
      n[Name(Quantity(i))] = p.derivatives[size_t(i)].normalised;
    }
    params.push_back({{"name", p.parameter.name},
                      {"group", p.parameter.group},
                      {"unit", p.parameter.unit},
                      {"nominal", p.parameter.nominal},
                      {"scale", p.parameter.scale},
                      {"step", p.parameter.step},
                      {"differentiable", p.differentiable},
                      {"note", p.note},
                      {"score", p.score},
                      {"derivative", d},
                      {"normalised", n}});
  }
  json out = {{"nominal", nominal},   {"quantity_units", units},    {"quantity_scales", scales},
              {"parameters", params}, {"model_runs", r.model_runs}, {"wall_s", r.wall_s},
              {"threads", r.threads}};
  if (r.stability.checked) {
    json ps = json::array();
    for (const auto& p : r.stability.parameters) {
      json j = {{"parameter", p.parameter},
                {"tolerance", p.tolerance},
                {"source", p.source},
                {"flips", p.flips},
                {"nonlinear", p.nonlinear},
                {"failed", p.failed},
                {"linear_ratio", p.linear_ratio}};
      if (p.nonlinear) j["nonlinear_quantity"] = p.nonlinear_quantity;
      if (p.boundary) {
        j["boundary"] = *p.boundary;
        j["change"] = p.change;
      }
      ps.push_back(j);
    }
    json s = {
        {"unstable", r.stability.unstable}, {"reasons", r.stability.reasons}, {"parameters", ps}};
    if (r.stability.nearest) {
      s["nearest_boundary"] = {{"parameter", r.stability.nearest->parameter},
                               {"offset", r.stability.nearest->offset},
                               {"tolerances", r.stability.nearest->tolerances},
                               {"change", r.stability.nearest->change}};
    } else {
      s["nearest_boundary"] = nullptr;
    }
    out["stability"] = s;
  }
  return out;
}

}  // namespace arena::assessment
