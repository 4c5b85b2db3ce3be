// The SVG charts parse as XML and carry the series they were given.
#include <array>
#include <cmath>
#include <functional>
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

// Issue 26: labels of a crowded cluster were pushed away from their points
// (no overlap) with nothing tying them back, so on the trade-off plot
// "g16_k3_dt0.001_auto" sat beside another setting's point. Pins: a label
// that cannot sit next to its point has a leader line from the point to its
// own box; one that sits next to it has none.
TEST(SvgChart, DisplacedLabelsAreTiedToTheirPoints) {
  Chart chart;
  chart.title = "crowded";
  chart.x_label = "x";
  Panel panel{"error", "mm", false, {}};
  Series s{"settings", {}, {}, "#1f77b4"};
  s.markers = true;
  for (int i = 0; i < 6; ++i) {  // six points within a few px of each other
    s.x.push_back(1.0 + 0.001 * i);
    s.y.push_back(1.0 + 0.001 * i);
    s.labels.push_back("g16_k3_dt0.00" + std::to_string(i) + "_auto");
  }
  s.x.push_back(10);  // one alone
  s.y.push_back(10);
  s.labels.push_back("alone");
  panel.series = {s};
  chart.panels = {panel};
  const std::string svg = RenderSvg(chart);
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  struct Label {
    double x, y;
    std::string text;
  };
  std::vector<Label> labels;
  std::vector<std::array<double, 4>> leaders;
  std::vector<std::pair<double, double>> points;
  std::function<void(const tinyxml2::XMLElement*)> walk = [&](const tinyxml2::XMLElement* e) {
    for (; e; e = e->NextSiblingElement()) {
      const std::string name = e->Name();
      if (name == "text" && e->Attribute("class", "point-label"))
        labels.push_back({e->DoubleAttribute("x"), e->DoubleAttribute("y"), e->GetText()});
      if (name == "line" && e->Attribute("class", "label-leader"))
        leaders.push_back({e->DoubleAttribute("x1"), e->DoubleAttribute("y1"),
                           e->DoubleAttribute("x2"), e->DoubleAttribute("y2")});
      if (name == "circle") points.push_back({e->DoubleAttribute("cx"), e->DoubleAttribute("cy")});
      walk(e->FirstChildElement());
    }
  };
  walk(doc.FirstChildElement("svg"));
  ASSERT_EQ(labels.size(), 7u);
  // Four spots touch a point's marker on each side; six labels cannot all.
  EXPECT_GE(leaders.size(), 1u);
  EXPECT_LT(leaders.size(), 6u);
  for (const auto& l : leaders) {
    // Starts on a labelled point, ends on the box of a label of that point.
    bool on_point = false;
    for (const auto& p : points)
      on_point |= std::abs(p.first - l[0]) < 0.01 && std::abs(p.second - l[1]) < 0.01;
    EXPECT_TRUE(on_point);
    bool on_label = false;
    for (const auto& t : labels) {
      const double w = 5.6 * t.text.size() + 2;
      on_label |= l[2] >= t.x - 0.01 && l[2] <= t.x + w + 0.01 && l[3] >= t.y - 8 - 0.01 &&
                  l[3] <= t.y + 2 + 0.01;
    }
    EXPECT_TRUE(on_label);
    EXPECT_GT(std::hypot(l[2] - l[0], l[3] - l[1]), 5.0);  // a leader only where it is far
  }
}

// Issue 26: a closed-loop trial's plot title ("...; closed loop: 0 of 376
// samples held, loop p50 0.257 ms, p99 ...") ran past both edges of the
// picture, cutting off the deadline misses it is there to report. Pins: a
// title wider than the picture is split in two lines that each fit, and no
// word is lost.
TEST(SvgChart, ALongTitleWrapsInsideThePicture) {
  Chart chart = TwoPanelChart();
  chart.title =
      "trial 1 (campaign 1 'pivot_control', attempt 1, cell sim1-0edbac) prediction "
      "g8_k3_dt0.004_auto; closed loop: 0 of 376 samples held, loop p50 0.257 ms, p99 1.54 ms "
      "against a 4 ms period";
  const std::string svg = RenderSvg(chart);
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  const auto* root = doc.FirstChildElement("svg");
  const double width = root->DoubleAttribute("width");
  std::string joined;
  int lines = 0;
  for (const auto* t = root->FirstChildElement("text"); t; t = t->NextSiblingElement("text")) {
    if (!t->Attribute("class", "chart-title")) continue;
    ++lines;
    const std::string text = t->GetText();
    EXPECT_LE(text.size() * 8.3, width - 20) << text;
    joined += (joined.empty() ? "" : " ") + text;
  }
  EXPECT_EQ(lines, 2);
  EXPECT_EQ(joined, chart.title);
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
