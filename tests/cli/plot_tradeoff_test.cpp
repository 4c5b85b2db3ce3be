// `arena plot --tradeoff`: the chart of an evaluation report parses as SVG
// and carries the settings, the Pareto front and the recommendation.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
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
  const auto& series = chart.panels[0].series;
  const auto& front = *std::find_if(series.begin(), series.end(),
                                    [](const Series& se) { return se.name == "pareto front"; });
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
  // MuJoCo predicting MuJoCo's trials is self-consistency (issue 26), and says so.
  EXPECT_EQ(labels.at("mujoco (self-consistency: the truth's own engine)"),
            (std::vector<std::string>{"mujoco_ts0.001"}));
  EXPECT_EQ(labels.count("mujoco"), 0u);
  // The diverging setting is drawn apart, above every error, never at its 1e-9.
  ASSERT_EQ(labels.at("failed settings").size(), 1u);
  EXPECT_NE(labels.at("failed settings")[0].find("mujoco_ts0.004: 3 diverged"), std::string::npos);
  const auto& failed = chart.panels[0].series[2];
  ASSERT_EQ(failed.name, "failed settings");
  EXPECT_GT(failed.y[0], 2);  // mm
  // Log-log: x and y both on log axes; the floor is drawn.
  EXPECT_TRUE(chart.log_x);
  EXPECT_TRUE(chart.panels[0].log_y);
  const auto points = SeriesPoints(svg);
  // The floor the table's multiples and the 1.5floor budget use: the median spread.
  EXPECT_EQ(points.at("noise floor (median replicate spread)"), 2);
  for (const auto& se : chart.panels[0].series) {
    if (se.name.rfind("noise floor", 0) == 0) {
      EXPECT_EQ(se.y, (std::vector<double>{0.2, 0.2}));  // mm, as the axis
    }
  }
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

// Pins (issue 26): the recommendation's marker (r = 1.8) was drawn under an
// ordinary point (r = 3.5) and the curves, unlabelled; the budget was never
// drawn; labels overlapped; errors were in metres where the text says mm.
TEST(PlotTradeoff, RecommendationOnTopLabelledBudgetDrawnInMm) {
  const nlohmann::json report = {
      {"campaign_id", 5},
      {"trials", 12},
      {"primary_metric", "position_p95"},
      {"recommended", "g8_dt0.004"},
      {"truth", {{"source", "model"}, {"independent", false}}},
      {"budgets",
       {{{"metric", "position_p95"}, {"limit", 1.5e-3}, {"text", "position_p95<=1.5mm"}}}},
      {"settings",
       {Predicted("arena", "g8_dt0.008", 0.008, 2e-3, 1e-3, true),
        Predicted("arena", "g8_dt0.004", 0.004, 1e-3, 1.05e-3, true),
        Predicted("arena", "g8_dt0.002", 0.002, 0.99e-3, 1.1e-3, true)}}};
  const Chart chart = TradeoffChart(report);
  const auto& series = chart.panels[0].series;
  // Drawn last (on top), bigger than any point, labelled.
  ASSERT_EQ(series.back().name, "recommended");
  EXPECT_GT(series.back().marker_radius, 3.5);
  EXPECT_EQ(series.back().labels, (std::vector<std::string>{"recommended: g8_dt0.004"}));
  EXPECT_NEAR(series.back().y.at(0), 1.0, 1e-12);  // mm
  EXPECT_NE(chart.panels[0].y_label.find("(mm)"), std::string::npos);
  bool budget = false;
  for (const auto& se : series)
    if (se.name.rfind("budget", 0) == 0) {
      budget = true;
      EXPECT_EQ(se.y, (std::vector<double>{1.5, 1.5}));
    }
  EXPECT_TRUE(budget) << "no budget line";
  EXPECT_NE(chart.title.find("self-consistency, not accuracy"), std::string::npos) << chart.title;
  // Labels of points close together never overlap (9 px text, ~5 px a character).
  tinyxml2::XMLDocument doc;
  const std::string svg = RenderSvg(chart);
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS);
  struct Box {
    double x, y, w;
  };
  std::vector<Box> boxes;
  std::function<void(const tinyxml2::XMLElement*)> walk = [&](const tinyxml2::XMLElement* e) {
    for (const auto* c = e->FirstChildElement(); c; c = c->NextSiblingElement()) {
      if (c->Attribute("class", "point-label"))
        boxes.push_back({c->DoubleAttribute("x"), c->DoubleAttribute("y"),
                         5.6 * std::string(c->GetText()).size()});
      walk(c);
    }
  };
  walk(doc.RootElement());
  ASSERT_GE(boxes.size(), 4u);
  for (size_t i = 0; i < boxes.size(); ++i)
    for (size_t j = i + 1; j < boxes.size(); ++j) {
      const bool overlap = boxes[i].x < boxes[j].x + boxes[j].w &&
                           boxes[j].x < boxes[i].x + boxes[i].w &&
                           std::abs(boxes[i].y - boxes[j].y) < 10;
      EXPECT_FALSE(overlap) << "labels " << i << " and " << j << " overlap";
    }
}

// Pins (issue 26): the front came from the report's flags, computed on time
// per trial, but was drawn on time per simulated second, so it doubled back.
TEST(PlotTradeoff, FrontComputedOnTheAxisDrawn) {
  // Per trial (time_s = per_sim_s / 5 here) and per simulated second agree on
  // order unless the durations differ: flags that disagree with the x drawn.
  const nlohmann::json report = {{"campaign_id", 6},
                                 {"trials", 12},
                                 {"primary_metric", "position_p95"},
                                 {"settings",
                                  {Predicted("arena", "a", 0.008, 2e-3, 3e-3, true),
                                   Predicted("arena", "b", 0.004, 1e-3, 1e-3, false),
                                   Predicted("arena", "c", 0.002, 5e-4, 2e-3, true)}}};
  const Chart chart = TradeoffChart(report);
  for (const auto& se : chart.panels[0].series) {
    if (se.name != "pareto front") continue;
    // b dominates a on the drawn axis; the front rises in x and falls in y.
    EXPECT_EQ(se.x, (std::vector<double>{1e-3, 2e-3}));
    for (size_t i = 1; i < se.x.size(); ++i) {
      EXPECT_GT(se.x[i], se.x[i - 1]);
      EXPECT_LT(se.y[i], se.y[i - 1]);
    }
  }
}

// Pins (issue 26): the slowest settings were drawn on the frame (their
// markers and labels clipped by it), and then the highest points 14 px under
// it, their labels pushed below them. Every marker keeps room for a label
// between it and each side of the frame (its radius, a 2 px gap and a 10 px
// label), and every label's box lies inside the frame; the SVG is written to
// tradeoff_frame.svg in the test's temporary folder to be looked at (never
// into the folder the test was started from).
TEST(PlotTradeoff, SlowestPointsAndLabelsInsideTheFrame) {
  nlohmann::json settings = nlohmann::json::array();
  // Two predictors over three decades of cost; the slowest is recommended.
  const double steps[] = {0.016, 0.008, 0.004, 0.002, 0.001};
  for (int i = 0; i < 5; ++i) {
    settings.push_back(Predicted("arena", "g8_dt" + std::to_string(steps[i]).substr(0, 5), steps[i],
                                 4e-3 / (i + 1), 1e-3 * std::pow(3.0, i), i == 4));
    settings.push_back(Predicted("mujoco", "mj_dt" + std::to_string(steps[i]).substr(0, 5),
                                 steps[i], 3e-3 / (i + 1), 5e-3 * std::pow(3.0, i), false));
  }
  const nlohmann::json report = {
      {"campaign_id", 7},
      {"trials", 24},
      {"primary_metric", "position_p95"},
      {"recommended", settings[8]["model_key"]},
      {"budgets",
       {{{"metric", "position_p95"}, {"limit", 1.2e-3}, {"text", "position_p95<=1.2mm"}}}},
      {"settings", settings}};
  const std::string svg = RenderSvg(TradeoffChart(report));
  {
    std::ofstream out(::testing::TempDir() + "tradeoff_frame.svg");
    out << svg;
  }
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS);
  int markers = 0, labels = 0;
  for (const auto* g = doc.RootElement()->FirstChildElement("g"); g;
       g = g->NextSiblingElement("g")) {
    const auto* frame = g->FirstChildElement("rect");
    ASSERT_NE(frame, nullptr);
    const double x0 = frame->DoubleAttribute("x"), y0 = frame->DoubleAttribute("y");
    const double x1 = x0 + frame->DoubleAttribute("width");
    const double y1 = y0 + frame->DoubleAttribute("height");
    for (const auto* s = g->FirstChildElement("g"); s; s = s->NextSiblingElement("g")) {
      if (!s->Attribute("data-name")) continue;
      const std::string name = s->Attribute("data-name");
      for (const auto* c = s->FirstChildElement("circle"); c; c = c->NextSiblingElement("circle")) {
        const double cx = c->DoubleAttribute("cx"), cy = c->DoubleAttribute("cy");
        const double r = c->DoubleAttribute("r");
        const double room = r + 2 + 10 - 0.5;  // marker, gap, label (half a px of rounding)
        EXPECT_GE(cx - x0, room) << name << " marker on the left frame";
        EXPECT_GE(x1 - cx, room) << name << " marker on the right frame";
        EXPECT_GE(cy - y0, room) << name << " marker on the top frame";
        EXPECT_GE(y1 - cy, room) << name << " marker on the bottom frame";
        ++markers;
      }
      for (const auto* t = s->FirstChildElement("text"); t; t = t->NextSiblingElement("text")) {
        if (!t->Attribute("class", "point-label")) continue;
        const double x = t->DoubleAttribute("x"), y = t->DoubleAttribute("y");
        EXPECT_GT(x, x0) << name << " label " << t->GetText();
        EXPECT_LT(x, x1) << name << " label " << t->GetText();
        EXPECT_GE(y - 8, y0) << name << " label on the top frame " << t->GetText();  // 9 px text
        EXPECT_LE(y + 2, y1) << name << " label on the bottom frame " << t->GetText();
        ++labels;
      }
    }
  }
  EXPECT_GE(markers, 11);
  EXPECT_GE(labels, 10);
}

TEST(PlotTradeoff, MalformedReportRefused) {
  EXPECT_THROW(TradeoffChart(nlohmann::json::object()), std::invalid_argument);
  EXPECT_THROW(TradeoffChart(nlohmann::json::array()), std::invalid_argument);
}

}  // namespace
}  // namespace arena::cli
