// Numerical stability at the extremes (issue 7): for every case of the
// mechanics extremes suite (tests/mechanics/extremes_suite.hpp), on both base
// scenes and both reductions, the solve status, the worst residuals over the
// trial and the solver's statistics, as a Markdown table (bench/README.md,
// section "Extremes").
//
//   build/bench/extremes_table
#include <cstdio>
#include <string>

#include "arena/mechanics/simulate.hpp"
#include "extremes_suite.hpp"

namespace m = arena::mechanics;

int main() {
  std::printf(
      "| base | case | reduce | status | steps | max pivots | force balance | complementarity | "
      "cone |\n");
  std::printf("|---|---|---|---|---:|---:|---:|---:|---:|\n");
  int solved = 0, failed = 0, over = 0;
  for (const auto& base : {std::make_pair("canonical", m::testing::CanonicalScene()),
                           std::make_pair("patches", m::testing::PatchScene())}) {
    for (const auto& x : m::testing::Extremes()) {
      for (m::Reduce reduce : {m::Reduce::kAuto, m::Reduce::kFull}) {
        m::Scene s = base.second;
        s.duration = 0.2;  // as in the test
        s.model.reduce = reduce;
        x.apply(s);
        const m::SimulationResult r = m::Simulate(s);
        const bool ok = r.status == m::SimulationStatus::kOk;
        std::string status = ok ? "ok"
                                : std::string(m::ToString(r.status)) + " at step " +
                                      std::to_string(r.failed_step) + ": " + r.error;
        for (auto& ch : status) {
          if (ch == '|') ch = '/';
        }
        const bool within = r.residuals.force_balance < 1e-8 &&
                            r.residuals.complementarity < 1e-8 && r.residuals.cone < 1e-8;
        if (ok)
          (within ? solved : over)++;
        else
          failed++;
        std::printf("| %s | %s | %s | %s | %d | %d | %.1e | %.1e | %.1e |\n", base.first,
                    x.name.c_str(), m::ToString(reduce), status.c_str(), r.solver.steps,
                    r.solver.max_pivots, r.residuals.force_balance, r.residuals.complementarity,
                    r.residuals.cone);
      }
    }
  }
  std::printf("\n%d solved within 1e-8, %d solved above 1e-8, %d typed failures\n", solved, over,
              failed);
  return over == 0 ? 0 : 1;
}
