// Line and scatter charts as standalone SVG (no runtime dependency): what
// `arena plot` draws. A chart is a stack of panels sharing the x axis; each
// panel has series of (x, y) points drawn as lines or markers.
#pragma once

#include <string>
#include <vector>

namespace arena::cli {

struct Series {
  std::string name;          // legend entry; also the SVG id (sanitised)
  std::vector<double> x, y;  // same length; non-finite points are skipped
  std::string color = "#1f77b4";
  bool markers = false;  // markers instead of a polyline
  bool dashed = false;
  bool connect = false;               // with markers: also a polyline through them
  std::vector<std::string> labels{};  // with markers: a text label per point (optional)
  double marker_radius = 0;           // with markers: 0 = 3.5 labelled, 1.8 otherwise
  bool hollow = false;                // with markers: a ring (drawn over what it marks)
};

struct Panel {
  std::string title;
  std::string y_label;
  bool log_y = false;
  std::vector<Series> series;
  // Linear axes: the y axis spans at least this much (y units), centred on
  // the data, so a flat or nearly flat signal is not blown up to noise.
  double min_y_span = 0;
  // Its own x axis (label under the panel) instead of the chart's shared one.
  bool own_x = false;
  std::string x_label{};
  bool log_x = false;
};

struct Chart {
  std::string title;
  std::string x_label{};
  bool log_x = false;
  std::vector<Panel> panels;
  int width = 900;
  int panel_height = 260;
};

// The SVG document. Every series is a <g class="series" id="..."> with a
// data-name attribute, so tests and scripts can find it; a point's label is a
// <text class="point-label"> inside its series' group, and a panel with its
// own x axis carries data-x-label. Point labels of a panel never overlap one
// another: each is placed at the first free spot around its point.
std::string RenderSvg(const Chart& chart);

// Text made safe for SVG/XML attributes and content (& < > ").
std::string SvgEscape(const std::string& s);

// v with `significant` significant digits, as printf's %g gives it (axis
// labels, table cells and captions of the plots).
std::string FormatNumber(double v, int significant);

// v with `decimals` digits after the point, as printf's %.Nf gives it (SVG
// coordinates: a tenth or a hundredth of a pixel is plenty).
std::string FormatFixed(double v, int decimals);

// An SVG coordinate or stroke width: a tenth of a pixel (FormatFixed(v, 1)).
inline std::string SvgNum(double v) { return FormatFixed(v, 1); }

// A scale bar's length: a round length (1, 2 or 5 times a power of ten) of
// at most a quarter of `view_m`, the width the drawing shows (m).
double ScaleBarLength(double view_m);

// "Nice" axis ticks covering [lo, hi] (about `count` of them).
std::vector<double> NiceTicks(double lo, double hi, int count = 6);

}  // namespace arena::cli
