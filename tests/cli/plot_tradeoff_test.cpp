// `arena plot --tradeoff`: the chart of an evaluation report parses as SVG
// and carries the settings, the Pareto front and the recommendation.
#include <map>
#include <string>

#include <gtest/gtest.h>
#include <tinyxml2.h>
#include <nlohmann/json.hpp>

#include "plot_charts.hpp"

namespace arena::cli {
namespace {

nlohmann::json Setting(const std::string& key, double err, double time_s, bool pareto,
                       int failures = 0) {
  return {{"model_key", key},
          {"primary_error", err},
          {"time_s", {{"median", time_s}, {"p95", time_s}}},
          {"pareto", pareto},
          {"failures", failures}};
}

// data-name -> number of markers (circles) or polyline points.
std::map<std::string, int> SeriesPoints(const std::string& svg) {
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  std::map<std::string, int> out;
  const auto* root = doc.FirstChildElement("svg");
  if (!root) return out;
  for (const auto* g = root->FirstChildElement("g"); g; g = g->NextSiblingElement("g")) {
    for (const auto* s = g->FirstChildElement("g"); s; s = s->NextSiblingElement("g")) {
      if (!s->Attribute("data-name")) continue;
      int n = 0;
      for (const auto* c = s->FirstChildElement("circle"); c; c = c->NextSiblingElement("circle"))
        ++n;
      for (const auto* p = s->FirstChildElement("polyline"); p;
           p = p->NextSiblingElement("polyline")) {
        const std::string pts = p->Attribute("points") ? p->Attribute("points") : "";
        int pairs = 0;  // "x,y x,y ": one comma per point
        for (char ch : pts) pairs += ch == ',';
        n += pairs;
      }
      out[s->Attribute("data-name")] = n;
    }
  }
  return out;
}

TEST(PlotTradeoff, SvgHasSettingsFrontAndRecommendation) {
  const nlohmann::json report = {
      {"campaign_id", 3},
      {"trials", 10},
      {"primary_metric", "position_median"},
      {"recommended", "g8"},
      {"settings",
       {Setting("g4", 4e-3, 1e-3, true), Setting("g8", 2e-3, 2e-3, true),
        Setting("g16", 3e-3, 3e-3, false), Setting("g32", 1e-3, 8e-3, false, 2),
        Setting("g6", 1e-3, 4e-3, true), Setting("g64", 0.0, 9e-3, false)}}};
  const Chart chart = TradeoffChart(report);
  EXPECT_TRUE(chart.log_x);
  ASSERT_EQ(chart.panels.size(), 1u);
  EXPECT_TRUE(chart.panels[0].log_y);
  EXPECT_NE(chart.title.find("1 settings with zero or no error not shown"), std::string::npos)
      << chart.title;
  const auto points = SeriesPoints(RenderSvg(chart));
  EXPECT_EQ(points.at("settings"), 4);         // g4 g8 g16 g6 (g64 has zero error)
  EXPECT_EQ(points.at("failed settings"), 1);  // g32
  EXPECT_EQ(points.at("recommended"), 1);
  EXPECT_EQ(points.at("pareto front"), 3);  // g4 -> g8 -> g6
  // The front runs by increasing time.
  const auto& front = chart.panels[0].series[2];
  EXPECT_EQ(front.name, "pareto front");
  EXPECT_EQ(front.x, (std::vector<double>{1, 2, 4}));
}

TEST(PlotTradeoff, MalformedReportRefused) {
  EXPECT_THROW(TradeoffChart(nlohmann::json::object()), std::invalid_argument);
  EXPECT_THROW(TradeoffChart(nlohmann::json::array()), std::invalid_argument);
}

}  // namespace
}  // namespace arena::cli
