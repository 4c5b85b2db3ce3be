// End to end: a small pivot campaign run by `arena run --cells 2` (a real
// service and cells over DDS), then `arena sensitivity --db --campaign`: the
// per-condition report (predicted vs observed spread, unstable flags) is
// stored, queryable and exported; `arena plot --map` draws it (parsed here).
#include <tinyxml2.h>

#include <filesystem>

#include <nlohmann/json.hpp>

#include <sstream>

#include <gtest/gtest.h>

#include "arena/db/sensitivity.hpp"
#include "orchestrator/service_support.hpp"

namespace arena::test {
namespace {

std::string Campaign() {
  return std::string(ARENA_SOURCE_DIR) + "/tests/assessment/data/pivot_small.json";
}

TEST(SensitivityEndToEnd, PivotCampaignReportStoredQueriedExportedAndMapped) {
  TempDir dir;
  const std::string db = dir / "pivot.db";
  // The campaign's profile (the lab's actuation and friction noise) travels
  // with each command; the cells apply it and record it; the ensemble draws
  // from what they recorded.
  ASSERT_EQ(RunArena({"run", Campaign(), "--db", db, "--cells", "2", "--domain",
                      std::to_string(TestDomain(18)), "--quiet"},
                     dir / "run.out", std::chrono::seconds(240)),
            0)
      << ReadFile(dir / "run.out") << ReadFile(db + ".log");
  ASSERT_EQ(CountStates(db, 1).at("done"), 24);

  const int rc = RunArena({"sensitivity", "--db", db, "--campaign", "1", "--ensemble", "16",
                           "--seed", "5", "--threads", "2", "--json"},
                          dir / "sens.json", std::chrono::seconds(240));
  ASSERT_EQ(rc, 0) << ReadFile(dir / "sens.json");
  const auto report = nlohmann::json::parse(ReadFile(dir / "sens.json"));
  EXPECT_EQ(report["conditions"], 8);
  ASSERT_EQ(report["condition_rows"].size(), 8u);
  for (const auto& c : report["condition_rows"]) {
    EXPECT_EQ(c["replicates"], 3) << c.dump();
    EXPECT_EQ(c["ensemble"], 16) << c.dump();
    EXPECT_TRUE(c["predicted_position_spread"].is_number()) << c.dump();
    EXPECT_TRUE(c["observed_position_spread"].is_number()) << c.dump();
    EXPECT_NE(c["verdict"], "no_prediction");
  }
  // The cells run arena's own model with the same noise the ensemble draws,
  // and the ensemble starts each run where a reset would have placed the
  // object, as the cells do: the pooled spread must agree (self-consistency,
  // not accuracy).
  EXPECT_EQ(report["pooled_position_verdict"], "matches") << report.dump(2);
  const std::int64_t run_id = report["sensitivity_run_id"].get<std::int64_t>();
  ASSERT_GT(run_id, 0);

  // Stored; a second run with the same seed gives the same rows.
  auto store = OpenReadOnly(db);
  const auto rows = db::ListSensitivityConditions(*store, run_id);
  ASSERT_EQ(rows.size(), 8u);
  EXPECT_TRUE(store->CheckInvariants().empty());
  // Each condition's ensemble drew the start pose from the reset parameters
  // the cells recorded (the default 0.2 mm placement accuracy).
  for (const auto& r : rows) {
    const auto start = nlohmann::json::parse(r.detail_json)["start_pose"];
    EXPECT_TRUE(start["drawn"].get<bool>()) << r.detail_json;
    EXPECT_DOUBLE_EQ(start["placement_position_std"].get<double>(), 2e-4) << r.detail_json;
  }
  ASSERT_EQ(RunArena({"sensitivity", "--db", db, "--campaign", "1", "--ensemble", "16", "--seed",
                      "5", "--threads", "1"},
                     dir / "sens2.txt", std::chrono::seconds(240)),
            0)
      << ReadFile(dir / "sens2.txt");
  EXPECT_NE(ReadFile(dir / "sens2.txt").find("unstable conditions:"), std::string::npos);
  // Issue 26: the table named each condition by its index alone ("cond 3"),
  // then by the campaign file's SI numbers. Pins: every row names its
  // condition's varied parameters, in N and mm.
  {
    std::istringstream table(ReadFile(dir / "sens2.txt"));
    std::string row;
    int named = 0;
    while (std::getline(table, row))
      if (row.find("grip_force=") != std::string::npos && row.find(" N, ") != std::string::npos &&
          row.find("pivot_offset=") != std::string::npos && row.find(" mm") != std::string::npos)
        ++named;
    EXPECT_EQ(named, 8) << ReadFile(dir / "sens2.txt");
  }
  const auto again = db::ListSensitivityConditions(*OpenReadOnly(db), run_id + 1);
  ASSERT_EQ(again.size(), rows.size());
  for (size_t i = 0; i < rows.size(); ++i) {
    EXPECT_EQ(again[i].predicted_position_spread, rows[i].predicted_position_spread);
    EXPECT_EQ(again[i].unstable, rows[i].unstable);
  }

  // Queryable.
  ASSERT_EQ(RunArena({"query", "--db", db, "--format", "json",
                      "SELECT condition, unstable, verdict FROM sensitivity_latest WHERE "
                      "campaign_id = 1 ORDER BY condition"},
                     dir / "q.json", std::chrono::seconds(20)),
            0)
      << ReadFile(dir / "q.json");
  EXPECT_EQ(nlohmann::json::parse(ReadFile(dir / "q.json")).size(), 8u);

  // Exported beside the trials.
  ASSERT_EQ(RunArena({"export", "--db", db, "--campaign", "1", "--format", "csv", "--out",
                      dir / "export"},
                     dir / "export.out", std::chrono::seconds(60)),
            0)
      << ReadFile(dir / "export.out");
  const std::string csv = ReadFile(dir / "export/sensitivity.csv");
  EXPECT_EQ(csv.rfind("run_id,condition,", 0), 0u) << csv.substr(0, 200);
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 9);  // header + 8 conditions
  EXPECT_NE(ReadFile(dir / "export/manifest.json").find("sensitivity.csv"), std::string::npos);

  // The map: one marker per condition with its flag, labelled axes with units.
  for (const char* metric : {"unstable", "observed_spread", "rotation"}) {
    const std::string svg_path = dir / (std::string(metric) + ".svg");
    ASSERT_EQ(RunArena({"plot", "--db", db, "--campaign", "1", "--map", "grip_force,pivot_offset",
                        "--metric", metric, "--out", svg_path},
                       dir / "plot.out", std::chrono::seconds(20)),
              0)
        << ReadFile(dir / "plot.out");
    tinyxml2::XMLDocument doc;
    ASSERT_EQ(doc.LoadFile(svg_path.c_str()), tinyxml2::XML_SUCCESS) << metric;
    int markers = 0, with_value = 0;
    std::vector<std::string> labels;
    std::function<void(const tinyxml2::XMLElement*)> walk = [&](const tinyxml2::XMLElement* e) {
      for (; e; e = e->NextSiblingElement()) {
        const char* cls = e->Attribute("class");
        if (cls && std::string(cls) == "condition") {
          ++markers;
          with_value += e->Attribute("data-value") != nullptr;
        }
        if (cls && std::string(cls) == "label" && e->GetText()) labels.push_back(e->GetText());
        walk(e->FirstChildElement());
      }
    };
    walk(doc.RootElement());
    EXPECT_EQ(markers, 8) << metric;
    EXPECT_EQ(with_value, 8) << metric;
    ASSERT_EQ(labels.size(), 2u);
    EXPECT_EQ(labels[0], "grip_force (N)");
    EXPECT_EQ(labels[1], "pivot_offset (m)");
  }
  // Bad input: exit 2, naming the problem.
  EXPECT_EQ(RunArena({"plot", "--db", db, "--campaign", "1", "--map", "grip_force,colour",
                      "--metric", "unstable", "--out", dir / "x.svg"},
                     dir / "bad.out", std::chrono::seconds(20)),
            2);
  EXPECT_NE(ReadFile(dir / "bad.out").find("no parameter 'colour'"), std::string::npos)
      << ReadFile(dir / "bad.out");
  EXPECT_EQ(RunArena({"sensitivity", "--db", db, "--campaign", "1", "--ensemble", "1"},
                     dir / "bad2.out", std::chrono::seconds(20)),
            2);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.svg"));
}

TEST(SensitivityCli, SceneReportAndBadInput) {
  TempDir dir;
  const std::string scene = std::string(ARENA_SOURCE_DIR) + "/examples/scenes/canonical.json";
  ASSERT_EQ(RunArena({"sensitivity", scene, "--params", "grip_force,friction,velocity", "--json",
                      "--threads", "2"},
                     dir / "s.json", std::chrono::seconds(120)),
            0)
      << ReadFile(dir / "s.json");
  const auto j = nlohmann::json::parse(ReadFile(dir / "s.json"));
  EXPECT_TRUE(j["nominal"]["ok"].get<bool>());
  EXPECT_GE(j["parameters"].size(), 6u);
  EXPECT_TRUE(j["stability"]["unstable"].is_boolean());
  EXPECT_EQ(RunArena({"sensitivity", scene, "--params", "nonsense"}, dir / "b.out",
                     std::chrono::seconds(20)),
            2);
  EXPECT_NE(ReadFile(dir / "b.out").find("'nonsense' matches no parameter"), std::string::npos);
  EXPECT_EQ(RunArena({"sensitivity", scene, "--tolerance", "-3%"}, dir / "c.out",
                     std::chrono::seconds(20)),
            2);
  EXPECT_EQ(RunArena({"sensitivity"}, dir / "d.out", std::chrono::seconds(20)), 2);
}

}  // namespace
}  // namespace arena::test
