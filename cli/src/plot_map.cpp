#include "plot_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "svg_chart.hpp"

namespace arena::cli {
namespace {

std::string Num(double v) { return FormatNumber(v, 6); }

struct Axis {
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
    return Num(t);
  }
};

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
  const int width = 820, height = 600;
  const int left = 90, right = 190, top = 90, bottom = 70;
  const int pw = width - left - right, ph = height - top - bottom;
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
  Axis ax, ay;
  ax.Fit(xs, m.x_categories);
  ay.Fit(ys, m.y_categories);
  double vlo = vs.empty() ? 0 : *std::min_element(vs.begin(), vs.end());
  double vhi = vs.empty() ? 1 : *std::max_element(vs.begin(), vs.end());
  if (m.flag) {
    vlo = 0;
    vhi = 1;
  }
  if (!(vhi > vlo)) vhi = vlo + (vlo == 0 ? 1 : std::abs(vlo) * 1e-6);
  auto X = [&](double x) { return left + (x - ax.lo) / (ax.hi - ax.lo) * pw; };
  auto Y = [&](double y) { return top + ph - (y - ay.lo) / (ay.hi - ay.lo) * ph; };
  auto colour = [&](double v) {
    if (m.flag) return std::string(v >= 0.5 ? "#d62728" : "#2ca02c");
    return MapColour((v - vlo) / (vhi - vlo));
  };

  std::ostringstream svg;
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
  for (double t : ax.ticks) {
    if (t < ax.lo || t > ax.hi) continue;
    svg << "<line x1=\"" << X(t) << "\" y1=\"" << top + ph << "\" x2=\"" << X(t) << "\" y2=\""
        << top + ph + 5 << "\" stroke=\"#333\"/><text x=\"" << X(t) << "\" y=\"" << top + ph + 18
        << "\" text-anchor=\"middle\">" << SvgEscape(ax.Label(t)) << "</text>\n";
  }
  svg << "<text class=\"label\" x=\"" << left + pw / 2 << "\" y=\"" << height - 20
      << "\" text-anchor=\"middle\">" << SvgEscape(m.x_label) << "</text>\n</g>\n";
  svg << "<g class=\"axis\" id=\"y-axis\">\n";
  for (double t : ay.ticks) {
    if (t < ay.lo || t > ay.hi) continue;
    svg << "<line x1=\"" << left - 5 << "\" y1=\"" << Y(t) << "\" x2=\"" << left << "\" y2=\""
        << Y(t) << "\" stroke=\"#333\"/><text x=\"" << left - 8 << "\" y=\"" << Y(t) + 4
        << "\" text-anchor=\"end\">" << SvgEscape(ay.Label(t)) << "</text>\n";
  }
  svg << "<text class=\"label\" x=\"22\" y=\"" << top + ph / 2 << "\" transform=\"rotate(-90 22 "
      << top + ph / 2 << ")\" text-anchor=\"middle\">" << SvgEscape(m.y_label) << "</text>\n</g>\n";

  // Conditions that share (x, y) (they differ in another varied parameter)
  // sit side by side on a small ring instead of hiding each other.
  std::map<std::pair<long, long>, std::vector<size_t>> at;
  for (size_t i = 0; i < m.points.size(); ++i) {
    at[{std::lround(X(m.points[i].x)), std::lround(Y(m.points[i].y))}].push_back(i);
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
        << Num(p.x) << "\" data-y=\"" << Num(p.y) << "\"";
    if (p.value) {
      svg << " data-value=\"" << Num(*p.value) << "\" fill=\"" << colour(*p.value)
          << "\" stroke=\"#222\"";
    } else {
      svg << " fill=\"none\" stroke=\"#999\"";
    }
    svg << " cx=\"" << X(p.x) + offset[i].first << "\" cy=\"" << Y(p.y) + offset[i].second
        << "\" r=\"7\"><title>condition " << p.condition << ": "
        << (p.value ? Num(*p.value) : std::string("no value")) << "</title></circle>\n";
    // A condition sharing its point says which one it is.
    const auto shared = at.find({std::lround(X(p.x)), std::lround(Y(p.y))});
    if (shared != at.end() && shared->second.size() > 1 && !p.label.empty()) {
      const bool right = offset[i].first >= 0;
      svg << "<text class=\"condition-label\" x=\"" << X(p.x) + offset[i].first * 1.9 << "\" y=\""
          << Y(p.y) + offset[i].second * 1.9 + 3 << "\" font-size=\"9\" text-anchor=\""
          << (right ? "start" : "end") << "\">" << SvgEscape(p.label) << "</text>\n";
    }
  }
  svg << "</g>\n";
  if (!m.boundary.empty()) {
    svg << "<g class=\"series\" id=\"boundary\" data-name=\"boundary points\">\n";
    for (const auto& [x, y] : m.boundary) {
      svg << "<circle class=\"boundary\" cx=\"" << X(x) << "\" cy=\"" << Y(y)
          << "\" r=\"3\" fill=\"black\"/>\n";
    }
    svg << "</g>\n";
  }

  // Legend or colour bar.
  const int lx = left + pw + 30;
  // The metric's label, wrapped to the legend's width.
  std::vector<std::string> lines(1);
  for (size_t i = 0; i < m.metric_label.size();) {
    size_t j = m.metric_label.find(' ', i);
    if (j == std::string::npos) j = m.metric_label.size();
    const std::string word = m.metric_label.substr(i, j - i);
    if (!lines.back().empty() && lines.back().size() + word.size() > 24) lines.emplace_back();
    lines.back() += (lines.back().empty() ? "" : " ") + word;
    i = j + 1;
  }
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
      svg << "<circle cx=\"" << lx + 7 << "\" cy=\"" << y << "\" r=\"7\" fill=\"" << colour(v)
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
    for (double t : NiceTicks(vlo, vhi, 5)) {
      if (t < vlo || t > vhi) continue;
      const double y = top + bar_h - (t - vlo) / (vhi - vlo) * bar_h;
      svg << "<text x=\"" << lx + 22 << "\" y=\"" << y + 4 << "\">" << Num(t) << "</text>\n";
    }
  }
  if (!m.boundary.empty()) {
    svg << "<circle cx=\"" << lx + 7 << "\" cy=\"" << top + ph - 10
        << "\" r=\"3\" fill=\"black\"/><text x=\"" << lx + 20 << "\" y=\"" << top + ph - 6
        << "\">boundary points</text>\n";
  }
  svg << "</g>\n</svg>\n";
  return svg.str();
}

}  // namespace arena::cli
