// Plausibility in the units a person types (issue 26): a campaign whose
// values are legal but cannot be what its author meant for the scene's
// scale (a push of 5 "m" meant as 5 mm, a speed of 10 "m/s" meant as
// 10 mm/s, a grip in kilonewtons on a 0.2 kg object) is refused naming the
// field written and the likely unit slip, before any scene is validated, so
// the blame does not land on a consequence (model.dt, the workspace).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/mechanics/pusher_motion.hpp"
#include "arena/orchestrator/campaign.hpp"

namespace arena::orchestrator {
namespace {

std::string G(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

// Every number a variation can take: a range's ends, each choice, the fixed value.
std::vector<double> Numbers(const Variation& v) {
  std::vector<double> out;
  if (v.type != ValueType::kNumber) return out;
  if (v.kind == Variation::Kind::kRange) return {v.min, v.max};
  for (const auto& c : v.choices)
    if (std::isfinite(c.number)) out.push_back(c.number);
  return out;
}

const Variation* Find(const Campaign& c, const std::string& name) {
  for (const auto& v : c.variations)
    if (v.name == name) return &v;
  return nullptr;
}

// The object's largest extent (m); 0 when the shape gives none.
double ObjectSize(const mechanics::ObjectSpec& o) {
  switch (o.shape) {
    case mechanics::ObjectShape::kBox:
      return o.size.maxCoeff();
    case mechanics::ObjectShape::kCylinder:
      return std::max(2 * o.radius, o.height);
    default: {
      double d = o.height;
      for (const auto& a : o.polygon)
        for (const auto& b : o.polygon) d = std::max(d, (a - b).norm());
      return d;
    }
  }
}

// The pusher speed limit the cells enforce: the campaign profile's
// max_pusher_speed, else the cells' default.
double PusherLimit(const Campaign& c) {
  constexpr double kDefaultLimit = 0.5;  // m/s, executors' DefectProfile default
  const auto d = nlohmann::json::parse(c.defects_json, nullptr, false);
  if (d.is_object() && d.contains("max_pusher_speed") && d["max_pusher_speed"].is_number())
    return d["max_pusher_speed"].get<double>();
  return kDefaultLimit;
}

}  // namespace

void CheckPlausibility(const Campaign& c) {
  const mechanics::Scene& s = c.scene;
  const double size = ObjectSize(s.object);
  const Variation* distance_var = Find(c, "push_distance");
  const Variation* speed_var = Find(c, "push_speed");
  const Variation* grip_var = Find(c, "grip_force");

  // Speeds: each push_speed, else the base scene's.
  std::vector<double> speeds;
  std::string speed_field = "scene.pusher.motion.velocity";
  if (speed_var) {
    speeds = Numbers(*speed_var);
    speed_field = "variations.push_speed";
  } else if (s.pusher && s.pusher->path) {
    // A recorded path: its fastest segment (its velocity field is unused).
    speeds = {mechanics::PusherPeakRates(*s.pusher).velocity.norm()};
    speed_field = "scene.pusher.motion.path";
  } else if (s.pusher && !s.pusher->controller) {
    speeds = {s.pusher->motion.velocity.norm()};
  }
  const double limit = PusherLimit(c);
  for (const double v : speeds) {
    if (v > limit) {
      throw CampaignError(speed_field,
                          G(v) + " m/s is above the pusher's limit of " + G(limit) +
                              " m/s (defects.max_pusher_speed; cells refuse a faster push); the "
                              "value is in m/s: " +
                              G(v) + " mm/s is " + G(v / 1000) + ". A faster cell: set " +
                              "defects.max_pusher_speed");
    }
  }

  // Push lengths: each push_distance, else the base scene's travel.
  constexpr double kMaxPushPerSize = 10;  // a push longer than 10 object sizes is a slip
  if (size > 0 && distance_var) {
    for (const double d : Numbers(*distance_var)) {
      if (d > kMaxPushPerSize * size) {
        throw CampaignError("variations.push_distance",
                            G(d) + " m is " + G(d / size) + " times the object's largest size (" +
                                G(size) + " m); the value is in metres: " + G(d) + " mm is " +
                                G(d / 1000));
      }
    }
  } else if (size > 0 && s.pusher && s.pusher->path) {
    // A recorded path: the farthest it takes the pusher from its start.
    double travel = 0;
    for (const auto& x : s.pusher->path->position) {
      travel = std::max(travel, (x - s.pusher->path->position.front()).norm());
    }
    if (travel > kMaxPushPerSize * size) {
      throw CampaignError("scene.pusher.motion.path", "moves the pusher " + G(travel) +
                                                          " m from its start, " + G(travel / size) +
                                                          " times the object's largest size (" +
                                                          G(size) + " m); positions are in metres");
    }
  } else if (size > 0 && s.pusher && !s.pusher->controller) {
    const double travel = s.pusher->motion.velocity.norm() * s.duration;
    if (travel > kMaxPushPerSize * size) {
      throw CampaignError("scene.duration",
                          G(s.duration) + " s at " + G(s.pusher->motion.velocity.norm()) +
                              " m/s pushes " + G(travel) + " m, " + G(travel / size) +
                              " times the object's largest size (" + G(size) +
                              " m); duration is in seconds and velocity in m/s");
    }
  }

  // A push shorter than one model step: blame the length or speed written.
  if (distance_var && !speeds.empty()) {
    const double v = *std::max_element(speeds.begin(), speeds.end());
    const auto ds = Numbers(*distance_var);
    // The cells' and the predictor's step; a step longer than 20 ms is itself
    // the slip (prediction.dt or model.dt is then blamed on its own).
    constexpr double kUsualStep = 0.02;
    const double step = std::max(s.model.dt <= kUsualStep ? s.model.dt : 0,
                                 c.prediction.dt <= kUsualStep ? c.prediction.dt : 0);
    if (!ds.empty() && v > 0) {
      const double d = *std::min_element(ds.begin(), ds.end());
      if (d / v < step) {
        throw CampaignError("variations.push_distance",
                            G(d) + " m at " + G(v) + " m/s lasts " + G(d / v * 1e3) +
                                " ms, shorter than one model step (" + G(step * 1e3) +
                                " ms); push_distance is in metres and push_speed in m/s");
      }
    }
  }

  // Grip against the object's weight.
  constexpr double kMaxGripPerWeight = 250;
  const double weight = s.object.mass * s.gravity.norm();
  if (weight > 0) {
    const std::vector<double> grips = grip_var ? Numbers(*grip_var) : std::vector{s.grip_force};
    const std::string field = grip_var ? "variations.grip_force" : "scene.grip_force";
    for (const double g : grips) {
      if (g > kMaxGripPerWeight * weight) {
        throw CampaignError(field, G(g) + " N is " + G(g / weight) + " times the weight of the " +
                                       G(s.object.mass) + " kg object (" + G(weight) +
                                       " N); the value is in newtons per finger: " + G(g) +
                                       " mN is " + G(g / 1000));
      }
    }
  }
}

}  // namespace arena::orchestrator
