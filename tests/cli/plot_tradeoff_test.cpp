// `arena plot --tradeoff`: the chart of an evaluation report parses as SVG
// and carries the settings, the Pareto front and the recommendation.
#include <map>
#include <string>
#include <vector>

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

// A setting as reports since issue 14 write it.
nlohmann::json Predicted(const std::string& predictor, const std::string& key, double step,
                         double err, double per_sim_s, bool pareto, int diverged = 0) {
  return {{"predictor", predictor},
          {"model_key", key},
          {"step_s", step},
          {"primary_error", err},
          {"time_s", {{"median", per_sim_s / 5}, {"p95", per_sim_s / 5}}},
          {"time_per_simulated_s", {{"median", per_sim_s}, {"p95", per_sim_s}}},
          {"pareto", pareto},
          {"failures", 0},
          {"diverged", diverged}};
}

// data-name -> the labels of its points.
std::map<std::string, std::vector<std::string>> SeriesLabels(const std::string& svg) {
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  std::map<std::string, std::vector<std::string>> out;
  const auto* root = doc.FirstChildElement("svg");
  if (!root) return out;
  for (const auto* g = root->FirstChildElement("g"); g; g = g->NextSiblingElement("g")) {
    for (const auto* s = g->FirstChildElement("g"); s; s = s->NextSiblingElement("g")) {
      if (!s->Attribute("data-name")) continue;
      auto& labels = out[s->Attribute("data-name")];
      for (const auto* t = s->FirstChildElement("text"); t; t = t->NextSiblingElement("text")) {
        if (t->Attribute("class", "point-label") && t->GetText()) labels.push_back(t->GetText());
      }
    }
  }
  return out;
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

TEST(PlotTradeoff, OldReportsStillDrawSettingsFrontAndRecommendation) {
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
  EXPECT_EQ(points.at("arena"), 4);            // g4 g8 g16 g6 (g64 has zero error)
  EXPECT_EQ(points.at("arena curve"), 3);      // its lower envelope: g4 -> g8 -> g6
  EXPECT_EQ(points.at("failed settings"), 1);  // g32
  EXPECT_EQ(points.at("recommended"), 1);
  EXPECT_EQ(points.at("pareto front"), 3);  // g4 -> g8 -> g6
  // The front runs by increasing time.
  const auto& front = chart.panels[0].series[2];
  EXPECT_EQ(front.name, "pareto front");
  EXPECT_EQ(front.x, (std::vector<double>{1e-3, 2e-3, 4e-3}));
}

TEST(PlotTradeoff, OneLabelledCurvePerPredictorFailuresApartDurationPanel) {
  const nlohmann::json report = {
      {"campaign_id", 4},
      {"trials", 36},
      {"primary_metric", "position_p95"},
      {"recommended", nullptr},
      {"truth", {{"source", "mujoco"}}},
      {"noise_floor", {{"position_m", {{"median", 2e-4}, {"p95", 5e-4}}}}},
      {"settings",
       {Predicted("arena", "g8_dt0.004", 0.004, 1e-3, 2e-3, true),
        Predicted("arena", "g8_dt0.008", 0.008, 2e-3, 1e-3, true),
        Predicted("arena", "g8_dt0.002", 0.002, 9e-4, 4e-3, false),
        Predicted("mujoco", "mujoco_ts0.001", 0.001, 5e-4, 2e-2, true),
        Predicted("mujoco", "mujoco_ts0.004", 0.004, 1e-9, 5e-3, false, 3)}},
      {"duration_curves",
       {{{"predictor", "arena"},
         {"model_key", "g8_dt0.002"},
         {"points",
          {{{"duration_s", 0.2}, {"trials", 20}, {"position_error_m", {{"p95", 1e-3}}}},
           {{"duration_s", 0.5}, {"trials", 16}, {"position_error_m", {{"p95", 3e-3}}}}}}},
        {{"predictor", "mujoco"},
         {"model_key", "mujoco_ts0.001"},
         {"points",
          {{{"duration_s", 0.2}, {"trials", 20}, {"position_error_m", {{"p95", 4e-4}}}}}}}}}};
  const Chart chart = TradeoffChart(report);
  ASSERT_EQ(chart.panels.size(), 2u);
  EXPECT_TRUE(chart.panels[1].own_x);
  EXPECT_TRUE(chart.panels[1].log_x);
  EXPECT_NE(chart.x_label.find("per simulated second"), std::string::npos);
  EXPECT_NE(chart.title.find("truth: mujoco"), std::string::npos) << chart.title;
  const std::string svg = RenderSvg(chart);
  const auto labels = SeriesLabels(svg);
  // arena's settings by cost, each point labelled with its setting; its curve is
  // what more time buys it.
  EXPECT_EQ(labels.at("arena"),
            (std::vector<std::string>{"g8_dt0.008", "g8_dt0.004", "g8_dt0.002"}));
  EXPECT_EQ(SeriesPoints(RenderSvg(chart)).at("arena curve"), 3);
  EXPECT_EQ(labels.at("mujoco"), (std::vector<std::string>{"mujoco_ts0.001"}));
  // The diverging setting is drawn apart, above every error, never at its 1e-9.
  ASSERT_EQ(labels.at("failed settings").size(), 1u);
  EXPECT_NE(labels.at("failed settings")[0].find("mujoco_ts0.004: 3 diverged"), std::string::npos);
  const auto& failed = chart.panels[0].series[2];
  ASSERT_EQ(failed.name, "failed settings");
  EXPECT_GT(failed.y[0], 2e-3);
  // Log-log: x and y both on log axes; the floor is drawn.
  EXPECT_TRUE(chart.log_x);
  EXPECT_TRUE(chart.panels[0].log_y);
  const auto points = SeriesPoints(svg);
  EXPECT_EQ(points.at("noise floor (replicate spread)"), 2);
  EXPECT_EQ(points.at("arena g8_dt0.002 p95"), 4);  // 2 markers + 2 line points
  // The duration panel has its own x axis, named in the SVG.
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS);
  int own_x = 0;
  for (const auto* g = doc.FirstChildElement("svg")->FirstChildElement("g"); g;
       g = g->NextSiblingElement("g")) {
    if (g->Attribute("data-x-label")) {
      ++own_x;
      EXPECT_NE(std::string(g->Attribute("data-x-label")).find("ground-truth duration"),
                std::string::npos);
    }
  }
  EXPECT_EQ(own_x, 1);
}

TEST(PlotTradeoff, MalformedReportRefused) {
  EXPECT_THROW(TradeoffChart(nlohmann::json::object()), std::invalid_argument);
  EXPECT_THROW(TradeoffChart(nlohmann::json::array()), std::invalid_argument);
}

}  // namespace
}  // namespace arena::cli
