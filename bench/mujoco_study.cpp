// MuJoCo as ground truth (issue 13), on the scenes of the smoke and pivot
// campaigns (one per condition; the pivot study's first N conditions):
//   1. convergence: final pose at the default settings against 4x finer
//      settings (timestep / 4; solref, impedance and the rest unchanged:
//      they are the contact's physics, not its discretisation), worst and
//      median over the scenes; the target is < 0.1 mm;
//   2. cost: CPU time (this thread) per simulated second of the mujoco simulator and of
//      the `model` backend's settings (arena g16 k5 dt 0.002, at least), and
//      the final-pose difference between the two (the model error a campaign
//      on the mujoco backend measures, at the cell's model settings).
// Prints Markdown tables (bench/README.md, section "MuJoCo as ground truth").
//
//   build/bench/mujoco_study [PIVOT_CONDITIONS=24 [TIMESTEP]]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

#include "arena/orchestrator/campaign.hpp"
#include "arena/simulators/simulator.hpp"

namespace {

using arena::mechanics::Scene;
using arena::mechanics::SimulationResult;
namespace sim = arena::simulators;

// CPU time of this thread (s): on a loaded machine wall time says more about
// the neighbours than about the simulator.
double CpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.angularDistance(b);
}

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Named {
  std::string label;
  Scene scene;
};

std::vector<Named> CampaignScenes(const std::string& file, int max_conditions) {
  const auto c = arena::orchestrator::LoadCampaignFile(std::string(ARENA_SOURCE_DIR) + "/" + file);
  std::vector<Named> out;
  const std::int64_t n = arena::orchestrator::TrialCount(c);
  for (std::int64_t i = 0; i < n && static_cast<int>(out.size()) < max_conditions; ++i) {
    const auto t = arena::orchestrator::PlanTrial(c, i);
    if (t.replicate != 0) continue;
    out.push_back({file + " #" + std::to_string(t.condition) + " " + t.parameters_json, t.scene});
  }
  return out;
}

double g_timestep = 0;  // argv[2]: study another default timestep

void Study(const char* title, const std::vector<Named>& scenes) {
  sim::MujocoSettings defaults;
  if (g_timestep > 0) defaults.timestep = g_timestep;
  sim::MujocoSettings fine = defaults;
  fine.timestep = defaults.timestep / 4;
  const auto mj = sim::MakeMujocoSimulator(defaults);
  const auto mj_fine = sim::MakeMujocoSimulator(fine);
  sim::ArenaSettings cell_model;
  cell_model.facets = 16;
  cell_model.points = 5;
  cell_model.dt = 0.002;
  cell_model.at_least = true;
  const auto model = sim::MakeArenaSimulator(cell_model);

  std::vector<double> dpos, dang, mj_cost, fine_cost, model_cost, gap_pos, gap_ang;
  int failures = 0;
  double simulated = 0;
  for (const auto& s : scenes) {
    const double c0 = CpuSeconds();
    const SimulationResult a = mj->Simulate(s.scene);
    const double c1 = CpuSeconds();
    const SimulationResult b = mj_fine->Simulate(s.scene);
    const double c2 = CpuSeconds();
    const SimulationResult m = model->Simulate(s.scene);
    const double c3 = CpuSeconds();
    if (a.status != arena::mechanics::SimulationStatus::kOk ||
        b.status != arena::mechanics::SimulationStatus::kOk ||
        m.status != arena::mechanics::SimulationStatus::kOk) {
      ++failures;
      std::fprintf(stderr, "%s: failed: %s %s %s\n", s.label.c_str(), a.error.c_str(),
                   b.error.c_str(), m.error.c_str());
      continue;
    }
    const auto &fa = a.samples.back(), &fb = b.samples.back(), &fm = m.samples.back();
    dpos.push_back((fa.position - fb.position).norm());
    if (dpos.back() > 0.05e-3 || AngleBetween(fa.orientation, fb.orientation) > 1e-3)
      std::fprintf(stderr, "not converged: %s: %.4f mm, %.3f mrad\n", s.label.c_str(),
                   dpos.back() * 1e3, AngleBetween(fa.orientation, fb.orientation) * 1e3);
    dang.push_back(AngleBetween(fa.orientation, fb.orientation));
    gap_pos.push_back((fa.position - fm.position).norm());
    gap_ang.push_back(AngleBetween(fa.orientation, fm.orientation));
    mj_cost.push_back((c1 - c0) / s.scene.duration);
    fine_cost.push_back((c2 - c1) / s.scene.duration);
    model_cost.push_back((c3 - c2) / s.scene.duration);
    simulated += s.scene.duration;
  }
  std::printf("\n### %s (%zu scenes, %.2f simulated s, %d failed)\n\n", title, scenes.size(),
              simulated, failures);
  std::printf("| quantity | median | worst |\n|---|---:|---:|\n");
  std::printf("| final position change, default vs timestep/4 (mm) | %.4f | %.4f |\n",
              Median(dpos) * 1e3, *std::max_element(dpos.begin(), dpos.end()) * 1e3);
  std::printf("| final angle change, default vs timestep/4 (mrad) | %.4f | %.4f |\n",
              Median(dang) * 1e3, *std::max_element(dang.begin(), dang.end()) * 1e3);
  std::printf("| MuJoCo CPU s per simulated s (dt %.4g s) | %.4f | %.4f |\n", defaults.timestep,
              Median(mj_cost), *std::max_element(mj_cost.begin(), mj_cost.end()));
  std::printf("| MuJoCo CPU s per simulated s (dt %.4g s) | %.4f | %.4f |\n", fine.timestep,
              Median(fine_cost), *std::max_element(fine_cost.begin(), fine_cost.end()));
  std::printf("| model backend CPU s per simulated s (g16 k5 dt 0.002) | %.4f | %.4f |\n",
              Median(model_cost), *std::max_element(model_cost.begin(), model_cost.end()));
  std::printf("| final position, MuJoCo vs model backend (mm) | %.3f | %.3f |\n",
              Median(gap_pos) * 1e3, *std::max_element(gap_pos.begin(), gap_pos.end()) * 1e3);
  std::printf("| final angle, MuJoCo vs model backend (mrad) | %.3f | %.3f |\n",
              Median(gap_ang) * 1e3, *std::max_element(gap_ang.begin(), gap_ang.end()) * 1e3);
}

}  // namespace

int main(int argc, char** argv) {
  const int pivot_conditions = argc > 1 ? std::atoi(argv[1]) : 24;
  if (argc > 2) g_timestep = std::atof(argv[2]);
  std::printf("MuJoCo %s settings: %s\n", "default",
              sim::MakeMujocoSimulator({})->settings_json().c_str());
  Study("smoke campaign", CampaignScenes("examples/campaigns/smoke.json", 1000));
  Study("pivot study", CampaignScenes("examples/campaigns/pivot_study.json", pivot_conditions));
  return 0;
}
