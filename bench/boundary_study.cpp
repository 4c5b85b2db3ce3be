// Boundary sampler vs the grid, on the same simulated cells (bench/README.md,
// "Adaptive boundary sampling").
//
// The "cell" is what `arena cell` runs: the trial's scene with the cell's
// defect profile (friction scale, per-trial variability, actuation noise drawn
// from the trial's seed) at the cell's fidelity (>= 16 facets, 5 points,
// dt <= 2 ms). The reference boundary is the class change on a dense grid
// (D x D points); an estimate's boundary is that of the 1-nearest-neighbour
// classifier of its samples on the same dense grid. Accuracy: the Hausdorff
// distance between the two boundary point sets, in the unit square.
//
// For each resolution the adaptive campaign is run to its stop (rounds of
// `batch`), its Hausdorff distance measured, and the smallest L x L grid
// whose Hausdorff distance is no larger is found: the trial ratio is the
// figure of merit (target: adaptive <= 25 % of the grid's trials).
//
//   boundary_study [CAMPAIGN.json] [--dense D] [--batch B] [--cell-defects FILE]
//                  [--resolutions 0.125,0.0625] [--threads N] [--coarse L] [--max-grid M]
//                  [--cache FILE] [--batches 1,2,4]
// --batches: run every resolution at each of these batch sizes (instead of
// --batch) and add a summary per resolution: median and range over the runs
// of the trials, the Hausdorff distance and the ratio, and how many runs
// meet 25 %. The distance is a maximum on the dense lattice, so one run
// moves by a lattice step with the luck of one sample; the median over
// several batch sizes (different but equally valid sequences) does not.
// Each resolution is run with synchronous rounds and with pipelined ones
// (round k+1 decided from rounds <= k-1, round k pending: adaptive.hpp).
// Grids: every L x L from 3 up to M (default 33; points off the reference
// lattice are simulated too), and beyond M those on the lattice ((D - 1)
// divisible by (L - 1)). The comparison takes the smallest grid at least
// as accurate (the grids' distance is not monotone in L: the harshest
// comparison for the adaptive sampler).
// --cache FILE: the cell's class by point, read before the run and written
// after it. Only for re-runs with the SAME campaign and cell profile (the
// cell is deterministic for a given point; the file does not record which
// campaign it was): a re-run that only changes the sampler or the
// resolutions then skips the ~14,000 simulations of the reference and the
// grids (90 s -> < 1 s on this machine).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "arena/executors/defects.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/adaptive.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/outcome.hpp"

namespace {

using arena::orchestrator::Campaign;
using Point = std::vector<double>;

struct Cell {
  const Campaign& campaign;
  arena::executors::DefectProfile defects;
  std::map<Point, bool> cache;
  int simulations = 0;

  bool Classify(const Point& u) {
    if (auto it = cache.find(u); it != cache.end()) return it->second;
    // Condition index from the point, so a grid point and an adaptive point
    // at the same place are the same trial (same seed, same perturbation).
    std::int64_t key = 0;
    for (double x : u) key = key * 100003 + std::llround(x * 100000);
    const auto trial = arena::orchestrator::PlanTrialAt(campaign, u, 0, key, 0);
    const auto p = arena::executors::DrawPerturbation(defects, trial.seed, 1);
    arena::mechanics::Scene s = arena::executors::ApplyPerturbation(trial.scene, p);
    s.model.facets = std::max(s.model.facets, 16);
    s.model.points = std::max(s.model.points, 5);
    s.model.dt = std::min(s.model.dt, 0.002);
    const auto r = arena::mechanics::Simulate(s);
    ++simulations;
    const auto o =
        arena::orchestrator::ComputeOutcome(r.samples, static_cast<int>(s.fingers.size()));
    const bool cls =
        arena::orchestrator::Classify(campaign.adaptive->outcome, campaign.adaptive->threshold, o);
    cache[u] = cls;
    return cls;
  }
};

// Boundary points of a class field on a D x D grid: midpoints of 4-neighbours
// that differ.
std::vector<Point> BoundaryOf(const std::vector<std::vector<bool>>& cls) {
  const int d = static_cast<int>(cls.size());
  std::vector<Point> out;
  const double h = 1.0 / (d - 1);
  for (int i = 0; i < d; ++i)
    for (int j = 0; j < d; ++j) {
      if (i + 1 < d && cls[i][j] != cls[i + 1][j]) out.push_back({(i + 0.5) * h, j * h});
      if (j + 1 < d && cls[i][j] != cls[i][j + 1]) out.push_back({i * h, (j + 0.5) * h});
    }
  return out;
}

double Hausdorff(const std::vector<Point>& a, const std::vector<Point>& b) {
  if (a.empty() || b.empty()) return a.empty() && b.empty() ? 0 : INFINITY;
  auto directed = [](const std::vector<Point>& x, const std::vector<Point>& y) {
    double worst = 0;
    for (const auto& p : x) {
      double best = INFINITY;
      for (const auto& q : y) best = std::min(best, std::hypot(p[0] - q[0], p[1] - q[1]));
      worst = std::max(worst, best);
    }
    return worst;
  };
  return std::max(directed(a, b), directed(b, a));
}

std::vector<std::vector<bool>> NearestNeighbourField(
    const std::vector<arena::orchestrator::LabelledPoint>& samples, int d) {
  std::vector<std::vector<bool>> cls(d, std::vector<bool>(d));
  for (int i = 0; i < d; ++i)
    for (int j = 0; j < d; ++j) {
      const double x = static_cast<double>(i) / (d - 1), y = static_cast<double>(j) / (d - 1);
      double best = INFINITY;
      for (const auto& s : samples) {
        const double dist = std::hypot(s.u[0] - x, s.u[1] - y);
        if (dist < best) {
          best = dist;
          cls[i][j] = s.positive;
        }
      }
    }
  return cls;
}

// One adaptive campaign to its stop, with the orchestrator's round policy
// (adaptive.cpp, DecideRound): round 1 from round 0; pipelined, round r >= 2
// first from rounds <= r-2 with round r-1 pending (its points asked, not yet
// evidence), and from rounds <= r-1 only when that adds nothing; the sampler
// stops when a decision from every round adds nothing.
struct Adaptive {
  std::vector<arena::orchestrator::LabelledPoint> samples;
  int rounds = 0;
};

Adaptive RunAdaptive(Cell& cell, double res, int batch, int coarse_levels, bool pipelined) {
  using arena::orchestrator::LabelledPoint;
  std::vector<std::vector<LabelledPoint>> rounds;  // rounds[r]: its points, labelled
  std::int64_t id = 0;
  rounds.emplace_back();
  for (const auto& u : arena::orchestrator::CoarseGrid(2, coarse_levels))
    rounds[0].push_back({u, cell.Classify(u), ++id});
  auto known = [&](int through) {
    std::vector<LabelledPoint> k;
    for (int r = 0; r <= through; ++r) k.insert(k.end(), rounds[r].begin(), rounds[r].end());
    return k;
  };
  for (;;) {
    const int r = static_cast<int>(rounds.size());
    std::vector<arena::orchestrator::BoundaryProposal> p;
    if (pipelined && r >= 2) {
      std::vector<Point> pending;
      for (const auto& q : rounds[r - 1]) pending.push_back(q.u);
      p = arena::orchestrator::ProposeBoundaryPoints(known(r - 2), pending, 2, res, batch);
    }
    if (p.empty()) p = arena::orchestrator::ProposeBoundaryPoints(known(r - 1), {}, 2, res, batch);
    if (p.empty()) break;
    rounds.emplace_back();
    for (const auto& q : p) rounds.back().push_back({q.u, cell.Classify(q.u), ++id});
  }
  return {known(static_cast<int>(rounds.size()) - 1), static_cast<int>(rounds.size()) - 1};
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

int main(int argc, char** argv) {
  std::string campaign_path =
      std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/closed_loop.json";
  std::string defects_path = std::string(ARENA_SOURCE_DIR) + "/examples/defects/friction_high.json";
  int dense = 33, batch = 4, threads = 2, coarse_levels = 0, max_grid = 33;
  std::vector<int> batches;
  bool map = false;
  std::string cache_path;
  std::vector<double> resolutions = {0.125, 0.0625};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--dense" && i + 1 < argc) {
      dense = std::stoi(argv[++i]);
    } else if (a == "--threads" && i + 1 < argc) {
      threads = std::max(1, std::stoi(argv[++i]));
    } else if (a == "--cache" && i + 1 < argc) {
      cache_path = argv[++i];
    } else if (a == "--map") {
      map = true;
    } else if (a == "--max-grid" && i + 1 < argc) {
      max_grid = std::stoi(argv[++i]);
    } else if (a == "--coarse" && i + 1 < argc) {
      coarse_levels = std::stoi(argv[++i]);
    } else if (a == "--batch" && i + 1 < argc) {
      batch = std::stoi(argv[++i]);
    } else if (a == "--batches" && i + 1 < argc) {
      std::stringstream in(argv[++i]);
      std::string b;
      while (std::getline(in, b, ',')) batches.push_back(std::max(1, std::stoi(b)));
    } else if (a == "--cell-defects" && i + 1 < argc) {
      defects_path = argv[++i];
    } else if (a == "--resolutions" && i + 1 < argc) {
      resolutions.clear();
      std::stringstream in(argv[++i]);
      std::string r;
      while (std::getline(in, r, ',')) resolutions.push_back(std::stod(r));
    } else {
      campaign_path = a;
    }
  }
  const Campaign campaign = arena::orchestrator::LoadCampaignFile(campaign_path);
  if (!campaign.adaptive || arena::orchestrator::SampledVariations(campaign).size() != 2) {
    std::fprintf(stderr, "boundary_study: needs a 2-D boundary campaign\n");
    return 2;
  }
  // 0: per resolution, as the orchestrator chooses (DefaultCoarseLevels).
  if (coarse_levels < 2) coarse_levels = campaign.adaptive->coarse_levels;
  Cell cell{campaign, arena::executors::ParseDefectProfile(ReadFile(defects_path)), {}, 0};
  const auto start = std::chrono::steady_clock::now();
  if (!cache_path.empty()) {
    // One point a line: u0 u1 class (%.17g: the doubles round-trip exactly,
    // so a point read back is the same key as the point computed).
    std::ifstream in(cache_path);
    double a = 0, b = 0;
    int c = 0;
    while (in >> a >> b >> c) cell.cache[{a, b}] = c != 0;
  }

  // Reference: the dense grid, simulated on `threads` threads (the results
  // go into the cell's cache: every grid and adaptive point below lies on
  // this lattice when dense - 1 is a power of two and the resolutions are
  // 2 / (dense - 1) times powers of two).
  // Simulates the points not yet known on `threads` threads (results into
  // the cell's cache).
  auto prefetch = [&](const std::vector<Point>& points) {
    std::vector<Point> unclassified;
    for (const auto& u : points)
      if (!cell.cache.count(u)) unclassified.push_back(u);
    std::vector<Cell> workers(static_cast<size_t>(threads), Cell{campaign, cell.defects, {}, 0});
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t)
      pool.emplace_back([&, t] {
        for (size_t k = static_cast<size_t>(t); k < unclassified.size();
             k += static_cast<size_t>(threads))
          workers[static_cast<size_t>(t)].Classify(unclassified[k]);
      });
    for (auto& th : pool) th.join();
    for (auto& w : workers) {
      cell.cache.insert(w.cache.begin(), w.cache.end());
      cell.simulations += w.simulations;
    }
  };
  std::vector<std::vector<bool>> ref(dense, std::vector<bool>(dense));
  {
    std::vector<Point> all;
    for (int i = 0; i < dense; ++i)
      for (int j = 0; j < dense; ++j)
        all.push_back({static_cast<double>(i) / (dense - 1), static_cast<double>(j) / (dense - 1)});
    prefetch(all);
  }
  for (int i = 0; i < dense; ++i)
    for (int j = 0; j < dense; ++j)
      ref[i][j] = cell.Classify(
          {static_cast<double>(i) / (dense - 1), static_cast<double>(j) / (dense - 1)});
  const auto ref_boundary = BoundaryOf(ref);
  int positives = 0;
  for (const auto& row : ref)
    positives += static_cast<int>(std::count(row.begin(), row.end(), true));
  std::printf("campaign %s, cell profile %s\n", campaign_path.c_str(), defects_path.c_str());
  std::printf("reference: %d x %d grid, %d of %d points '%s', %zu boundary points (%.1f s)\n",
              dense, dense, positives, dense * dense,
              arena::orchestrator::ClassName(campaign.adaptive->outcome, true), ref_boundary.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());

  if (map) {  // the reference field, first dimension across, '#' = positive
    for (int j = dense - 1; j >= 0; --j) {
      for (int i = 0; i < dense; ++i) std::putchar(ref[i][j] ? '#' : '.');
      std::putchar('\n');
    }
  }
  // Grids L x L: every L up to max_grid (points off the reference lattice
  // are simulated too), and the lattice's own divisors beyond.
  auto grid_points = [](int l) {
    std::vector<Point> g;
    for (int i = 0; i < l; ++i)
      for (int j = 0; j < l; ++j)
        g.push_back({static_cast<double>(i) / (l - 1), static_cast<double>(j) / (l - 1)});
    return g;
  };
  std::vector<int> sides;
  for (int l = 3; l <= dense; ++l)
    if (l <= max_grid || (dense - 1) % (l - 1) == 0) sides.push_back(l);
  {
    std::vector<Point> all;
    for (int l : sides)
      for (const auto& u : grid_points(l)) all.push_back(u);
    prefetch(all);
  }
  std::vector<std::pair<int, double>> grids;
  for (int l : sides) {
    std::vector<arena::orchestrator::LabelledPoint> samples;
    for (int i = 0; i < l; ++i)
      for (int j = 0; j < l; ++j) {
        const Point u = {static_cast<double>(i) / (l - 1), static_cast<double>(j) / (l - 1)};
        samples.push_back({u, cell.Classify(u), 0});
      }
    grids.emplace_back(l,
                       Hausdorff(ref_boundary, BoundaryOf(NearestNeighbourField(samples, dense))));
  }

  std::printf("\n| grid | trials | Hausdorff |\n|---|---|---|\n");
  for (const auto& [l, gh] : grids) std::printf("| %d x %d | %d | %.4f |\n", l, l, l * l, gh);
  // The grids' Hausdorff distance is not monotone in L (a boundary point
  // can fall between samples of a finer grid); "as accurate" below is the
  // smallest grid at least as accurate.
  std::printf(
      "\n| resolution | rounds policy | adaptive trials | rounds | Hausdorff | smallest grid as "
      "accurate "
      "| grid trials | ratio |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  if (batches.empty()) batches.push_back(batch);
  struct Run {
    double trials, hausdorff, ratio;  // ratio: +infinity when no grid is as accurate
  };
  std::map<double, std::vector<Run>> runs;
  for (double res : resolutions)
    for (const int b : batches)
      for (const bool pipelined : {false, true}) {
        const int levels =
            coarse_levels >= 2 ? coarse_levels : arena::orchestrator::DefaultCoarseLevels(2, res);
        const Adaptive run = RunAdaptive(cell, res, b, levels, pipelined);
        const auto& samples = run.samples;
        const double h = Hausdorff(ref_boundary, BoundaryOf(NearestNeighbourField(samples, dense)));
        int grid_l = -1;
        double grid_h = 0;
        for (const auto& [l, gh] : grids) {
          if (gh <= h + 1e-12) {
            grid_l = l;
            grid_h = gh;
            break;
          }
        }
        const std::string mode = std::string(pipelined ? "pipelined" : "sync") + ", coarse " +
                                 std::to_string(levels) + ", batch " + std::to_string(b);
        const double trials = static_cast<double>(samples.size());
        runs[res].push_back(
            {trials, h, grid_l < 0 ? INFINITY : 100.0 * trials / (grid_l * grid_l)});
        if (grid_l < 0) {
          std::printf("| %.3f | %s | %zu | %d | %.4f | none up to %d x %d | - | - |\n", res,
                      mode.c_str(), samples.size(), run.rounds, h, dense, dense);
        } else {
          std::printf("| %.3f | %s | %zu | %d | %.4f | %d x %d (Hausdorff %.4f) | %d | %.0f %% |\n",
                      res, mode.c_str(), samples.size(), run.rounds, h, grid_l, grid_l, grid_h,
                      grid_l * grid_l,
                      100.0 * static_cast<double>(samples.size()) / (grid_l * grid_l));
        }
      }
  if (batches.size() > 1) {
    auto median_range = [](std::vector<double> v, const char* format) {
      std::sort(v.begin(), v.end());
      const size_t n = v.size();
      const double median = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
      char text[96];
      std::snprintf(text, sizeof text, format, median, v.front(), v.back());
      return std::string(text);
    };
    std::printf(
        "\n| resolution | adaptive trials, median (range) | Hausdorff, median (range) | ratio to "
        "the grid, median (range) | runs <= 25 %% |\n|---|---|---|---|---|\n");
    for (const auto& [res, v] : runs) {
      std::vector<double> trials, hausdorff, ratio;
      int meet = 0;
      for (const auto& r : v) {
        trials.push_back(r.trials);
        hausdorff.push_back(r.hausdorff);
        ratio.push_back(r.ratio);
        meet += r.ratio <= 25.0;
      }
      std::printf("| %.4g | %s | %s | %s | %d of %zu |\n", res,
                  median_range(trials, "%.0f (%.0f-%.0f)").c_str(),
                  median_range(hausdorff, "%.3f (%.3f-%.3f)").c_str(),
                  median_range(ratio, "%.0f %% (%.0f-%.0f)").c_str(), meet, v.size());
    }
  }
  if (!cache_path.empty()) {
    std::ofstream out(cache_path);
    char line[96];
    for (const auto& [u, positive] : cell.cache) {
      std::snprintf(line, sizeof line, "%.17g %.17g %d\n", u[0], u[1], positive ? 1 : 0);
      out << line;
    }
    if (!out) std::fprintf(stderr, "boundary_study: could not write %s\n", cache_path.c_str());
  }
  std::printf("\n%d distinct cell simulations, %.1f s\n", cell.simulations,
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  return 0;
}
