#include "svg_chart.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <utility>

namespace arena::cli {

std::string SvgEscape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

namespace {

std::string Id(const std::string& s) {
  std::string out;
  for (char c : s) out += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return out;
}

std::string Num(double v) { return FormatFixed(v, 2); }

std::string TickLabel(double v) {
  char buf[32];
  if (v != 0 && (std::fabs(v) < 1e-3 || std::fabs(v) >= 1e5)) {
    std::snprintf(buf, sizeof buf, "%.0e", v);
  } else {
    std::snprintf(buf, sizeof buf, "%.3g", v);
  }
  return buf;
}

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  bool empty() const { return !(lo <= hi); }
};

// Axis mapping; log axes map log10(v) and drop non-positive values.
struct Axis {
  bool log = false;
  double lo = 0, hi = 1;
  bool Usable(double v) const { return std::isfinite(v) && (!log || v > 0); }
  double T(double v) const { return log ? std::log10(v) : v; }
  double Frac(double v) const { return (T(v) - lo) / (hi - lo); }
};

// Pixels kept clear between the data's extremes and the frame: the largest
// marker (a recommendation's 8 px ring), the 2 px gap and a 10 px label
// beside it, so no point or its label sits on the frame.
constexpr double kClearPx = 20;

// `px`: the axis's length in pixels.
Axis MakeAxis(Range r, bool log, double px) {
  Axis a;
  a.log = log;
  if (r.empty()) r = {log ? 1.0 : 0.0, log ? 10.0 : 1.0};
  a.lo = log ? std::log10(r.lo) : r.lo;
  a.hi = log ? std::log10(r.hi) : r.hi;
  if (a.hi - a.lo < 1e-12 * std::max(1.0, std::fabs(a.hi))) {
    const double pad = log ? 0.5 : std::max(1e-9, std::fabs(a.hi) * 0.1 + 1e-9);
    a.lo -= pad;
    a.hi += pad;
  } else {  // linear or in decades: points and lines at the ends stay off the frame
    // p of the span on each side puts the ends p / (1 + 2p) of the axis, at
    // least kClearPx, from the frame (and never less than 5 % of the span).
    const double room = std::max(px - 2 * kClearPx, kClearPx);
    const double pad = std::max(0.05, kClearPx / room) * (a.hi - a.lo);
    a.lo -= pad;
    a.hi += pad;
  }
  return a;
}

std::vector<double> Ticks(const Axis& a) {
  if (!a.log) return NiceTicks(a.lo, a.hi);
  std::vector<double> t;
  for (double e = std::ceil(a.lo); e <= std::floor(a.hi); e += 1) t.push_back(std::pow(10.0, e));
  if (t.size() >= 2) return t;
  // Less than two decades: 1, 2 and 5 times the powers of ten inside.
  t.clear();
  for (double e = std::floor(a.lo); e <= std::ceil(a.hi); e += 1) {
    for (double m : {1.0, 2.0, 5.0}) {
      const double v = m * std::pow(10.0, e);
      if (std::log10(v) >= a.lo - 1e-9 && std::log10(v) <= a.hi + 1e-9) t.push_back(v);
    }
  }
  if (t.size() < 2) return {std::pow(10.0, a.lo), std::pow(10.0, a.hi)};
  return t;
}

}  // namespace

std::vector<double> NiceTicks(double lo, double hi, int count) {
  if (!(hi > lo) || !std::isfinite(lo) || !std::isfinite(hi)) return {lo};
  const double raw = (hi - lo) / std::max(count, 2);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  for (double m : {1.0, 2.0, 2.5, 5.0, 10.0}) {
    step = m * mag;
    if (step >= raw) break;
  }
  std::vector<double> ticks;
  for (double v = std::ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) {
    ticks.push_back(std::fabs(v) < 1e-12 * step ? 0.0 : v);
  }
  return ticks;
}

namespace {

// Point labels that do not overlap: each label goes to the first spot around
// its point (right, left, above, below, then further out) whose box is free.
class LabelPlacer {
 public:
  // Labels stay inside the panel's frame (x0, y0)-(x1, y1) when a spot there is free.
  LabelPlacer(double x0, double y0, double x1, double y1) : x0_(x0), y0_(y0), x1_(x1), y1_(y1) {}
  // Where a label went: its text's baseline start and, when it could not sit
  // next to its point, the end of a leader line from the point to its box.
  struct Spot {
    double x, y;
    bool displaced;
    double leader_x, leader_y;
  };
  // @returns the spot for a 9 px label of `chars`.
  Spot Place(double x, double y, double r, size_t chars) {
    const double w = 5.6 * static_cast<double>(chars) + 2, h = 10;  // 9 px sans-serif
    const double gap = r + 2;
    // Candidate boxes (left, top) around the point.
    std::vector<std::pair<double, double>> spots = {
        {x + gap, y - gap - h}, {x + gap, y + gap},       {x - gap - w, y - gap - h},
        {x - gap - w, y + gap}, {x - w / 2, y - gap - h}, {x - w / 2, y + gap}};
    for (int k = 1; k <= 12; ++k) {
      spots.emplace_back(x + gap, y - gap - h - k * (h + 1));
      spots.emplace_back(x + gap, y + gap + k * (h + 1));
      spots.emplace_back(x - gap - w, y - gap - h - k * (h + 1));
      spots.emplace_back(x - gap - w, y + gap + k * (h + 1));
    }
    std::pair<double, double> chosen = spots.front();
    std::size_t k_chosen = 0;
    for (std::size_t k = 0; k < spots.size(); ++k) {
      const auto& s = spots[k];
      const bool inside =
          s.first >= x0_ && s.first + w <= x1_ && s.second >= y0_ && s.second + h <= y1_;
      if (inside && Free(s.first, s.second, w, h)) {
        chosen = s;
        k_chosen = k;
        break;
      }
    }
    boxes_.push_back({chosen.first, chosen.second, w, h});
    // The first six spots touch the point's marker; a label further out is
    // tied to its point by a leader, else a reader takes it for a neighbour's.
    const double lx = std::clamp(x, chosen.first, chosen.first + w);
    const double ly = std::clamp(y, chosen.second, chosen.second + h);
    return {chosen.first, chosen.second + h - 2, k_chosen >= 6, lx, ly};
  }

 private:
  struct Box {
    double x, y, w, h;
  };
  bool Free(double x, double y, double w, double h) const {
    for (const auto& b : boxes_)
      if (x < b.x + b.w && b.x < x + w && y < b.y + b.h && b.y < y + h) return false;
    return true;
  }
  double x0_, y0_, x1_, y1_;
  std::vector<Box> boxes_;
};

// The chart's margins (px): the legend sits in the right one.
constexpr int kLeft = 80, kRight = 190, kTop = 58, kGap = 60, kBottom = 50;

// The x axis of the panels that share it (only == nullptr) or of one panel
// with its own.
Axis XAxisOf(const Chart& chart, bool log, const Panel* only, int plot_w) {
  Range xr;
  for (const auto& p : chart.panels) {
    if (only ? &p != only : p.own_x) continue;
    for (const auto& s : p.series)
      for (double x : s.x)
        if (std::isfinite(x) && (!log || x > 0)) xr.Add(x);
  }
  return MakeAxis(xr, log, plot_w);
}

// A panel's y axis: its data's range, at least min_y_span wide when linear.
Axis YAxisOf(const Panel& panel, int height) {
  Range yr;
  for (const auto& s : panel.series)
    for (size_t i = 0; i < s.y.size() && i < s.x.size(); ++i)
      if (std::isfinite(s.y[i]) && (!panel.log_y || s.y[i] > 0)) yr.Add(s.y[i]);
  if (!panel.log_y && panel.min_y_span > 0 && !yr.empty() && yr.hi - yr.lo < panel.min_y_span) {
    const double mid = 0.5 * (yr.lo + yr.hi);
    yr.lo = mid - 0.5 * panel.min_y_span;
    yr.hi = mid + 0.5 * panel.min_y_span;
  }
  return MakeAxis(yr, panel.log_y, height);
}

// One panel's plot area in px.
struct PanelFrame {
  int plot_w, y0, h;
  Axis xa, ya;
  double Px(double x) const { return kLeft + xa.Frac(x) * plot_w; }
  double Py(double y) const { return y0 + h - ya.Frac(y) * h; }
  bool Usable(const Series& s, size_t i) const { return xa.Usable(s.x[i]) && ya.Usable(s.y[i]); }
};

// The panel's title, frame, grid with tick labels, and axis labels.
void WriteFrameAndGrid(const PanelFrame& f, const Panel& panel, std::ostringstream& svg) {
  const int left = kLeft, plot_w = f.plot_w, y0 = f.y0, h = f.h;
  svg << "<g class=\"panel\" data-title=\"" << SvgEscape(panel.title) << "\"";
  if (panel.own_x) svg << " data-x-label=\"" << SvgEscape(panel.x_label) << "\"";
  svg << ">\n"
      << "<text x=\"" << left << "\" y=\"" << y0 - 8 << "\" font-size=\"13\">"
      << SvgEscape(panel.title) << "</text>\n"
      << "<rect x=\"" << left << "\" y=\"" << y0 << "\" width=\"" << plot_w << "\" height=\"" << h
      << "\" fill=\"none\" stroke=\"#444\"/>\n";
  for (double t : Ticks(f.ya)) {
    if (!f.ya.Usable(t)) continue;
    const double y = f.Py(t);
    if (y < y0 - 0.5 || y > y0 + h + 0.5) continue;
    svg << "<line x1=\"" << left << "\" x2=\"" << left + plot_w << "\" y1=\"" << Num(y)
        << "\" y2=\"" << Num(y) << "\" stroke=\"#ddd\"/>"
        << "<text x=\"" << left - 6 << "\" y=\"" << Num(y + 4) << "\" text-anchor=\"end\">"
        << TickLabel(t) << "</text>\n";
  }
  for (double t : Ticks(f.xa)) {
    if (!f.xa.Usable(t)) continue;
    const double x = f.Px(t);
    if (x < left - 0.5 || x > left + plot_w + 0.5) continue;
    svg << "<line x1=\"" << Num(x) << "\" x2=\"" << Num(x) << "\" y1=\"" << y0 << "\" y2=\""
        << y0 + h << "\" stroke=\"#eee\"/>"
        << "<text x=\"" << Num(x) << "\" y=\"" << y0 + h + 16 << "\" text-anchor=\"middle\">"
        << TickLabel(t) << "</text>\n";
  }
  if (panel.own_x) {
    svg << "<text x=\"" << left + plot_w / 2 << "\" y=\"" << y0 + h + 32
        << "\" text-anchor=\"middle\">" << SvgEscape(panel.x_label) << "</text>\n";
  }
  svg << "<text transform=\"translate(" << left - 55 << ',' << y0 + h / 2
      << ") rotate(-90)\" text-anchor=\"middle\">" << SvgEscape(panel.y_label) << "</text>\n";
}

void WritePolyline(const PanelFrame& f, const Series& s, const char* width,
                   std::ostringstream& svg) {
  svg << "<polyline fill=\"none\" stroke=\"" << s.color << "\" stroke-width=\"" << width << "\""
      << (s.dashed ? " stroke-dasharray=\"6 3\"" : "") << " points=\"";
  for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
    if (!f.Usable(s, i)) continue;
    svg << Num(f.Px(s.x[i])) << ',' << Num(f.Py(s.y[i])) << ' ';
  }
  svg << "\"/>\n";
}

// Markers (optionally connected), each with its label where it has one.
void WriteMarkers(const PanelFrame& f, const Series& s, LabelPlacer& placed,
                  std::ostringstream& svg) {
  if (s.connect) WritePolyline(f, s, "1.2", svg);
  const double r = s.marker_radius > 0 ? s.marker_radius : (s.labels.empty() ? 1.8 : 3.5);
  for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
    if (!f.Usable(s, i)) continue;
    svg << "<circle cx=\"" << Num(f.Px(s.x[i])) << "\" cy=\"" << Num(f.Py(s.y[i])) << "\" r=\""
        << Num(r) << "\" "
        << (s.hollow ? "fill=\"none\" stroke-width=\"2.5\" stroke=\"" : "fill=\"") << s.color
        << "\"/>\n";
    if (i < s.labels.size() && !s.labels[i].empty()) {
      const auto at = placed.Place(f.Px(s.x[i]), f.Py(s.y[i]), r, s.labels[i].size());
      if (at.displaced)
        svg << "<line class=\"label-leader\" x1=\"" << Num(f.Px(s.x[i])) << "\" y1=\""
            << Num(f.Py(s.y[i])) << "\" x2=\"" << Num(at.leader_x) << "\" y2=\"" << Num(at.leader_y)
            << "\" stroke=\"" << s.color << "\" stroke-width=\"0.6\" stroke-opacity=\"0.7\"/>\n";
      svg << "<text class=\"point-label\" x=\"" << Num(at.x) << "\" y=\"" << Num(at.y)
          << "\" font-size=\"9\" fill=\"" << s.color << "\">" << SvgEscape(s.labels[i])
          << "</text>\n";
    }
  }
}

void WriteLegendEntry(const PanelFrame& f, const Series& s, int legend_y, std::ostringstream& svg) {
  const int left = kLeft, plot_w = f.plot_w;
  if (s.markers) {
    svg << "<circle cx=\"" << left + plot_w + 22 << "\" cy=\"" << legend_y - 4
        << "\" r=\"3\" fill=\"" << s.color << "\"/>";
  } else {
    svg << "<line x1=\"" << left + plot_w + 12 << "\" x2=\"" << left + plot_w + 32 << "\" y1=\""
        << legend_y - 4 << "\" y2=\"" << legend_y - 4 << "\" stroke=\"" << s.color
        << "\" stroke-width=\"3\"" << (s.dashed ? " stroke-dasharray=\"6 3\"" : "") << "/>";
  }
  svg << "<text x=\"" << left + plot_w + 38 << "\" y=\"" << legend_y << "\">" << SvgEscape(s.name)
      << "</text>\n";
}

void WritePanel(const Chart& chart, int pi, const Axis& shared_xa, int plot_w,
                std::ostringstream& svg) {
  const Panel& panel = chart.panels[pi];
  const int y0 = kTop + pi * (chart.panel_height + kGap);
  const PanelFrame f{plot_w, y0, chart.panel_height,
                     panel.own_x ? XAxisOf(chart, panel.log_x, &panel, plot_w) : shared_xa,
                     YAxisOf(panel, chart.panel_height)};
  WriteFrameAndGrid(f, panel, svg);
  int legend_y = y0 + 12;
  LabelPlacer placed(kLeft, y0, kLeft + plot_w, y0 + f.h);
  for (const auto& s : panel.series) {
    svg << "<g class=\"series\" id=\"p" << pi << '_' << Id(s.name) << "\" data-name=\""
        << SvgEscape(s.name) << "\">\n";
    if (s.markers) {
      WriteMarkers(f, s, placed, svg);
    } else {
      WritePolyline(f, s, "1.5", svg);
    }
    svg << "</g>\n";
    WriteLegendEntry(f, s, legend_y, svg);
    legend_y += 16;
  }
  svg << "</g>\n";
}

}  // namespace

// The title on one line, or two when it is wider than the picture (a closed-
// loop trial's deadline misses end it): split at the "; " or ", " nearest its
// middle, else at a space.
std::vector<std::string> TitleLines(const std::string& title, int width) {
  constexpr double kCharPx = 8.3;  // 15 px sans-serif
  if (title.size() * kCharPx <= width - 20) return {title};
  for (const char* sep : {"; ", ", ", " "}) {
    std::size_t best = std::string::npos;
    for (auto at = title.find(sep); at != std::string::npos; at = title.find(sep, at + 1))
      if (best == std::string::npos ||
          std::abs(2.0 * at - title.size()) < std::abs(2.0 * best - title.size()))
        best = at;
    if (best != std::string::npos && best > title.size() / 4 && best < 3 * title.size() / 4)
      return {title.substr(0, best + (sep[0] == ' ' ? 0 : 1)),
              title.substr(best + std::string(sep).size())};
  }
  return {title};
}

std::string RenderSvg(const Chart& chart) {
  const int plot_w = chart.width - kLeft - kRight;
  const int n = static_cast<int>(chart.panels.size());
  const int height = kTop + n * chart.panel_height + (n - 1) * kGap + kBottom;
  // The legend's longest entry widens the picture, never the plot (about 7 px
  // per character at 12 px): a long series name is read whole, not clipped.
  std::size_t longest = 0;
  for (const auto& p : chart.panels)
    for (const auto& s : p.series) longest = std::max(longest, s.name.size());
  const int width = std::max(chart.width, kLeft + plot_w + 48 + static_cast<int>(7 * longest));
  const Axis shared_xa = XAxisOf(chart, chart.log_x, nullptr, plot_w);
  const bool any_shared = std::any_of(chart.panels.begin(), chart.panels.end(),
                                      [](const Panel& p) { return !p.own_x; });

  std::ostringstream svg;
  svg << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
      << "\" viewBox=\"0 0 " << width << ' ' << height
      << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
      << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  const auto title = TitleLines(chart.title, width);
  for (std::size_t k = 0; k < title.size(); ++k)
    svg << "<text class=\"chart-title\" x=\"" << width / 2 << "\" y=\"" << 20 + 17 * k
        << "\" text-anchor=\"middle\" font-size=\"" << (k == 0 ? 15 : 13) << "\">"
        << SvgEscape(title[k]) << "</text>\n";
  for (int pi = 0; pi < n; ++pi) WritePanel(chart, pi, shared_xa, plot_w, svg);
  if (any_shared) {
    int last_shared = 0;
    for (int pi = 0; pi < n; ++pi)
      if (!chart.panels[pi].own_x) last_shared = pi;
    const int y = last_shared == n - 1
                      ? height - 12
                      : kTop + last_shared * (chart.panel_height + kGap) + chart.panel_height + 32;
    svg << "<text x=\"" << kLeft + plot_w / 2 << "\" y=\"" << y << "\" text-anchor=\"middle\">"
        << SvgEscape(chart.x_label) << "</text>\n";
  }
  svg << "</svg>\n";
  return svg.str();
}

std::string FormatNumber(double v, int significant) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.*g", significant, v);
  return buf;
}

double ScaleBarLength(double view_m) {
  const double target = view_m / 4;
  const double p = std::pow(10.0, std::floor(std::log10(target)));
  for (double m : {5.0, 2.0, 1.0})
    if (m * p <= target) return m * p;
  return p;
}

std::string FormatFixed(double v, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return buf;
}

}  // namespace arena::cli
