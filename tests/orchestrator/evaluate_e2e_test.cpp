// End to end: a small campaign run by `arena run --cells 1` (a real service
// and cell over DDS on a test-unique domain), then `arena evaluate` at two
// fidelity settings: the run and its per-trial results are in the store,
// the JSON report names both settings; `arena plot --tradeoff` draws it.
#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include "service_support.hpp"

namespace arena::test {
namespace {

TEST(EvaluateEndToEnd, TwoSettingsStoredReportedAndPlotted) {
  TempDir dir;
  const std::string db = dir / "eval.db";
  ASSERT_EQ(RunArena({"run", TestCampaign("eval6.json"), "--db", db, "--cells", "1", "--domain",
                      std::to_string(TestDomain(7)), "--quiet"},
                     dir / "run.out", std::chrono::seconds(120)),
            0)
      << ReadFile(dir / "run.out") << ReadFile(db + ".log");
  ASSERT_EQ(CountStates(db, 1).at("done"), 6);

  const int rc = RunArena({"evaluate", "--db", db, "--campaign", "1", "--facets", "4,8", "--points",
                           "2", "--dt", "0.004", "--budget", "50mm", "--threads", "2", "--json"},
                          dir / "evaluate.json", std::chrono::seconds(60));
  ASSERT_EQ(rc, 0) << ReadFile(dir / "evaluate.json");
  const auto report = nlohmann::json::parse(ReadFile(dir / "evaluate.json"));
  EXPECT_EQ(report["trials"], 6);
  ASSERT_EQ(report["settings"].size(), 2u);
  EXPECT_EQ(report["settings"][0]["model_key"], "g4_k2_dt0.004_auto_cone-aligned_inertia-auto");
  EXPECT_EQ(report["settings"][1]["model_key"], "g8_k2_dt0.004_auto_cone-aligned_inertia-auto");
  for (const auto& s : report["settings"]) {
    EXPECT_EQ(s["trials"], 6);
    EXPECT_EQ(s["ok"], 6) << s.dump();
    EXPECT_GE(s["position_error_m"]["p95"].get<double>(),
              s["position_error_m"]["median"].get<double>());
    EXPECT_GT(s["time_s"]["median"].get<double>(), 0);
  }
  // The cells ran the model: the report says its truth is self-consistency.
  EXPECT_EQ(report["truth"]["source"], "model");
  EXPECT_EQ(report["truth"]["independent"], false);
  EXPECT_NE(report["truth"]["statement"].get<std::string>().find(
                "the truth is the model at the cell's settings (self-consistency, not accuracy)"),
            std::string::npos)
      << report["truth"].dump();
  // The sim cell's pushes are small: a 50 mm budget holds, so one is recommended.
  ASSERT_TRUE(report["recommended"].is_string()) << report.dump(2);

  auto store = OpenReadOnly(db);
  const auto runs = store->ListEvaluations(1);
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].id, report["evaluation_id"].get<std::int64_t>());
  const auto rows = store->ListEvaluationResults(runs[0].id);
  EXPECT_EQ(rows.size(), 12u);  // 6 trials x 2 settings
  for (const auto& r : rows)
    EXPECT_EQ(r.prediction.status, db::PredictionStatus::kOk) << r.prediction.detail_json;
  // Evaluating changed no trial.
  EXPECT_EQ(CountStates(db, 1).at("done"), 6);
  EXPECT_TRUE(store->CheckInvariants().empty());

  // The table form, and the plot of the latest run.
  ASSERT_EQ(
      RunArena({"evaluate", "--db", db, "--campaign", "1", "--facets", "4", "--points", "2,3"},
               dir / "evaluate.txt", std::chrono::seconds(60)),
      0);
  const std::string table = ReadFile(dir / "evaluate.txt");
  EXPECT_NE(table.find("g4_k3_dt0.004_auto"), std::string::npos) << table;
  EXPECT_NE(table.find("recommendation:"), std::string::npos) << table;
  EXPECT_NE(table.find("self-consistency, not accuracy"), std::string::npos) << table;
  EXPECT_NE(table.find("noise floor"), std::string::npos) << table;
  ASSERT_EQ(RunArena({"plot", "--db", db, "--campaign", "1", "--tradeoff", "--out", dir / "t.svg"},
                     dir / "plot.out", std::chrono::seconds(20)),
            0)
      << ReadFile(dir / "plot.out");
  const std::string svg = ReadFile(dir / "t.svg");
  EXPECT_NE(svg.find("data-name=\"pareto front\""), std::string::npos);

  // Bad input: exit 2 with the reason.
  EXPECT_EQ(RunArena({"evaluate", "--db", db, "--campaign", "1", "--budget", "1kg"},
                     dir / "bad.out", std::chrono::seconds(20)),
            2);
  EXPECT_NE(ReadFile(dir / "bad.out").find("unknown unit"), std::string::npos)
      << ReadFile(dir / "bad.out");
  EXPECT_EQ(RunArena({"evaluate", "--db", db, "--campaign", "9"}, dir / "none.out",
                     std::chrono::seconds(20)),
            2);
}

}  // namespace
}  // namespace arena::test
