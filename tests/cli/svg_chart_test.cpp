// The SVG charts parse as XML and carry the series they were given.
#include <cmath>
#include <string>

#include <gtest/gtest.h>
#include <tinyxml2.h>

#include "svg_chart.hpp"

namespace arena::cli {
namespace {

Chart TwoPanelChart() {
  Chart chart;
  chart.title = "trial 7 <pose & force>";
  chart.x_label = "t (s)";
  Panel pose{"object z", "m", false, {}};
  Series truth{"true", {0, 0.1, 0.2}, {0, 0.001, 0.002}, "#000"};
  Series observed{"observed", {0, 0.1, 0.2}, {0, NAN, 0.0021}, "#f00"};
  observed.markers = true;
  pose.series = {truth, observed};
  Panel force{"pusher force", "N", true, {}};
  force.series = {Series{"predicted", {0, 0.1, 0.2}, {1, 10, -1}, "#00f", false, true}};
  chart.panels = {pose, force};
  return chart;
}

TEST(SvgChart, ParsesAndHasEverySeries) {
  const std::string svg = RenderSvg(TwoPanelChart());
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  const auto* root = doc.FirstChildElement("svg");
  ASSERT_NE(root, nullptr);
  std::vector<std::string> names;
  int circles = 0, polylines = 0;
  for (const auto* g = root->FirstChildElement("g"); g; g = g->NextSiblingElement("g")) {
    for (const auto* s = g->FirstChildElement("g"); s; s = s->NextSiblingElement("g")) {
      names.push_back(s->Attribute("data-name"));
      for (const auto* c = s->FirstChildElement("circle"); c; c = c->NextSiblingElement("circle"))
        ++circles;
      for (const auto* p = s->FirstChildElement("polyline"); p;
           p = p->NextSiblingElement("polyline")) {
        ++polylines;
        // Non-finite and (on a log axis) non-positive points are left out.
        const std::string pts = p->Attribute("points");
        EXPECT_EQ(pts.find("nan"), std::string::npos);
        EXPECT_EQ(pts.find("inf"), std::string::npos);
      }
    }
  }
  EXPECT_EQ(names, (std::vector<std::string>{"true", "observed", "predicted"}));
  EXPECT_EQ(circles, 2);  // the NaN sample is skipped
  EXPECT_EQ(polylines, 2);
}

TEST(SvgChart, NiceTicksCoverTheRange) {
  const auto ticks = NiceTicks(0.013, 0.987);
  ASSERT_GE(ticks.size(), 3u);
  EXPECT_GE(ticks.front(), 0.013);
  EXPECT_LE(ticks.back(), 0.987);
  for (size_t i = 1; i < ticks.size(); ++i) EXPECT_GT(ticks[i], ticks[i - 1]);
}

}  // namespace
}  // namespace arena::cli
