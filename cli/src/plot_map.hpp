// A 2-D map over two varied parameters of a campaign (`arena plot --map X,Y
// --metric M`): one marker per condition at its (x, y), coloured by the
// metric (a colour bar gives the scale; a 0/1 flag such as "unstable" gets
// two colours and a legend). A categorical parameter (finger_type,
// push_direction) is an axis of evenly spaced labelled categories.
//
// SVG structure for scripts and tests: every condition is a
// <circle class="condition" data-condition=".." data-x=".." data-y=".."
// data-value=".."/> (data-value absent when the metric has no value there,
// drawn hollow grey); overlaid points (an adaptive campaign's boundary) are
// <g class="series" id="boundary"> of <circle class="boundary"/>. Axis
// labels carry their units.
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace arena::cli {

struct MapPoint {
  int condition = 0;
  double x = 0, y = 0;  // axis coordinates (a category's index for categorical axes)
  std::optional<double> value;
  // The condition's other sampled parameters ("finger_type=line"): written
  // beside it where several conditions share (x, y).
  std::string label{};
};

struct MapData {
  std::string title;
  std::string x_label, y_label, metric_label;           // with units, e.g. "grip_force (N)"
  std::vector<std::string> x_categories, y_categories;  // non-empty: categorical axis
  bool flag = false;  // the metric is 0/1 (e.g. unstable): two colours, no colour bar
  std::string flag_on = "yes", flag_off = "no";
  std::vector<MapPoint> points;
  std::vector<std::pair<double, double>> boundary;  // overlaid points (axis coordinates)
  std::string note;                                 // a line under the title ("" none)
};

std::string RenderMapSvg(const MapData& map);

// Viridis-like colour of t in [0, 1] as "#rrggbb".
std::string MapColour(double t);

}  // namespace arena::cli
