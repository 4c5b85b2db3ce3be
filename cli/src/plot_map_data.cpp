// arena plot --campaign ID --map X,Y --metric M: gathers the map's data from
// the store (plot_map.hpp draws it).
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "arena/db/query.hpp"
#include "plot_map.hpp"
#include "plot_map_data.hpp"
#include "svg_chart.hpp"

namespace arena::cli {
namespace {

using nlohmann::json;

struct MetricInfo {
  const char* name;
  const char* label;  // with unit
  const char* sql;    // SELECT condition, value ... for campaign ?1 (grouped by condition)
  bool flag;
};

constexpr const char* kMean = "GROUP BY t.condition";

// Every metric as one SQL over the store's tables and views (db/README.md).
const std::vector<MetricInfo>& Metrics() {
  static const std::vector<MetricInfo> kMetrics = {
      {"displacement", "observed displacement (m), mean over replicates",
       "SELECT condition, avg(displacement_m) FROM trial_results WHERE campaign_id = ?1 "
       "GROUP BY condition",
       false},
      {"rotation", "observed rotation (rad), mean over replicates",
       "SELECT condition, avg(rotation_rad) FROM trial_results WHERE campaign_id = ?1 "
       "GROUP BY condition",
       false},
      {"position_error", "final position error (m), mean over replicates",
       "SELECT t.condition, avg(p.final_position_error) FROM trials t JOIN predictions p ON "
       "p.trial_id = t.id AND p.attempt = t.attempt WHERE t.campaign_id = ?1 ",
       false},
      {"angle_error", "final angle error (rad), mean over replicates",
       "SELECT t.condition, avg(p.final_angle_error) FROM trials t JOIN predictions p ON "
       "p.trial_id = t.id AND p.attempt = t.attempt WHERE t.campaign_id = ?1 ",
       false},
      {"force_error", "RMS contact force error (N), mean over replicates",
       "SELECT t.condition, avg(p.force_error) FROM trials t JOIN predictions p ON "
       "p.trial_id = t.id AND p.attempt = t.attempt WHERE t.campaign_id = ?1 ",
       false},
      {"mode_agreement", "contact mode agreement (fraction), mean over replicates",
       "SELECT t.condition, avg(p.mode_agreement) FROM trials t JOIN predictions p ON "
       "p.trial_id = t.id AND p.attempt = t.attempt WHERE t.campaign_id = ?1 ",
       false},
      {"predicted_spread", "predicted position spread (m)",
       "SELECT condition, predicted_position_spread FROM sensitivity_latest WHERE campaign_id = "
       "?1",
       false},
      {"observed_spread", "observed position spread (m)",
       "SELECT condition, observed_position_spread FROM sensitivity_latest WHERE campaign_id = ?1",
       false},
      {"predicted_rotation_spread", "predicted rotation spread (rad)",
       "SELECT condition, predicted_rotation_spread FROM sensitivity_latest WHERE campaign_id = "
       "?1",
       false},
      {"observed_rotation_spread", "observed rotation spread (rad)",
       "SELECT condition, observed_rotation_spread FROM sensitivity_latest WHERE campaign_id = ?1",
       false},
      {"spread_ratio", "observed / predicted position spread (1)",
       "SELECT condition, observed_position_spread / nullif(predicted_position_spread, 0) FROM "
       "sensitivity_latest WHERE campaign_id = ?1",
       false},
      {"predicted_displacement", "predicted displacement (m)",
       "SELECT condition, predicted_displacement FROM sensitivity_latest WHERE campaign_id = ?1",
       false},
      {"predicted_rotation", "predicted rotation (rad)",
       "SELECT condition, predicted_rotation FROM sensitivity_latest WHERE campaign_id = ?1",
       false},
      {"flip_fraction", "ensemble members with another contact-mode outcome (fraction)",
       "SELECT condition, flip_fraction FROM sensitivity_latest WHERE campaign_id = ?1", false},
      {"unstable", "unstable (sensitivity run)",
       "SELECT condition, unstable FROM sensitivity_latest WHERE campaign_id = ?1", true},
  };
  return kMetrics;
}

// Units of the campaign variations (orchestrator/README.md's catalogue).
std::string VariationUnit(const std::string& variation) {
  static const std::map<std::string, std::string> kUnits = {
      {"object_size_x", "m"},
      {"object_size_y", "m"},
      {"object_size_z", "m"},
      {"object_radius", "m"},
      {"object_height", "m"},
      {"object_mass", "kg"},
      {"finger_length", "m"},
      {"finger_radius", "m"},
      {"finger_mu", "1"},
      {"grip_force", "N"},
      {"pusher_length", "m"},
      {"pusher_radius", "m"},
      {"pusher_mu", "1"},
      {"pivot_offset", "m"},
      {"push_speed", "m/s"},
      {"push_distance", "m"},
      {"finger_type", "type"},
      {"pusher_type", "type"},
      {"push_direction", "unit vector, gripper frame"},
      {"pivot_axis", "unit vector, gripper frame"}};
  auto it = kUnits.find(variation);
  return it == kUnits.end() ? "?" : it->second;
}

std::optional<double> AsNumber(const db::Value& v) {
  if (const auto* d = std::get_if<double>(&v)) return *d;
  if (const auto* i = std::get_if<std::int64_t>(&v)) return static_cast<double>(*i);
  return std::nullopt;
}

}  // namespace

std::string MapMetricNames() {
  std::string s;
  for (const auto& m : Metrics()) s += (s.empty() ? "" : ", ") + std::string(m.name);
  return s;
}

MapData BuildCampaignMap(const db::Store& store, std::int64_t campaign_id, const std::string& x,
                         const std::string& y, const std::string& metric) {
  const auto it = std::find_if(Metrics().begin(), Metrics().end(),
                               [&](const MetricInfo& m) { return metric == m.name; });
  if (it == Metrics().end()) {
    throw std::invalid_argument("--metric: unknown metric '" + metric + "' (one of " +
                                MapMetricNames() + ")");
  }
  const db::Campaign campaign = store.GetCampaign(campaign_id);
  // Parameters of each condition (replicates share them).
  const std::string id = std::to_string(campaign_id);
  const auto params = db::RunQuery(
      store, "SELECT condition, min(params_json) FROM trials WHERE campaign_id = " + id +
                 " GROUP BY condition ORDER BY condition");
  std::string sql = std::string(it->sql);
  if (sql.find("JOIN predictions") != std::string::npos) sql += kMean;
  for (std::size_t p; (p = sql.find("?1")) != std::string::npos;) sql.replace(p, 2, id);
  std::map<int, std::optional<double>> values;
  for (const auto& row : db::RunQuery(store, sql).rows) {
    if (auto c = AsNumber(row[0])) values[static_cast<int>(*c)] = AsNumber(row[1]);
  }

  MapData map;
  map.flag = it->flag;
  map.flag_on = "unstable";
  map.flag_off = "stable";
  map.metric_label = it->label;
  map.x_label = x + " (" + VariationUnit(x) + ")";
  map.y_label = y + " (" + VariationUnit(y) + ")";
  map.title = "campaign " + id + " (" + campaign.name + "): " + metric + " over " + x + " and " + y;

  // Axis values: numbers, or categories (text / vectors) in order of first appearance.
  struct Raw {
    int condition;
    json xv, yv;
    json all;
  };
  std::vector<Raw> raws;
  std::set<std::string> varied;
  for (const auto& row : params.rows) {
    const auto c = AsNumber(row[0]);
    const auto* text = std::get_if<std::string>(&row[1]);
    if (!c || !text) continue;
    json pj = json::parse(*text, nullptr, false);
    if (!pj.is_object()) continue;
    for (auto kv = pj.begin(); kv != pj.end(); ++kv) varied.insert(kv.key());
    raws.push_back({static_cast<int>(*c), pj.value(x, json()), pj.value(y, json()), pj});
  }
  auto list = [&] {
    std::string s;
    for (const auto& v : varied) s += (s.empty() ? "" : ", ") + v;
    return s.empty() ? std::string("none") : s;
  };
  for (const auto& [axis, name] : {std::pair{0, x}, std::pair{1, y}}) {
    const bool present = std::any_of(raws.begin(), raws.end(), [&](const Raw& r) {
      return !(axis == 0 ? r.xv : r.yv).is_null();
    });
    if (!present) {
      throw std::invalid_argument("--map: campaign " + id + " has no parameter '" + name +
                                  "' (its parameters: " + list() + ")");
    }
  }
  auto categorical = [&](bool is_x) {
    return std::any_of(raws.begin(), raws.end(), [&](const Raw& r) {
      const json& v = is_x ? r.xv : r.yv;
      return !v.is_number();
    });
  };
  const bool cx = categorical(true), cy = categorical(false);
  auto coordinate = [](const json& v, bool cat, std::vector<std::string>* cats) {
    if (!cat) return v.get<double>();
    const std::string key = v.is_string() ? v.get<std::string>() : v.dump();
    auto f = std::find(cats->begin(), cats->end(), key);
    if (f == cats->end()) {
      cats->push_back(key);
      return static_cast<double>(cats->size() - 1);
    }
    return static_cast<double>(f - cats->begin());
  };
  // The other parameters that differ between conditions: what tells apart
  // conditions drawn at the same (x, y).
  std::set<std::string> differing;
  for (const auto& name : varied) {
    if (name == x || name == y) continue;
    std::set<std::string> seen;
    for (const auto& r : raws) seen.insert(r.all.value(name, json()).dump());
    if (seen.size() > 1) differing.insert(name);
  }
  for (const auto& r : raws) {
    MapPoint p;
    p.condition = r.condition;
    for (const auto& name : differing) {
      const json v = r.all.value(name, json());
      p.label += (p.label.empty() ? "" : ", ") + name + "=" +
                 (v.is_string()   ? v.get<std::string>()
                  : v.is_number() ? FormatNumber(v.get<double>(), 3)
                                  : v.dump());
    }
    p.x = coordinate(r.xv, cx, &map.x_categories);
    p.y = coordinate(r.yv, cy, &map.y_categories);
    if (auto v = values.find(r.condition); v != values.end()) p.value = v->second;
    map.points.push_back(p);
  }
  const long with_value = std::count_if(map.points.begin(), map.points.end(),
                                        [](const MapPoint& p) { return p.value.has_value(); });
  map.note = std::to_string(map.points.size()) + " conditions, " + std::to_string(with_value) +
             " with a value";
  if (with_value == 0 && std::string(it->sql).find("sensitivity_latest") != std::string::npos) {
    map.note += " (run `arena sensitivity --db FILE --campaign " + id + "` first)";
  }
  map.boundary = AdaptiveBoundaryPoints(store, campaign_id, x, y);
  return map;
}

std::vector<std::pair<double, double>> AdaptiveBoundaryPoints(const db::Store& store,
                                                              std::int64_t campaign_id,
                                                              const std::string& x,
                                                              const std::string& y) {
  // An adaptive (boundary) campaign records why it chose each trial
  // (sampler_decisions, schema version 7); the trials its nearest-neighbour
  // margin rule placed on the estimated boundary are the overlay. A store
  // without that table (older, or a binary without adaptive samplers) has none.
  const auto has =
      db::RunQuery(store,
                   "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = "
                   "'sampler_decisions'");
  if (has.rows.empty() || AsNumber(has.rows[0][0]).value_or(0) == 0) return {};
  const auto rows = db::RunQuery(
      store,
      "SELECT t.params_json FROM sampler_decisions d JOIN trials t ON t.id = d.trial_id WHERE "
      "d.campaign_id = " +
          std::to_string(campaign_id) +
          " AND json_extract(d.basis_json, '$.rule') = 'nn_margin' ORDER BY t.id");
  std::vector<std::pair<double, double>> out;
  for (const auto& row : rows.rows) {
    const auto* text = std::get_if<std::string>(&row[0]);
    if (!text) continue;
    const json p = json::parse(*text, nullptr, false);
    if (!p.is_object() || !p.value(x, json()).is_number() || !p.value(y, json()).is_number()) {
      continue;
    }
    out.emplace_back(p[x].get<double>(), p[y].get<double>());
  }
  return out;
}

}  // namespace arena::cli
