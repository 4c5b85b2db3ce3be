// Wall time of whole model runs of scene files at their own settings (a
// study: prints one Markdown row per scene). The steps alone are timed, not
// parsing or set-up; each scene runs `--runs` times and the fastest and the
// median run are printed. `--cone polyhedral|aligned` overrides the scenes'
// cone, `--inertia carried|quasi_static|auto` their inertia; `--counts` adds
// one run's solver work (Lemke pivots, the aligned cones' and the balance's
// extra solves, the quasi-static steps carried). Written against ContactModel's oldest
// API (construct, Step(), ok, error) so that the same file builds against an older commit's
// mechanics library and compares it with today's in one sitting (bench/README.md, "Steered slip and
// the defaults' cost").
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "arena/mechanics/model.hpp"
#include "arena/mechanics/scene_json.hpp"

namespace {

using arena::mechanics::ContactModel;
using arena::mechanics::Scene;

int Usage() {
  std::fprintf(stderr,
               "usage: scene_timing [--runs N] [--cone polyhedral|aligned] "
               "[--inertia carried|quasi_static|auto] [--counts] SCENE.json...\n");
  return 2;
}

// Milliseconds of each of `runs` runs of the scene's steps; empty when a
// step fails (the reason printed).
std::vector<double> TimeRuns(const Scene& scene, int runs) {
  const long steps = std::max(1L, std::lround(scene.duration / scene.model.dt));
  std::vector<double> ms;
  for (int r = 0; r < runs; ++r) {
    ContactModel model(scene);
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = 0; k < steps; ++k) {
      const auto report = model.Step();
      if (!report.ok) {
        std::fprintf(stderr, "step %ld: %s\n", k, report.error.c_str());
        return {};
      }
    }
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms;
}

#ifdef ARENA_SCENE_TIMING_CONE
// One run's solver work, as Markdown cells: Lemke pivots, the aligned cones'
// extra solves, the balance's extra solves and the steps it carried.
std::string CountRun(const Scene& scene) {
  const long steps = std::max(1L, std::lround(scene.duration / scene.model.dt));
  ContactModel model(scene);
  long pivots = 0, align = 0, balance = 0, carried = 0;
  for (long k = 0; k < steps; ++k) {
    const auto report = model.Step();
    if (!report.ok) return " failed | | | |";
    pivots += report.pivots;
    align += report.align_solves;
    balance += report.quasi_static_solves;
    carried += report.quasi_static_carried;
  }
  char row[128];
  std::snprintf(row, sizeof row, " %ld | %ld | %ld | %ld |", pivots, align, balance, carried);
  return row;
}
#endif

}  // namespace

int main(int argc, char** argv) {
  int runs = 40;
  std::string cone, inertia;
  bool counts = false;
  std::vector<std::string> files;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
      runs = std::atoi(argv[++i]);
    } else if (std::strcmp(argv[i], "--cone") == 0 && i + 1 < argc) {
      cone = argv[++i];
    } else if (std::strcmp(argv[i], "--inertia") == 0 && i + 1 < argc) {
      inertia = argv[++i];
    } else if (std::strcmp(argv[i], "--counts") == 0) {
      counts = true;
    } else if (argv[i][0] == '-') {
      return Usage();
    } else {
      files.emplace_back(argv[i]);
    }
  }
  if (files.empty() || runs < 1 || runs > 100000) return Usage();
  if (!inertia.empty() && inertia != "carried" && inertia != "quasi_static" && inertia != "auto")
    return Usage();
#ifndef ARENA_SCENE_TIMING_CONE
  if (counts) {
    std::fprintf(stderr, "--counts: this build's model does not report them\n");
    return 2;
  }
#endif
  std::printf(
      "| scene | cone | inertia | steps | fastest ms | median ms "
      "|%s\n|---|---|---|---|---|---|%s\n",
      counts ? " pivots | align solves | balance solves | carried |" : "",
      counts ? "---|---|---|---|" : "");
  for (const std::string& file : files) {
    Scene scene;
    try {
      scene = arena::mechanics::LoadSceneFile(file);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "%s: %s\n", file.c_str(), e.what());
      return 2;
    }
    if (!cone.empty() && cone != "aligned" && cone != "polyhedral") return Usage();
#ifdef ARENA_SCENE_TIMING_CONE
    if (cone == "aligned") scene.model.cone = arena::mechanics::ConeModel::kAligned;
    if (cone == "polyhedral") scene.model.cone = arena::mechanics::ConeModel::kPolyhedral;
    using arena::mechanics::InertiaModel;
    if (inertia == "carried") scene.model.inertia = InertiaModel::kCarried;
    if (inertia == "quasi_static") scene.model.inertia = InertiaModel::kQuasiStatic;
    if (inertia == "auto") scene.model.inertia = InertiaModel::kAuto;
#else
    // An older library without the choice (built by hand, see the top).
    if (!cone.empty() || !inertia.empty()) {
      std::fprintf(stderr, "--cone, --inertia: this build's model has no such choice\n");
      return 2;
    }
#endif
    const std::vector<double> ms = TimeRuns(scene, runs);
    if (ms.empty()) return 1;
    std::string extra;
#ifdef ARENA_SCENE_TIMING_CONE
    if (counts) extra = CountRun(scene);
#endif
    std::printf("| %s | %s | %s | %ld | %.3f | %.3f |%s\n", file.c_str(),
                cone.empty() ? "scene's" : cone.c_str(),
                inertia.empty() ? "scene's" : inertia.c_str(),
                std::max(1L, std::lround(scene.duration / scene.model.dt)), ms.front(),
                ms[ms.size() / 2], extra.c_str());
  }
  return 0;
}
