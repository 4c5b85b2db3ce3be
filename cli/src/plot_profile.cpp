// arena plot --calibration ID: each fitted parameter's loss profile
// (assessment/calibration.hpp), one panel per parameter.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include <nlohmann/json.hpp>

#include "plot_charts.hpp"

namespace arena::cli {
namespace {

std::string Format(double v) { return FormatNumber(v, 4); }

// A vertical line at x over [lo, hi] (log y: both ends must be > 0).
Series Vertical(const std::string& name, double x, double lo, double hi, const char* color) {
  Series s{name, {x, x}, {lo, hi}, color};
  s.dashed = true;
  return s;
}

Panel ProfilePanel(const std::string& name, const nlohmann::json& p) {
  const nlohmann::json& profile = p.at("profile");
  Series loss{"loss " + name, {}, {}, "#1f77b4", true};
  loss.connect = true;
  for (const auto& point : profile.at("loss")) {
    const double scale = point.at(0).get<double>(), mean = point.at(1).get<double>();
    if (scale > 0 && mean > 0) {  // log axes
      loss.x.push_back(scale);
      loss.y.push_back(mean);
    }
  }
  if (loss.x.empty()) throw std::invalid_argument(name + ": its profile has no point to draw");
  const double lo = *std::min_element(loss.y.begin(), loss.y.end());
  const double hi = *std::max_element(loss.y.begin(), loss.y.end());
  const double fit = p.at("scale").get<double>();
  const double range_lo = profile.at("range").at(0).get<double>();
  const double range_hi = profile.at("range").at(1).get<double>();
  const bool bounded_lo = profile.at("bounded").at(0).get<bool>();
  const bool bounded_hi = profile.at("bounded").at(1).get<bool>();
  const bool identified = profile.at("identified").get<bool>();

  Panel panel;
  panel.title = name + ": fit " + Format(fit) + ", fits as well from " + Format(range_lo) +
                (bounded_lo ? "" : " (bound)") + " to " + Format(range_hi) +
                (bounded_hi ? "" : " (bound)") +
                (identified ? "" : ": NOT IDENTIFIED by these trials");
  panel.y_label = "mean training loss";
  panel.log_y = true;
  panel.own_x = true;
  panel.log_x = true;
  panel.x_label = "scale of " + name + " (others at the fit)";
  panel.series.push_back(loss);
  Series at_fit{"fit " + name, {fit}, {lo}, "#d62728", true};
  at_fit.labels = {"fit " + Format(fit)};
  panel.series.push_back(at_fit);
  panel.series.push_back(Vertical("fits as well from " + name, range_lo, lo, hi, "#7f7f7f"));
  panel.series.push_back(Vertical("fits as well up to " + name, range_hi, lo, hi, "#7f7f7f"));
  return panel;
}

}  // namespace

Chart CalibrationProfileChart(const nlohmann::json& params, const std::string& title) {
  if (!params.is_object()) throw std::invalid_argument("its parameters are not a JSON object");
  Chart chart;
  chart.title = title;
  for (const auto& [name, p] : params.items()) {
    if (p.is_object() && p.contains("profile")) chart.panels.push_back(ProfilePanel(name, p));
  }
  if (chart.panels.empty()) {
    throw std::invalid_argument(
        "it has no loss profile (fitted before profiles existed, or with --profile-points 0)");
  }
  return chart;
}

}  // namespace arena::cli
