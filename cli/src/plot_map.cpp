#include "plot_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "svg_chart.hpp"

namespace arena::cli {
namespace {

// Six significant digits: the map's data attributes and tick labels.
std::string Num6(double v) { return FormatNumber(v, 6); }

struct MapAxis {
  double lo = 0, hi = 1;
  std::vector<std::string> categories;
  std::vector<double> ticks;
  void Fit(const std::vector<double>& values, const std::vector<std::string>& cats) {
    categories = cats;
    if (!cats.empty()) {
      lo = -0.5;
      hi = static_cast<double>(cats.size()) - 0.5;
      ticks.clear();
      for (size_t i = 0; i < cats.size(); ++i) ticks.push_back(static_cast<double>(i));
      return;
    }
    if (values.empty()) return;
    lo = *std::min_element(values.begin(), values.end());
    hi = *std::max_element(values.begin(), values.end());
    const double pad = hi > lo ? 0.05 * (hi - lo) : std::max(std::abs(lo) * 0.1, 1e-9);
    lo -= pad;
    hi += pad;
    ticks = NiceTicks(lo, hi, 6);
  }
  std::string Label(double t) const {
    if (!categories.empty()) return categories[static_cast<size_t>(std::lround(t))];
    return Num6(t);
  }
};

// The map's layout: the plot area, its axes and the value range coloured.
struct MapFrame {
  static constexpr int width = 820, height = 600;
  static constexpr int left = 90, right = 190, top = 90, bottom = 70;
  static constexpr int pw = width - left - right, ph = height - top - bottom;
  MapAxis ax, ay;
  double vlo = 0, vhi = 1;
  bool flag = false;
  double X(double x) const { return left + (x - ax.lo) / (ax.hi - ax.lo) * pw; }
  double Y(double y) const { return top + ph - (y - ay.lo) / (ay.hi - ay.lo) * ph; }
  std::string Colour(double v) const {
    if (flag) return std::string(v >= 0.5 ? "#d62728" : "#2ca02c");
    return MapColour((v - vlo) / (vhi - vlo));
  }
};

MapFrame FitFrame(const MapData& m) {
  MapFrame f;
  std::vector<double> xs, ys, vs;
  for (const auto& p : m.points) {
    xs.push_back(p.x);
    ys.push_back(p.y);
    if (p.value) vs.push_back(*p.value);
  }
  for (const auto& [x, y] : m.boundary) {
    xs.push_back(x);
    ys.push_back(y);
  }
  f.ax.Fit(xs, m.x_categories);
  f.ay.Fit(ys, m.y_categories);
  f.vlo = vs.empty() ? 0 : *std::min_element(vs.begin(), vs.end());
  f.vhi = vs.empty() ? 1 : *std::max_element(vs.begin(), vs.end());
  f.flag = m.flag;
  if (m.flag) {
    f.vlo = 0;
    f.vhi = 1;
  }
  if (!(f.vhi > f.vlo)) f.vhi = f.vlo + (f.vlo == 0 ? 1 : std::abs(f.vlo) * 1e-6);
  return f;
}

// Title, note, the plot's frame and both axes.
void WriteFrameAndAxes(const MapFrame& f, const MapData& m, std::ostringstream& svg) {
  const int width = f.width, height = f.height, left = f.left, top = f.top, pw = f.pw, ph = f.ph;
  svg << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
      << "\" viewBox=\"0 0 " << width << ' ' << height
      << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
      << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
      << "<text class=\"title\" x=\"" << width / 2 << "\" y=\"24\" text-anchor=\"middle\" "
      << "font-size=\"15\">" << SvgEscape(m.title) << "</text>\n";
  if (!m.note.empty()) {
    svg << "<text class=\"note\" x=\"" << width / 2 << "\" y=\"44\" text-anchor=\"middle\" "
        << "fill=\"#555\">" << SvgEscape(m.note) << "</text>\n";
  }
  svg << "<rect x=\"" << left << "\" y=\"" << top << "\" width=\"" << pw << "\" height=\"" << ph
      << "\" fill=\"none\" stroke=\"#333\"/>\n";
  svg << "<g class=\"axis\" id=\"x-axis\">\n";
  for (double t : f.ax.ticks) {
    if (t < f.ax.lo || t > f.ax.hi) continue;
    svg << "<line x1=\"" << f.X(t) << "\" y1=\"" << top + ph << "\" x2=\"" << f.X(t) << "\" y2=\""
        << top + ph + 5 << "\" stroke=\"#333\"/><text x=\"" << f.X(t) << "\" y=\"" << top + ph + 18
        << "\" text-anchor=\"middle\">" << SvgEscape(f.ax.Label(t)) << "</text>\n";
  }
  svg << "<text class=\"label\" x=\"" << left + pw / 2 << "\" y=\"" << height - 20
      << "\" text-anchor=\"middle\">" << SvgEscape(m.x_label) << "</text>\n</g>\n";
  svg << "<g class=\"axis\" id=\"y-axis\">\n";
  for (double t : f.ay.ticks) {
    if (t < f.ay.lo || t > f.ay.hi) continue;
    svg << "<line x1=\"" << left - 5 << "\" y1=\"" << f.Y(t) << "\" x2=\"" << left << "\" y2=\""
        << f.Y(t) << "\" stroke=\"#333\"/><text x=\"" << left - 8 << "\" y=\"" << f.Y(t) + 4
        << "\" text-anchor=\"end\">" << SvgEscape(f.ay.Label(t)) << "</text>\n";
  }
  svg << "<text class=\"label\" x=\"22\" y=\"" << top + ph / 2 << "\" transform=\"rotate(-90 22 "
      << top + ph / 2 << ")\" text-anchor=\"middle\">" << SvgEscape(m.y_label) << "</text>\n</g>\n";
}

// The conditions, and the boundary sampler's points. Conditions that share
// (x, y) (they differ in another varied parameter) sit side by side on a
// small ring instead of hiding each other.
void WritePoints(const MapFrame& f, const MapData& m, std::ostringstream& svg) {
  std::map<std::pair<long, long>, std::vector<size_t>> at;
  for (size_t i = 0; i < m.points.size(); ++i) {
    at[{std::lround(f.X(m.points[i].x)), std::lround(f.Y(m.points[i].y))}].push_back(i);
  }
  std::vector<std::pair<double, double>> offset(m.points.size(), {0.0, 0.0});
  for (const auto& [key, members] : at) {
    if (members.size() < 2) continue;
    for (size_t k = 0; k < members.size(); ++k) {
      const double a = 2 * M_PI * static_cast<double>(k) / static_cast<double>(members.size());
      offset[members[k]] = {9 * std::cos(a), -9 * std::sin(a)};
    }
  }
  svg << "<g class=\"series\" id=\"conditions\" data-metric=\"" << SvgEscape(m.metric_label)
      << "\">\n";
  for (size_t i = 0; i < m.points.size(); ++i) {
    const MapPoint& p = m.points[i];
    svg << "<circle class=\"condition\" data-condition=\"" << p.condition << "\" data-x=\""
        << Num6(p.x) << "\" data-y=\"" << Num6(p.y) << "\"";
    if (p.value) {
      svg << " data-value=\"" << Num6(*p.value) << "\" fill=\"" << f.Colour(*p.value)
          << "\" stroke=\"#222\"";
    } else {
      svg << " fill=\"none\" stroke=\"#999\"";
    }
    svg << " cx=\"" << f.X(p.x) + offset[i].first << "\" cy=\"" << f.Y(p.y) + offset[i].second
        << "\" r=\"7\"><title>condition " << p.condition << ": "
        << (p.value ? Num6(*p.value) : std::string("no value")) << "</title></circle>\n";
    // A condition sharing its point says which one it is.
    const auto shared = at.find({std::lround(f.X(p.x)), std::lround(f.Y(p.y))});
    if (shared != at.end() && shared->second.size() > 1 && !p.label.empty()) {
      const bool right = offset[i].first >= 0;
      svg << "<text class=\"condition-label\" x=\"" << f.X(p.x) + offset[i].first * 1.9 << "\" y=\""
          << f.Y(p.y) + offset[i].second * 1.9 + 3 << "\" font-size=\"9\" text-anchor=\""
          << (right ? "start" : "end") << "\">" << SvgEscape(p.label) << "</text>\n";
    }
  }
  svg << "</g>\n";
  if (!m.boundary.empty()) {
    svg << "<g class=\"series\" id=\"boundary\" data-name=\"boundary points\">\n";
    for (const auto& [x, y] : m.boundary) {
      svg << "<circle class=\"boundary\" cx=\"" << f.X(x) << "\" cy=\"" << f.Y(y)
          << "\" r=\"3\" fill=\"black\"/>\n";
    }
    svg << "</g>\n";
  }
}

// The metric's label, wrapped to the legend's width.
std::vector<std::string> WrapLegendLabel(const std::string& label) {
  std::vector<std::string> lines(1);
  for (size_t i = 0; i < label.size();) {
    size_t j = label.find(' ', i);
    if (j == std::string::npos) j = label.size();
    const std::string word = label.substr(i, j - i);
    if (!lines.back().empty() && lines.back().size() + word.size() > 24) lines.emplace_back();
    lines.back() += (lines.back().empty() ? "" : " ") + word;
    i = j + 1;
  }
  return lines;
}

// Legend (a flag's two values) or colour bar.
void WriteLegend(const MapFrame& f, const MapData& m, std::ostringstream& svg) {
  const int top = f.top, ph = f.ph;
  const int lx = f.left + f.pw + 30;
  const std::vector<std::string> lines = WrapLegendLabel(m.metric_label);
  svg << "<g class=\"legend\">\n<text class=\"metric\" x=\"" << lx << "\" y=\""
      << top - 12 * static_cast<int>(lines.size()) << "\">";
  for (size_t k = 0; k < lines.size(); ++k) {
    svg << "<tspan x=\"" << lx << "\" dy=\"" << (k == 0 ? 0 : 14) << "\">" << SvgEscape(lines[k])
        << "</tspan>";
  }
  svg << "</text>\n";
  if (m.flag) {
    int y = top + 10;
    for (auto [v, name] : {std::pair{1.0, m.flag_on}, std::pair{0.0, m.flag_off}}) {
      svg << "<circle cx=\"" << lx + 7 << "\" cy=\"" << y << "\" r=\"7\" fill=\"" << f.Colour(v)
          << "\" stroke=\"#222\"/><text x=\"" << lx + 20 << "\" y=\"" << y + 4 << "\">"
          << SvgEscape(name) << "</text>\n";
      y += 24;
    }
  } else {
    const int bar_h = ph - 40, steps = 40;
    for (int i = 0; i < steps; ++i) {
      const double t = (i + 0.5) / steps;
      svg << "<rect x=\"" << lx << "\" y=\"" << top + bar_h - (i + 1) * bar_h / steps
          << "\" width=\"16\" height=\"" << bar_h / steps + 1 << "\" fill=\"" << MapColour(t)
          << "\"/>\n";
    }
    for (double t : NiceTicks(f.vlo, f.vhi, 5)) {
      if (t < f.vlo || t > f.vhi) continue;
      const double y = top + bar_h - (t - f.vlo) / (f.vhi - f.vlo) * bar_h;
      svg << "<text x=\"" << lx + 22 << "\" y=\"" << y + 4 << "\">" << Num6(t) << "</text>\n";
    }
  }
  if (!m.boundary.empty()) {
    svg << "<circle cx=\"" << lx + 7 << "\" cy=\"" << top + ph - 10
        << "\" r=\"3\" fill=\"black\"/><text x=\"" << lx + 20 << "\" y=\"" << top + ph - 6
        << "\">boundary points</text>\n";
  }
  svg << "</g>\n";
}

}  // namespace

std::string MapColour(double t) {
  // Viridis at five stops, linearly interpolated.
  static const double kStops[5][3] = {
      {68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}};
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * 4;
  const int i = std::min(3, static_cast<int>(t));
  const double f = t - i;
  char buf[8];
  std::snprintf(
      buf, sizeof buf, "#%02x%02x%02x",
      static_cast<int>(std::lround(kStops[i][0] + f * (kStops[i + 1][0] - kStops[i][0]))),
      static_cast<int>(std::lround(kStops[i][1] + f * (kStops[i + 1][1] - kStops[i][1]))),
      static_cast<int>(std::lround(kStops[i][2] + f * (kStops[i + 1][2] - kStops[i][2]))));
  return buf;
}

std::string RenderMapSvg(const MapData& m) {
  const MapFrame f = FitFrame(m);
  std::ostringstream svg;
  WriteFrameAndAxes(f, m, svg);
  WritePoints(f, m, svg);
  WriteLegend(f, m, svg);
  svg << "</svg>\n";
  return svg.str();
}

}  // namespace arena::cli
