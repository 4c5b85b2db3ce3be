// Convergence study (issue 7): the model's error against the closed forms of
// the mechanics validation tests (tests/mechanics/validation_test.cpp) as the
// fidelity knobs are refined, with the observed order of convergence
// p = log(e_i / e_{i+1}) / log(h_i / h_{i+1}) between successive settings.
// Prints Markdown tables (bench/README.md, section "Convergence").
//
//   build/bench/convergence_study
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/simulate.hpp"
#include "scenes.hpp"

namespace m = arena::mechanics;

namespace {

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

struct Row {
  double h;      // the knob's "mesh size" (1/facets, dt)
  double knob;   // the knob's value as printed
  double error;  // relative error against the closed form
  bool ok;
};

void PrintTable(const char* knob, const std::vector<Row>& rows) {
  std::printf("| %s | relative error | observed order |\n|---:|---:|---:|\n", knob);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    char order[32] = "";
    if (i > 0 && rows[i].ok && rows[i - 1].ok && rows[i].error > 0 && rows[i - 1].error > 0) {
      std::snprintf(
          order, sizeof order, "%.2f",
          std::log(rows[i - 1].error / rows[i].error) / std::log(rows[i - 1].h / rows[i].h));
    }
    if (!rows[i].ok) {
      std::printf("| %g | solver failure | |\n", rows[i].knob);
    } else {
      std::printf("| %g | %.3e | %s |\n", rows[i].knob, rows[i].error, order);
    }
  }
  std::printf("\n");
}

// (d) Facets: the fingers' resistance to a push along the bisector of two
// cone edges (the direction the polyhedral cone approximates worst) against
// Coulomb's 2 μ N (the circular cone). Expected: 1 - cos(π/g) ~ π²/(2 g²), order 2.
std::vector<Row> FacetsSweep() {
  std::vector<Row> rows;
  // Even g only: for odd g the direction opposite a bisector is a cone edge,
  // where the polyhedral cone is exact (g = 3 gives 1e-16).
  for (int g : {4, 6, 8, 16, 32, 64, 128}) {
    m::Scene s = m::testing::HeldBox(0.2, 10.0, 0.5, g);
    s.gravity.setZero();
    const double a = std::numbers::pi / g;
    const Eigen::Vector3d u(0, -std::sin(a), std::cos(a));
    s.pusher = Pusher(-0.05 * u, u, 0.01 * u, 0.0);
    const m::SimulationResult r = m::Simulate(s);
    const double coulomb = 2 * 0.5 * 10.0;
    const bool ok = r.status == m::SimulationStatus::kOk;
    const double err = ok ? std::abs(r.samples.back().pusher_force.dot(u) - coulomb) / coulomb : 0;
    rows.push_back({1.0 / g, double(g), err, ok});
  }
  return rows;
}

// (a) Time step: a held object sliding down (m g = 2 · 2 μ N), final position
// at t = 0.2 s against z = -a t²/2 with a = g - 2 μ N / m.
std::vector<Row> DtSweep() {
  std::vector<Row> rows;
  const double mu = 0.5, grip = 10.0, g = 9.81;
  const double mass = 2.0 * 2 * mu * grip / g;
  const double acc = g - 2 * mu * grip / mass;
  for (double dt : {0.008, 0.004, 0.002, 0.001, 0.0005, 0.00025}) {
    m::Scene s = m::testing::HeldBox(mass, grip, mu);
    s.model.dt = dt;
    const m::SimulationResult r = m::Simulate(s);
    const bool ok = r.status == m::SimulationStatus::kOk;
    double err = 0;
    if (ok) {
      const auto& last = r.samples.back();
      const double exact = -0.5 * acc * last.t * last.t;
      err = std::abs(last.position.z() - exact) / std::abs(exact);
    }
    rows.push_back({dt, dt, err, ok});
  }
  return rows;
}

// (c) Time step: a pivoting push on two point fingers turns the object at
// ω = v / d once the fingers stick. The pusher starts at full speed (a
// velocity step), so the first step must bring the object from rest to ω in
// one dt: an impulse I ω / d spread over dt, a force that grows as 1/dt. Below
// dt ≈ 1.3 ms (grip 10 N) that force leaves the fingers' friction cone, the
// fingers slip during the first steps and the object lags v t / d by a fixed
// angle: the rigid-body limit (dt → 0) of a velocity step is an impact, not
// the sticking closed form. So the sweep reports, per dt: the final angle
// against (v/d) t with grip 10 N (the validation case, start slip included),
// whether the first step slipped, the turning rate over the second half
// (after the start) against v/d, and the final angle with grip 1000 N (a
// hundred times the friction: the start sticks at every dt listed).
struct PivotRow {
  double dt;
  bool ok;
  double final_error;   // grip 10 N, |angle - (v/d) t| / ((v/d) t)
  bool start_slipped;   // grip 10 N, a finger slid in the first step
  double rate_error;    // grip 10 N, angle gained over t in [T/2, T] against (v/d) T/2
  double strong_error;  // grip 1000 N, final angle error
};

std::vector<PivotRow> PivotDtSweep() {
  std::vector<PivotRow> rows;
  const double d = 0.02, v = 0.02;
  // Final angle error; also the first step's slip and the angle at T/2.
  auto run = [&](double dt, double grip, bool* slipped, double* half_error) {
    m::Scene s = m::testing::HeldBox(0.2, grip, 0.5);
    s.pusher = Pusher({0, -0.015, -d}, {0, 1, 0}, {0, v, 0}, 0.3);
    s.model.dt = dt;
    m::ContactModel model(s);
    const int steps = static_cast<int>(std::lround(s.duration / dt));
    double half_angle = 0, half_time = 0;
    for (int i = 0; i < steps; ++i) {
      if (!model.Step().ok) return -1.0;
      if (i == 0 && slipped) {
        *slipped = model.contacts()[0].mode == m::ContactMode::kSlide ||
                   model.contacts()[1].mode == m::ContactMode::kSlide;
      }
      if (i + 1 == steps / 2) {
        half_angle = Eigen::AngleAxisd(model.orientation()).angle();
        half_time = model.time();
      }
    }
    const double angle = Eigen::AngleAxisd(model.orientation()).angle();
    if (half_error) {
      const double gained = v / d * (model.time() - half_time);
      *half_error = std::abs((angle - half_angle) - gained) / gained;
    }
    const double exact = v / d * model.time();
    return std::abs(angle - exact) / exact;
  };
  for (double dt : {0.008, 0.004, 0.002, 0.001, 0.0005, 0.00025, 0.000125}) {
    PivotRow row{dt, true, 0, false, 0, 0};
    row.final_error = run(dt, 10.0, &row.start_slipped, &row.rate_error);
    row.strong_error = run(dt, 1000.0, nullptr, nullptr);
    row.ok = row.final_error >= 0 && row.strong_error >= 0;
    rows.push_back(row);
  }
  return rows;
}

void PrintPivotTable(const std::vector<PivotRow>& rows) {
  std::printf(
      "| dt (s) | final angle error, grip 10 N | first step slips | rate error after the start | "
      "final angle error, grip 1000 N |\n|---:|---:|:---:|---:|---:|\n");
  for (const PivotRow& r : rows) {
    if (!r.ok) {
      std::printf("| %g | solver failure | | | |\n", r.dt);
      continue;
    }
    std::printf("| %g | %.3e | %s | %.1e | %.1e |\n", r.dt, r.final_error,
                r.start_slipped ? "yes" : "no", r.rate_error, r.strong_error);
  }
  std::printf("\n");
}

}  // namespace

int main() {
  std::printf("### Friction cone facets: bisector resistance vs Coulomb (validation case d)\n\n");
  PrintTable("facets g", FacetsSweep());
  std::printf("### Time step: sliding held object, final position vs -a t^2/2 (case a)\n\n");
  PrintTable("dt (s)", DtSweep());
  std::printf("### Time step: pivoting push, final angle vs (v/d) t (case c)\n\n");
  PrintPivotTable(PivotDtSweep());
  return 0;
}
