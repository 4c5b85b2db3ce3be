// `arena plot --calibration`: a calibration's stored parameters (as
// assessment::ParamsJson writes them) drawn as one loss-profile panel per
// parameter; a parameter the data do not identify says so in its title.
#include <cmath>
#include <map>
#include <string>

#include <gtest/gtest.h>
#include <tinyxml2.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "plot_charts.hpp"

namespace arena::cli {
namespace {

assessment::FittedParam Profiled(const std::string& name, double fit, bool bounded_high) {
  assessment::FittedParam f;
  f.name = name;
  f.scale = fit;
  f.profiled = true;
  f.profile_low = 0.8 * fit;
  f.profile_high = bounded_high ? 1.2 * fit : 5.0;
  f.bounded_low = true;
  f.bounded_high = bounded_high;
  for (double s : {0.2, 0.5, 1.0, 2.0, 5.0})
    f.profile.emplace_back(s, 10 + (bounded_high ? 100 * std::abs(std::log(s / fit)) : 0.0));
  f.profile.emplace_back(fit, 10);
  return f;
}

// data-name -> number of drawn points (markers, or polyline vertices).
std::map<std::string, int> Series(const std::string& svg, std::string* titles) {
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  std::map<std::string, int> out;
  const auto* root = doc.FirstChildElement("svg");
  if (!root) return out;
  for (const auto* t = root->FirstChildElement("text"); t; t = t->NextSiblingElement("text"))
    if (t->GetText()) *titles += std::string(t->GetText()) + "\n";
  for (const auto* g = root->FirstChildElement("g"); g; g = g->NextSiblingElement("g")) {
    for (const auto* t = g->FirstChildElement("text"); t; t = t->NextSiblingElement("text"))
      if (t->GetText()) *titles += std::string(t->GetText()) + "\n";
    for (const auto* s = g->FirstChildElement("g"); s; s = s->NextSiblingElement("g")) {
      if (!s->Attribute("data-name")) continue;
      int n = 0;
      for (const auto* c = s->FirstChildElement("circle"); c; c = c->NextSiblingElement("circle"))
        ++n;
      out[s->Attribute("data-name")] += n;
    }
  }
  return out;
}

TEST(PlotCalibrationProfile, OnePanelPerProfiledParameterAndTheUnidentifiedOneSaysSo) {
  assessment::CalibrationResult r;
  r.fitted = {Profiled("mu_fingers", 1.3, true), Profiled("mu_pusher", 1.0, false)};
  const Chart chart =
      CalibrationProfileChart(nlohmann::json::parse(assessment::ParamsJson(r)), "calibration 1");
  ASSERT_EQ(chart.panels.size(), 2u);
  EXPECT_EQ(chart.panels[0].title.find("NOT IDENTIFIED"), std::string::npos)
      << chart.panels[0].title;
  EXPECT_NE(chart.panels[1].title.find("NOT IDENTIFIED"), std::string::npos)
      << chart.panels[1].title;
  EXPECT_NE(chart.panels[1].title.find("5 (bound)"), std::string::npos) << chart.panels[1].title;
  EXPECT_TRUE(chart.panels[0].log_x && chart.panels[0].log_y);

  std::string titles;
  const auto series = Series(RenderSvg(chart), &titles);
  EXPECT_EQ(series.at("loss mu_fingers"), 6);  // every profiled scale
  EXPECT_EQ(series.at("fit mu_pusher"), 1);
  EXPECT_TRUE(series.count("fits as well from mu_pusher"));
  EXPECT_TRUE(series.count("fits as well up to mu_pusher"));
  EXPECT_NE(titles.find("calibration 1"), std::string::npos) << titles;
}

TEST(PlotCalibrationProfile, AFitWithoutProfilesIsRefused) {
  assessment::CalibrationResult r;
  assessment::FittedParam plain;
  plain.name = "mu_fingers";
  r.fitted = {plain};
  EXPECT_THROW(CalibrationProfileChart(nlohmann::json::parse(assessment::ParamsJson(r)), "c"),
               std::invalid_argument);
  EXPECT_THROW(CalibrationProfileChart(nlohmann::json::array(), "c"), std::invalid_argument);
}

}  // namespace
}  // namespace arena::cli
