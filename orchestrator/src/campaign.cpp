// Campaign parsing, validation and planning (format: orchestrator/README.md).
#include "arena/orchestrator/campaign.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <sstream>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/assessment/sensitivity.hpp"
#include "arena/mechanics/frames.hpp"
#include "arena/mechanics/json_path.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/sampler.hpp"
#include "arena/simulators/simulator.hpp"

namespace arena::orchestrator {

using mechanics::ContactSpec;
using mechanics::ContactType;
using mechanics::Scene;
using nlohmann::json;

CampaignError::CampaignError(std::string field, const std::string& reason)
    : Error(ErrorCategory::kBadInput,
            (field.empty() ? std::string("campaign") : field) + ": " + reason),
      field_(std::move(field)),
      reason_(reason) {}

const char* ToString(SamplerKind kind) {
  switch (kind) {
    case SamplerKind::kGrid:
      return "grid";
    case SamplerKind::kUniform:
      return "uniform";
    case SamplerKind::kLatinHypercube:
      return "latin_hypercube";
    case SamplerKind::kSobol:
      return "sobol";
  }
  return "?";
}

const char* ToString(AdaptiveKind kind) {
  switch (kind) {
    case AdaptiveKind::kBoundary:
      return "boundary";
    case AdaptiveKind::kReplicates:
      return "replicates";
  }
  return "?";
}

const char* ToString(OutcomeKind kind) {
  switch (kind) {
    case OutcomeKind::kPivoted:
      return "pivoted";
    case OutcomeKind::kFingerSlip:
      return "finger_slip";
    case OutcomeKind::kGraspKept:
      return "grasp_kept";
  }
  return "?";
}

namespace {

constexpr int kMaxJsonDepth = 16;
constexpr std::size_t kMaxJsonArray = 4096;

// The variation space: every name a campaign may vary, in canonical order
// (the order they are applied to the base scene and the sampler's dimension
// order). lower/strict: the value must be > lower (strict) or >= lower.
struct VariationInfo {
  const char* name;
  ValueType type;
  double lower;
  bool strict;
  const char* unit;  // SI (VariationUnit)
};
constexpr double kNoBound = -std::numeric_limits<double>::infinity();
constexpr std::array<VariationInfo, 22> kVariationCatalog = {{
    {"object_size_x", ValueType::kNumber, 0, true, "m"},  // box extents
    {"object_size_y", ValueType::kNumber, 0, true, "m"},
    {"object_size_z", ValueType::kNumber, 0, true, "m"},
    {"object_radius", ValueType::kNumber, 0, true, "m"},  // cylinder
    {"object_height", ValueType::kNumber, 0, true, "m"},
    {"object_mass", ValueType::kNumber, 0, true, "kg"},
    {"finger_type", ValueType::kContactType, 0, false, ""},
    {"finger_length", ValueType::kNumber, 0, true, "m"},  // line fingers
    {"finger_radius", ValueType::kNumber, 0, true, "m"},  // patch fingers
    {"finger_mu", ValueType::kNumber, 0, false, "1"},
    {"grip_force", ValueType::kNumber, 0, false, "N"},
    {"pusher_type", ValueType::kContactType, 0, false, ""},
    {"pusher_length", ValueType::kNumber, 0, true, "m"},
    {"pusher_radius", ValueType::kNumber, 0, true, "m"},
    {"pusher_mu", ValueType::kNumber, 0, false, "1"},
    {"pivot_axis", ValueType::kVector, 0, false,
     "unit vector, gripper frame"},                              // in the pusher's contact plane
    {"pivot_offset", ValueType::kNumber, kNoBound, false, "m"},  // along pivot_axis
    {"push_direction", ValueType::kVector, 0, false, "unit vector, gripper frame"},
    {"push_speed", ValueType::kNumber, 0, false, "m/s"},
    {"push_distance", ValueType::kNumber, 0, true, "m"},  // sets duration = distance / speed
    // Closed loop (issue 19): the scene's pusher.motion controller settings.
    {"controller_target", ValueType::kNumber, kNoBound, false, ""},  // controller's units
    {"controller_gain", ValueType::kNumber, kNoBound, false, ""},
}};

const VariationInfo* FindVariation(std::string_view name) {
  for (const auto& v : kVariationCatalog) {
    if (name == v.name) return &v;
  }
  return nullptr;
}

int CatalogIndex(std::string_view name) {
  for (size_t i = 0; i < kVariationCatalog.size(); ++i) {
    if (name == kVariationCatalog[i].name) return static_cast<int>(i);
  }
  return static_cast<int>(kVariationCatalog.size());
}

using mechanics::json_path::Index;
using mechanics::json_path::Join;
using mechanics::json_path::Num;
using mechanics::json_path::Printable;

std::string TypeName(const json& v) {
  if (v.is_number()) return "a number";
  if (v.is_string()) return "a string";
  if (v.is_boolean()) return "a boolean";
  if (v.is_null()) return "null";
  if (v.is_array()) return "an array";
  return "an object";
}

void RequireObject(const json& v, const std::string& path,
                   std::initializer_list<std::string_view> known) {
  if (!v.is_object()) throw CampaignError(path, "must be an object, got " + TypeName(v));
  for (const auto& item : v.items()) {
    if (std::find(known.begin(), known.end(), item.key()) == known.end()) {
      std::string list;
      for (auto k : known) list += (list.empty() ? "" : ", ") + std::string(k);
      throw CampaignError(Join(path, item.key()), "unknown key (expected one of: " + list + ")");
    }
  }
}

double Number(const json& v, const std::string& path) {
  if (!v.is_number()) throw CampaignError(path, "must be a number, got " + TypeName(v));
  const double x = v.get<double>();
  if (!std::isfinite(x)) throw CampaignError(path, "must be finite");
  return x;
}

int64_t Integer(const json& v, const std::string& path, int64_t lo, int64_t hi) {
  const std::string range =
      "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  if (!v.is_number()) throw CampaignError(path, "must be " + range + ", got " + TypeName(v));
  const double x = v.get<double>();
  if (std::floor(x) != x || x < static_cast<double>(lo) || x > static_cast<double>(hi)) {
    throw CampaignError(path, "must be " + range + ", got " + Num(x));
  }
  return static_cast<int64_t>(x);
}

std::string String(const json& v, const std::string& path) {
  if (!v.is_string()) throw CampaignError(path, "must be a string, got " + TypeName(v));
  return v.get<std::string>();
}

VariationValue ReadValue(const json& v, const std::string& path, const VariationInfo& info) {
  VariationValue value;
  switch (info.type) {
    case ValueType::kNumber: {
      value.number = Number(v, path);
      const bool ok = info.strict ? value.number > info.lower : value.number >= info.lower;
      if (!ok) {
        throw CampaignError(path, std::string("must be ") + (info.strict ? "> " : ">= ") +
                                      Num(info.lower) + ", got " + Num(value.number));
      }
      break;
    }
    case ValueType::kContactType: {
      const std::string text = String(v, path);
      const auto type = mechanics::ContactTypeFromString(text);
      if (!type) {
        throw CampaignError(
            path, "must be \"point\", \"line\" or \"patch\", got \"" + Printable(text, 40) + "\"");
      }
      value.contact_type = *type;
      break;
    }
    case ValueType::kVector: {
      if (!v.is_array() || v.size() != 3)
        throw CampaignError(path, "must be an array of 3 numbers");
      for (int i = 0; i < 3; ++i)
        value.vector[i] = Number(v[i], Index(path, static_cast<size_t>(i)));
      const double n = value.vector.norm();
      if (!(n > 0)) throw CampaignError(path, "must be a non-zero direction");
      value.vector /= n;  // a direction: only where it points matters
      break;
    }
  }
  return value;
}

Variation ReadVariation(const json& v, const std::string& path, const VariationInfo& info,
                        bool grid) {
  Variation var;
  var.name = info.name;
  var.type = info.type;
  const bool spec = v.is_object();
  if (!spec) {  // a bare value: fixed
    var.kind = Variation::Kind::kFixed;
    var.choices.push_back(ReadValue(v, path, info));
    return var;
  }
  if (v.contains("choices")) {
    RequireObject(v, path, {"choices"});
    const json& c = v["choices"];
    const std::string cpath = Join(path, "choices");
    if (!c.is_array() || c.empty()) throw CampaignError(cpath, "must be a non-empty array");
    if (c.size() > static_cast<size_t>(kMaxChoices)) {
      throw CampaignError(cpath, "must have at most " + std::to_string(kMaxChoices) + " choices");
    }
    var.kind = Variation::Kind::kChoices;
    for (size_t i = 0; i < c.size(); ++i)
      var.choices.push_back(ReadValue(c[i], Index(cpath, i), info));
    return var;
  }
  if (v.contains("value")) {
    RequireObject(v, path, {"value"});
    var.kind = Variation::Kind::kFixed;
    var.choices.push_back(ReadValue(v["value"], Join(path, "value"), info));
    return var;
  }
  RequireObject(v, path, {"min", "max", "scale", "levels"});
  if (info.type != ValueType::kNumber) {
    throw CampaignError(path,
                        "a range is only possible for numbers; give \"choices\" or a fixed value");
  }
  if (!v.contains("min"))
    throw CampaignError(Join(path, "min"), "is required (or give \"choices\" or \"value\")");
  if (!v.contains("max")) throw CampaignError(Join(path, "max"), "is required");
  var.kind = Variation::Kind::kRange;
  var.min = ReadValue(v["min"], Join(path, "min"), info).number;
  var.max = ReadValue(v["max"], Join(path, "max"), info).number;
  if (var.max < var.min) {
    throw CampaignError(Join(path, "max"),
                        "must be >= min (" + Num(var.min) + "), got " + Num(var.max));
  }
  if (v.contains("scale")) {
    const std::string scale = String(v["scale"], Join(path, "scale"));
    if (scale == "log") {
      var.log_scale = true;
    } else if (scale != "linear") {
      throw CampaignError(Join(path, "scale"),
                          "must be \"linear\" or \"log\", got \"" + Printable(scale, 40) + "\"");
    }
    if (var.log_scale && !(var.min > 0)) {
      throw CampaignError(Join(path, "min"), "must be > 0 for scale \"log\", got " + Num(var.min));
    }
  }
  if (v.contains("levels")) {
    var.levels = static_cast<int>(Integer(v["levels"], Join(path, "levels"), 1, kMaxGridLevels));
  }
  if (grid && var.min < var.max) {
    if (var.levels == 0)
      throw CampaignError(Join(path, "levels"), "is required by the grid sampler");
    if (var.levels < 2)
      throw CampaignError(Join(path, "levels"), "must be >= 2 for a range with min < max");
  }
  return var;
}

// ---------------------------------------------------------------------------
// Applying a condition's values to the base scene.

using mechanics::FirstTangent;
using mechanics::RotationFromRpy;

// Stretches the object by k (per axis of the object frame) and carries each
// contact along: a point on a face stays on that face, normals transform by
// the inverse transpose, a line keeps its ends on the surface.
void ScaleContact(ContactSpec* c, const mechanics::Pose& pose, const Eigen::Vector3d& k) {
  const Eigen::Matrix3d R_GO = RotationFromRpy(pose.rpy);
  const Eigen::Vector3d p_O = R_GO.transpose() * (c->position - pose.position);
  c->position = pose.position + R_GO * p_O.cwiseProduct(k);
  const Eigen::Vector3d n_O = (R_GO.transpose() * c->normal).cwiseQuotient(k);
  c->normal = R_GO * n_O.normalized();
  if (c->type == ContactType::kLine) {
    const Eigen::Vector3d a_O = (R_GO.transpose() * c->axis).cwiseProduct(k);
    c->length *= a_O.norm();
    Eigen::Vector3d axis = R_GO * a_O.normalized();
    c->axis = (axis - axis.dot(c->normal) * c->normal).normalized();
  }
}

// Turns a contact into `type`; a new line lies along the contact's first
// tangent (docs/scene.md basis).
void ChangeType(ContactSpec* c, ContactType type) {
  if (c->type == type) return;
  c->type = type;
  if (type == ContactType::kLine) c->axis = FirstTangent(c->normal);
}

using Values = std::map<std::string, VariationValue>;

const VariationValue* Get(const Values& values, const char* name) {
  const auto it = values.find(name);
  return it == values.end() ? nullptr : &it->second;
}

// The scene of one condition. @throws CampaignError (variations.*) when the
// combination cannot be built; the result is not yet validated.
Scene BuildScene(const Scene& base, const Values& values) {
  Scene s = base;
  // Geometry first: contacts move with the surface they sit on.
  Eigen::Vector3d k = Eigen::Vector3d::Ones();
  if (s.object.shape == mechanics::ObjectShape::kBox) {
    const char* names[3] = {"object_size_x", "object_size_y", "object_size_z"};
    for (int i = 0; i < 3; ++i) {
      if (const auto* v = Get(values, names[i])) k[i] = v->number / s.object.size[i];
    }
    s.object.size = s.object.size.cwiseProduct(k);
  } else {
    if (const auto* v = Get(values, "object_radius")) k.x() = k.y() = v->number / s.object.radius;
    if (const auto* v = Get(values, "object_height")) k.z() = v->number / s.object.height;
    s.object.radius *= k.x();
    s.object.height *= k.z();
  }
  if (k != Eigen::Vector3d::Ones()) {
    for (auto& f : s.fingers) ScaleContact(&f, s.object.pose, k);
    if (s.pusher) ScaleContact(&*s.pusher, s.object.pose, k);
  }
  if (const auto* v = Get(values, "object_mass")) {
    if (s.object.inertia)
      *s.object.inertia *= v->number / s.object.mass;  // same shape, scaled density
    s.object.mass = v->number;
  }

  // Contacts: type, then the parameters of that type.
  auto apply_contact = [&](ContactSpec* c, const std::string& path, const char* type_name,
                           const char* length_name, const char* radius_name, const char* mu_name) {
    if (const auto* v = Get(values, type_name)) {
      const ContactType before = c->type;
      ChangeType(c, v->contact_type);
      if (v->contact_type == ContactType::kLine && before != ContactType::kLine &&
          !Get(values, length_name)) {
        throw CampaignError(std::string("variations.") + type_name,
                            std::string("\"line\" needs variations.") + length_name + " (" + path +
                                " is a " + mechanics::ToString(before) + " in the base scene)");
      }
      if (v->contact_type == ContactType::kPatch && before != ContactType::kPatch &&
          !Get(values, radius_name)) {
        throw CampaignError(std::string("variations.") + type_name,
                            std::string("\"patch\" needs variations.") + radius_name + " (" + path +
                                " is a " + mechanics::ToString(before) + " in the base scene)");
      }
    }
    if (const auto* v = Get(values, length_name); v && c->type == ContactType::kLine)
      c->length = v->number;
    if (const auto* v = Get(values, radius_name); v && c->type == ContactType::kPatch)
      c->radius = v->number;
    if (const auto* v = Get(values, mu_name)) c->mu = v->number;
  };
  for (size_t i = 0; i < s.fingers.size(); ++i) {
    apply_contact(&s.fingers[i], Index("scene.fingers", i), "finger_type", "finger_length",
                  "finger_radius", "finger_mu");
  }
  if (const auto* v = Get(values, "grip_force")) s.grip_force = v->number;

  if (s.pusher) {
    mechanics::PusherSpec& p = *s.pusher;
    apply_contact(&p, "scene.pusher", "pusher_type", "pusher_length", "pusher_radius", "pusher_mu");
    if (const auto* offset = Get(values, "pivot_offset")) {
      Eigen::Vector3d axis = FirstTangent(p.normal);
      if (const auto* a = Get(values, "pivot_axis")) axis = a->vector;
      if (std::abs(axis.dot(p.normal)) > 1e-6) {
        throw CampaignError("variations.pivot_axis",
                            "must be perpendicular to the pusher's normal (" + Num(p.normal.x()) +
                                ", " + Num(p.normal.y()) + ", " + Num(p.normal.z()) + ")");
      }
      p.position += offset->number * axis;
    }
    const Eigen::Vector3d base_velocity = p.motion.velocity;
    const auto* direction = Get(values, "push_direction");
    const auto* speed = Get(values, "push_speed");
    // A recorded path has no velocity to vary (its velocity field is unused).
    if (p.path && (direction || speed || Get(values, "push_distance"))) {
      throw CampaignError("scene.pusher.motion.path",
                          "a recorded path cannot take variations.push_direction, push_speed or "
                          "push_distance (it has no velocity to vary)");
    }
    if (direction || speed) {
      const double v = speed ? speed->number : base_velocity.norm();
      if (!direction && !(base_velocity.norm() > 0)) {
        throw CampaignError(
            "variations.push_speed",
            "needs variations.push_direction (the base scene's pusher does not move)");
      }
      const Eigen::Vector3d dir =
          direction ? direction->vector : Eigen::Vector3d(base_velocity.normalized());
      p.motion.velocity = v * dir;
    }
    if (const auto* distance = Get(values, "push_distance")) {
      const double v = p.motion.velocity.norm();
      if (!(v > 0)) {
        throw CampaignError(
            "variations.push_distance",
            "needs a pusher speed > 0 (variations.push_speed or the base scene's velocity)");
      }
      s.duration = distance->number / v;
    }
    const auto* target = Get(values, "controller_target");
    const auto* gain = Get(values, "controller_gain");
    if ((target || gain) && !p.controller) {
      throw CampaignError(target ? "variations.controller_target" : "variations.controller_gain",
                          "needs a closed-loop scene (pusher.motion {\"controller\": NAME})");
    }
    if (target) p.controller->target = target->number;
    if (gain) p.controller->gain = gain->number;
  }
  return s;
}

json ValueJson(const Variation& var, const VariationValue& v) {
  switch (var.type) {
    case ValueType::kNumber:
      return v.number;
    case ValueType::kContactType:
      return mechanics::ToString(v.contact_type);
    case ValueType::kVector:
      return json::array({v.vector.x(), v.vector.y(), v.vector.z()});
  }
  return nullptr;
}

VariationValue RangeValue(const Variation& var, double u) {
  VariationValue v;
  v.number = var.log_scale
                 ? std::exp(std::log(var.min) + u * (std::log(var.max) - std::log(var.min)))
                 : var.min + u * (var.max - var.min);
  v.number = std::clamp(v.number, var.min, var.max);  // rounding only: u is in [0, 1]
  return v;
}

// Values of every variation for one condition.
Values ConditionValues(const Campaign& c, int64_t condition) {
  Values values;
  if (c.sampler == SamplerKind::kGrid) {
    int64_t rest = condition;  // mixed radix, first sampled variation fastest
    for (const auto& var : c.variations) {
      if (!var.IsSampled()) {
        values[var.name] =
            var.kind == Variation::Kind::kRange ? RangeValue(var, 0) : var.choices[0];
        continue;
      }
      const int64_t radix = var.kind == Variation::Kind::kRange
                                ? var.levels
                                : static_cast<int64_t>(var.choices.size());
      const int64_t digit = rest % radix;
      rest /= radix;
      values[var.name] =
          var.kind == Variation::Kind::kRange
              ? RangeValue(var, static_cast<double>(digit) / static_cast<double>(radix - 1))
              : var.choices[static_cast<size_t>(digit)];
    }
    return values;
  }
  const std::vector<double> point = ConditionPoint(c, condition);
  size_t d = 0;
  for (const auto& var : c.variations) {
    if (!var.IsSampled()) {
      values[var.name] = var.kind == Variation::Kind::kRange ? RangeValue(var, 0) : var.choices[0];
      continue;
    }
    const double u = point[d++];
    if (var.kind == Variation::Kind::kRange) {
      values[var.name] = RangeValue(var, u);
    } else {
      const auto n = var.choices.size();
      values[var.name] =
          var.choices[std::min(n - 1, static_cast<size_t>(u * static_cast<double>(n)))];
    }
  }
  return values;
}

// Values of every variation at a point u of the unit box (sampled ranges only).
Values PointValues(const Campaign& c, const std::vector<double>& u) {
  Values values;
  size_t d = 0;
  for (const auto& var : c.variations) {
    if (!var.IsSampled()) {
      values[var.name] = var.kind == Variation::Kind::kRange ? RangeValue(var, 0) : var.choices[0];
      continue;
    }
    values[var.name] = RangeValue(var, u.at(d++));
  }
  return values;
}

OutcomeKind ReadOutcome(const json& v, const std::string& path) {
  const std::string name = String(v, path);
  if (name == "pivoted") return OutcomeKind::kPivoted;
  if (name == "finger_slip") return OutcomeKind::kFingerSlip;
  if (name == "grasp_kept") return OutcomeKind::kGraspKept;
  throw CampaignError(path, "must be \"pivoted\", \"finger_slip\" or \"grasp_kept\", got \"" +
                                Printable(name, 40) + "\"");
}

// "scheduling": {"change_aware": bool, "window": K} (claim_chooser.hpp).
SchedulingOptions ReadSchedulingBlock(const json& v) {
  RequireObject(v, "scheduling", {"change_aware", "window"});
  SchedulingOptions s;
  if (v.contains("change_aware")) {
    if (!v["change_aware"].is_boolean())
      throw CampaignError("scheduling.change_aware",
                          "must be true or false, got " + TypeName(v["change_aware"]));
    s.change_aware = v["change_aware"].get<bool>();
  }
  if (v.contains("window"))
    s.window = static_cast<int>(Integer(v["window"], "scheduling.window", 1, kMaxSchedulingWindow));
  return s;
}

// "sampler": {"adaptive": ...} (orchestrator/README.md, "Adaptive samplers").
AdaptiveSpec ReadAdaptive(const json& v, SamplerKind* base) {
  if (!v.contains("adaptive"))
    throw CampaignError("sampler.adaptive", "is required in a sampler object");
  const std::string kind = String(v["adaptive"], "sampler.adaptive");
  AdaptiveSpec a;
  auto number = [&](const char* key, double lo, double hi, bool lo_open, double* out) {
    if (!v.contains(key)) return;
    const std::string path = std::string("sampler.") + key;
    const double x = Number(v[key], path);
    if ((lo_open ? !(x > lo) : !(x >= lo)) || !(x <= hi)) {
      throw CampaignError(path, "must be in " + std::string(lo_open ? "(" : "[") + Num(lo) + ", " +
                                    Num(hi) + "], got " + Num(x));
    }
    *out = x;
  };
  auto integer = [&](const char* key, int64_t lo, int64_t hi, int* out) {
    if (v.contains(key))
      *out = static_cast<int>(Integer(v[key], std::string("sampler.") + key, lo, hi));
  };
  integer("batch", 1, 1000, &a.batch);
  if (v.contains("pipeline")) {
    if (!v["pipeline"].is_boolean())
      throw CampaignError("sampler.pipeline", "must be true or false");
    a.pipeline = v["pipeline"].get<bool>();
    a.pipeline_given = true;
  }
  if (kind == "boundary") {
    RequireObject(v, "sampler",
                  {"adaptive", "outcome", "threshold", "resolution", "coarse_levels", "batch",
                   "max_trials", "pipeline"});
    a.kind = AdaptiveKind::kBoundary;
    if (!v.contains("outcome"))
      throw CampaignError("sampler.outcome", "is required (pivoted, finger_slip or grasp_kept)");
    a.outcome = ReadOutcome(v["outcome"], "sampler.outcome");
    a.threshold = a.outcome == OutcomeKind::kPivoted      ? 0.05
                  : a.outcome == OutcomeKind::kFingerSlip ? 0.5
                                                          : 0.01;
    number("threshold", 0, 1e3, true, &a.threshold);
    number("resolution", 0, 0.5, true, &a.resolution);
    if (a.resolution < 0.002)
      throw CampaignError("sampler.resolution", "must be >= 0.002, got " + Num(a.resolution));
    integer("coarse_levels", 2, 33, &a.coarse_levels);
    a.max_trials = 200;
    integer("max_trials", 2, 100000, &a.max_trials);
    return a;
  }
  if (kind == "replicates") {
    RequireObject(v, "sampler",
                  {"adaptive", "base", "min_replicates", "max_replicates", "ci_position",
                   "ci_angle", "confidence", "batch", "max_trials", "pipeline"});
    a.kind = AdaptiveKind::kReplicates;
    *base = SamplerKind::kSobol;
    if (v.contains("base")) {
      const std::string b = String(v["base"], "sampler.base");
      if (b == "grid")
        *base = SamplerKind::kGrid;
      else if (b == "uniform")
        *base = SamplerKind::kUniform;
      else if (b == "latin_hypercube")
        *base = SamplerKind::kLatinHypercube;
      else if (b != "sobol")
        throw CampaignError("sampler.base",
                            "must be \"grid\", \"uniform\", \"latin_hypercube\" or \"sobol\", "
                            "got \"" +
                                Printable(b, 40) + "\"");
    }
    integer("min_replicates", 2, kMaxReplicates, &a.min_replicates);
    integer("max_replicates", 2, kMaxReplicates, &a.max_replicates);
    if (a.max_replicates < a.min_replicates) {
      throw CampaignError("sampler.max_replicates",
                          "must be >= min_replicates (" + std::to_string(a.min_replicates) + ")");
    }
    number("ci_position", 0, 1, true, &a.ci_position);
    number("ci_angle", 0, 3.2, false, &a.ci_angle);
    number("confidence", 0.5, 0.999, false, &a.confidence);
    a.max_trials = static_cast<int>(kMaxTrials);
    integer("max_trials", 2, kMaxTrials, &a.max_trials);
    return a;
  }
  throw CampaignError("sampler.adaptive", "must be \"boundary\" or \"replicates\", got \"" +
                                              Printable(kind, 40) + "\"");
}

// The boundary sampler works in a box of 1 to 3 numeric ranges.
void CheckBoundaryVariations(const json& doc, const Campaign& c) {
  for (const char* key : {"conditions", "trials"}) {
    if (doc.contains(key))
      throw CampaignError(key,
                          "the boundary sampler chooses its points; bound it with "
                          "sampler.max_trials instead");
  }
  int dims = 0;
  for (const auto& var : c.variations) {
    if (!var.IsSampled()) continue;
    if (var.kind != Variation::Kind::kRange) {
      throw CampaignError("variations." + var.name,
                          "the boundary sampler needs numeric ranges (min < max), not choices");
    }
    ++dims;
  }
  if (dims < 1 || dims > 3) {
    throw CampaignError("variations", "the boundary sampler needs 1 to 3 ranges (min < max), got " +
                                          std::to_string(dims));
  }
}

std::string ParametersJson(const Campaign& c, const Values& values) {
  json out = json::object();
  for (const auto& var : c.variations) out[var.name] = ValueJson(var, values.at(var.name));
  return out.dump();
}

std::string ReadFileLimited(const std::filesystem::path& path, const std::string& field) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw CampaignError(field, "cannot open '" + path.string() + "'");
  const std::streamoff size = in.tellg();
  if (size < 0) throw CampaignError(field, "cannot read '" + path.string() + "'");
  if (static_cast<std::uintmax_t>(size) > kMaxCampaignBytes) {
    throw CampaignError(field, "'" + path.string() + "' is " + std::to_string(size) +
                                   " bytes, larger than the limit of " +
                                   std::to_string(kMaxCampaignBytes) + " bytes (1 MiB)");
  }
  in.seekg(0);
  std::string text(static_cast<size_t>(size), '\0');
  in.read(text.data(), size);
  if (!in) throw CampaignError(field, "cannot read '" + path.string() + "'");
  return text;
}

// Parses a document whose paths are reported under `field`. The first pass
// (FindJsonProblem) names the path of a syntax error, a non-UTF-8 byte or a
// duplicate key and bounds size, nesting and array length.
json ParseJson(std::string_view text, const std::string& field) {
  const mechanics::JsonLimits limits{kMaxCampaignBytes, kMaxJsonDepth, kMaxJsonArray};
  if (const auto problem = mechanics::FindJsonProblem(text, limits)) {
    const std::string path = problem->path.empty()     ? field
                             : field.empty()           ? problem->path
                             : problem->path[0] == '[' ? field + problem->path
                                                       : field + "." + problem->path;
    throw CampaignError(path, problem->reason);
  }
  return json::parse(text.begin(), text.end());
}

mechanics::Scene WithModel(mechanics::Scene scene, const mechanics::ModelOptions& model) {
  scene.model = model;
  return scene;
}

bool ValidName(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  return std::all_of(name.begin(), name.end(), [](char ch) {
    return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') ||
           ch == '_' || ch == '-' || ch == '.';
  });
}

// --- ParseCampaign's readers, one per field group, in the order it calls them
// (the order decides which of two faults a campaign is refused for first).

// name, description, seed, priority.
void ReadIdentity(const json& doc, Campaign* c) {
  if (!doc.contains("name")) throw CampaignError("name", "is required");
  c->name = String(doc["name"], "name");
  if (!ValidName(c->name)) {
    throw CampaignError("name", "must be 1 to 64 letters, digits, '_', '-' or '.', got \"" +
                                    Printable(c->name, 40) + "\"");
  }
  if (doc.contains("description")) c->description = String(doc["description"], "description");
  if (!doc.contains("seed"))
    throw CampaignError("seed", "is required (sampling is deterministic from it)");
  const json& seed = doc["seed"];
  if (!seed.is_number_integer() || (seed.is_number_integer() && !seed.is_number_unsigned())) {
    throw CampaignError("seed",
                        "must be a non-negative integer below 2^64, got " +
                            (seed.is_number() ? Printable(seed.dump(), 40) : TypeName(seed)));
  }
  c->seed = seed.get<uint64_t>();
  if (doc.contains("priority"))
    c->priority = static_cast<int>(Integer(doc["priority"], "priority", -1000, 1000));
}

// A JSON-lines file of scenes: {"scene": {...}, "seed": "..."} (an arena
// dataset's scenes.jsonl) or bare scenes.
json ReadScenesFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CampaignError("scenes", "cannot open '" + path.string() + "'");
  json list = json::array();
  std::string line;
  std::size_t bytes = 0;
  for (int number = 1; std::getline(in, line); ++number) {
    bytes += line.size() + 1;
    if (bytes > kMaxScenesFileBytes)
      throw CampaignError("scenes", "'" + path.string() + "' is larger than " +
                                        std::to_string(kMaxScenesFileBytes) + " bytes");
    if (line.empty()) continue;
    list.push_back(ParseJson(line, "scenes (line " + std::to_string(number) + ")"));
  }
  return list;
}

// A listed scene's seed: an unsigned integer or its decimal text.
uint64_t ReadSceneSeed(const json& sj, const std::string& field) {
  if (sj.is_number_unsigned()) return sj.get<uint64_t>();
  if (sj.is_string()) {
    const std::string text = sj.get<std::string>();
    uint64_t v = 0;
    const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
    if (r.ec == std::errc() && r.ptr == text.data() + text.size()) return v;
  }
  throw CampaignError(field + ".seed", "must be an integer in [0, 2^64)");
}

// One listed scene, rewritten in place to {"scene": ..., ["seed": "..."]}.
void ReadListedScene(json& item, const std::string& field, Campaign* c) {
  if (!item.is_object()) throw CampaignError(field, "must be an object");
  std::optional<uint64_t> seed;
  if (item.contains("scene")) {  // {"scene": ..., "seed": ...} (other keys: the dataset's)
    if (item.contains("seed")) seed = ReadSceneSeed(item["seed"], field);
    json scene = item["scene"];
    item = json{{"scene", scene}};
    if (seed) item["seed"] = std::to_string(*seed);
  } else {
    item = json{{"scene", item}};
  }
  try {
    c->scenes.push_back(mechanics::ParseScene(item["scene"].dump()));
  } catch (const mechanics::SceneError& e) {
    throw CampaignError(e.field().empty() ? field : field + "." + e.field(), e.reason());
  }
  c->scene_seeds.push_back(seed);
}

// Listed scenes: each one condition; the first is the base scene.
void ReadListedScenes(json& doc, const std::filesystem::path& dir, Campaign* c) {
  for (const char* k : {"scene", "variations", "sampler", "conditions", "trials"}) {
    if (doc.contains(k))
      throw CampaignError(k, "a campaign of listed \"scenes\" has no \"" + std::string(k) +
                                 "\" (each listed scene is one condition)");
  }
  json list = json::array();
  if (doc["scenes"].is_string()) {
    list = ReadScenesFile(dir / doc["scenes"].get<std::string>());
  } else if (doc["scenes"].is_array()) {
    list = doc["scenes"];
  } else {
    throw CampaignError("scenes",
                        "must be an array of scenes or a path to a JSON-lines file, "
                        "got " +
                            TypeName(doc["scenes"]));
  }
  if (list.empty()) throw CampaignError("scenes", "lists no scene");
  if (static_cast<int64_t>(list.size()) > kMaxConditions)
    throw CampaignError("scenes", "lists more than " + std::to_string(kMaxConditions));
  for (std::size_t i = 0; i < list.size(); ++i) {
    ReadListedScene(list[i], "scenes[" + std::to_string(i) + "]", c);
  }
  doc["scenes"] = list;  // inline: the stored campaign is whole without the file
  c->scene = c->scenes.front();
  c->sampler = SamplerKind::kGrid;
}

// The base scene: inline or a file (then inlined into doc).
void ReadBaseScene(json& doc, const std::filesystem::path& dir, Campaign* c) {
  if (!doc.contains("scene"))
    throw CampaignError("scene", "is required (a scene, docs/scene.md, or a path to one)");
  try {
    if (doc["scene"].is_string()) {
      const std::filesystem::path path = dir / doc["scene"].get<std::string>();
      const std::string text = ReadFileLimited(path, "scene");
      c->scene = mechanics::ParseScene(text);
      doc["scene"] = ParseJson(text, "scene");
    } else if (doc["scene"].is_object()) {
      c->scene = mechanics::ParseScene(doc["scene"].dump());
    } else {
      throw CampaignError("scene",
                          "must be a scene object or a file path, got " + TypeName(doc["scene"]));
    }
  } catch (const mechanics::SceneError& e) {
    throw CampaignError(e.field().empty() ? "scene" : "scene." + e.field(), e.reason());
  }
}

void ReadSampler(const json& doc, Campaign* c) {
  if (doc.contains("sampler") && doc["sampler"].is_object()) {
    c->adaptive = ReadAdaptive(doc["sampler"], &c->sampler);
  } else if (doc.contains("sampler")) {
    const std::string s = String(doc["sampler"], "sampler");
    if (s == "grid")
      c->sampler = SamplerKind::kGrid;
    else if (s == "uniform")
      c->sampler = SamplerKind::kUniform;
    else if (s == "latin_hypercube")
      c->sampler = SamplerKind::kLatinHypercube;
    else if (s == "sobol")
      c->sampler = SamplerKind::kSobol;
    else {
      throw CampaignError(
          "sampler",
          "must be \"grid\", \"uniform\", \"latin_hypercube\", \"sobol\" or an object "
          "{\"adaptive\": \"boundary\"|\"replicates\", ...}, got \"" +
              Printable(s, 40) + "\"");
    }
  }
}

// Variations, in canonical order.
void ReadVariations(const json& doc, bool grid, Campaign* c) {
  if (!doc.contains("variations")) return;
  const json& vars = doc["variations"];
  if (!vars.is_object())
    throw CampaignError("variations", "must be an object, got " + TypeName(vars));
  std::vector<std::pair<int, Variation>> read;
  for (const auto& item : vars.items()) {
    const std::string path = Join("variations", item.key());
    const VariationInfo* info = FindVariation(item.key());
    if (!info) {
      std::string list;
      for (const auto& v : kVariationCatalog)
        list += (list.empty() ? "" : ", ") + std::string(v.name);
      throw CampaignError(path, "unknown variation (expected one of: " + list + ")");
    }
    read.emplace_back(CatalogIndex(item.key()), ReadVariation(item.value(), path, *info, grid));
  }
  std::sort(read.begin(), read.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  for (auto& [index, var] : read) c->variations.push_back(std::move(var));
}

// What the base scene must offer for a variation to make sense.
void CheckVariationsFitBaseScene(const Campaign& c) {
  const bool box = c.scene.object.shape == mechanics::ObjectShape::kBox;
  for (const auto& var : c.variations) {
    const std::string path = "variations." + var.name;
    if (var.name.rfind("object_size_", 0) == 0 && !box) {
      throw CampaignError(path, "only for a box (the base scene's object is a cylinder)");
    }
    if ((var.name == "object_radius" || var.name == "object_height") && box) {
      throw CampaignError(path, "only for a cylinder (the base scene's object is a box)");
    }
    if (var.name.rfind("object_", 0) == 0 && var.name != "object_mass" && c.scene.object.inertia) {
      throw CampaignError(
          path,
          "the base scene gives object.inertia explicitly; remove it so that inertia "
          "follows from the varied shape");
    }
    const bool pusher_var = var.name.rfind("pusher_", 0) == 0 || var.name.rfind("push_", 0) == 0 ||
                            var.name.rfind("pivot_", 0) == 0;
    if (pusher_var && !c.scene.pusher) throw CampaignError(path, "the base scene has no pusher");
  }
}

// The grid's number of conditions (1 when not a grid); refuses a sobol
// sampler over too many dimensions.
int64_t GridLevels(const Campaign& c, bool grid) {
  int64_t sampled_levels = 1;
  int sampled_dims = 0;
  for (const auto& var : c.variations) {
    if (!var.IsSampled()) continue;
    ++sampled_dims;
    const int64_t radix =
        var.kind == Variation::Kind::kRange ? var.levels : static_cast<int64_t>(var.choices.size());
    if (grid) {
      if (sampled_levels > kMaxConditions / radix) {
        throw CampaignError("variations", "the grid has more than " +
                                              std::to_string(kMaxConditions) + " conditions");
      }
      sampled_levels *= radix;
    }
  }
  if (c.sampler == SamplerKind::kSobol && sampled_dims > kMaxSobolDimensions) {
    throw CampaignError("variations",
                        "sobol supports at most " + std::to_string(kMaxSobolDimensions) +
                            " varied dimensions, got " + std::to_string(sampled_dims));
  }
  return sampled_levels;
}

// replicates, conditions, trials.
void ReadCounts(const json& doc, bool grid, bool boundary, Campaign* c) {
  const int64_t sampled_levels = GridLevels(*c, grid);
  if (c->adaptive && doc.contains("replicates")) {
    throw CampaignError("replicates",
                        "an adaptive sampler chooses replicates itself; give "
                        "sampler.min_replicates / sampler.max_replicates instead");
  }
  if (doc.contains("replicates")) {
    c->replicates = static_cast<int>(Integer(doc["replicates"], "replicates", 1, kMaxReplicates));
  }
  if (c->adaptive && c->adaptive->kind == AdaptiveKind::kReplicates)
    c->replicates = c->adaptive->min_replicates;
  if (boundary) CheckBoundaryVariations(doc, *c);
  const bool has_conditions = doc.contains("conditions");
  const bool has_trials = doc.contains("trials");
  if (has_conditions && has_trials) {
    throw CampaignError("trials",
                        "give either conditions or trials (= conditions x replicates), not both");
  }
  int64_t conditions = 0;
  if (has_conditions) conditions = Integer(doc["conditions"], "conditions", 1, kMaxConditions);
  if (has_trials) {
    const int64_t trials = Integer(doc["trials"], "trials", 1, kMaxTrials);
    if (trials % c->replicates != 0) {
      throw CampaignError("trials", "must be a multiple of replicates (" +
                                        std::to_string(c->replicates) + "), got " +
                                        std::to_string(trials));
    }
    conditions = trials / c->replicates;
  }
  if (boundary) {
    conditions = 0;  // points are chosen as results come in
  } else if (!c->scenes.empty()) {
    conditions = static_cast<int64_t>(c->scenes.size());
  } else if (grid) {
    if (conditions != 0 && conditions != sampled_levels) {
      throw CampaignError(has_trials ? "trials" : "conditions",
                          "the grid has " + std::to_string(sampled_levels) + " conditions (x " +
                              std::to_string(c->replicates) +
                              " replicates); leave it out or match it");
    }
    conditions = sampled_levels;
  } else if (conditions == 0) {
    throw CampaignError("conditions", "is required for sampler " +
                                          std::string(ToString(c->sampler)) + " (or give trials)");
  }
  c->conditions = conditions;
  if (c->adaptive && c->adaptive->kind == AdaptiveKind::kReplicates &&
      c->conditions * c->adaptive->max_replicates > kMaxTrials) {
    throw CampaignError("sampler.max_replicates",
                        "conditions x max_replicates must be <= " + std::to_string(kMaxTrials));
  }
  if (c->conditions * c->replicates > kMaxTrials) {
    throw CampaignError("replicates",
                        "conditions x replicates must be <= " + std::to_string(kMaxTrials));
  }
}

// Which predictor: arena's model (knobs facets, points, dt, reduce, contacts,
// pads, cone, inertia) or MuJoCo (timestep, cone, noslip_iterations, solref,
// solimp); knobs of the other are refused. `cone` is both's, each with its
// own values (arena: polyhedral | aligned; MuJoCo: pyramidal | elliptic). A
// calibration's scales apply to either (SubmitCampaign checks that it was
// fitted for the campaign's predictor).
void ReadPredictor(const json& p, Campaign* c) {
  if (p.contains("predictor")) c->predictor = String(p["predictor"], "prediction.predictor");
  if (c->predictor != "arena" && c->predictor != "mujoco") {
    throw CampaignError("prediction.predictor", "must be \"arena\" or \"mujoco\", got \"" +
                                                    Printable(c->predictor, 40) + "\"");
  }
  const bool mujoco = c->predictor == "mujoco";
  for (const char* k : {"facets", "points", "dt", "reduce", "contacts", "pads", "inertia",
                        "timestep", "noslip_iterations", "solref", "solimp"}) {
    const std::string key = k;
    const bool arena_knob =
        key != "timestep" && key != "noslip_iterations" && key != "solref" && key != "solimp";
    if (p.contains(k) && arena_knob == mujoco) {
      throw CampaignError(std::string("prediction.") + k,
                          std::string("is not a knob of the ") + c->predictor + " predictor");
    }
  }
}

// MuJoCo's knobs are checked by the simulator that will use them.
void ReadMujocoKnobs(const json& p, Campaign* c) {
  json knobs = p;
  for (const char* k : {"predictor", "calibration", "calibrated", "start"}) knobs.erase(k);
  try {
    (void)simulators::MakeSimulator("mujoco", knobs.dump());
  } catch (const simulators::SimulatorError& e) {
    const std::string field = e.field().rfind("mujoco.", 0) == 0 ? e.field().substr(7) : "";
    const std::string what = e.what();
    throw CampaignError("prediction" + (field.empty() ? "" : "." + field),
                        what.substr(std::min(what.size(), e.field().size() + 2)));
  }
  c->predictor_settings_json = knobs.dump();
}

void ReadCalibration(const json& p, Campaign* c) {
  if (p.contains("calibrated")) {
    // Written by SubmitCampaign from "calibration" (or given by hand): scales.
    RequireObject(p["calibrated"], "prediction.calibrated",
                  {"mu_fingers", "mu_pusher", "grip_force", "object_mass"});
    for (const auto& item : p["calibrated"].items()) {
      const std::string path = "prediction.calibrated." + item.key();
      const double k = Number(item.value(), path);
      if (!(k > 0)) throw CampaignError(path, "must be > 0, got " + Num(k));
      c->calibrated_scales[item.key()] = k;
    }
  }
  if (p.contains("calibration")) {
    c->calibration_id =
        Integer(p["calibration"], "prediction.calibration", 1, std::numeric_limits<int32_t>::max());
  }
}

// arena's own model knobs, overriding the base scene's model.
void ReadModelKnobs(const json& p, mechanics::ModelOptions* model) {
  if (p.contains("facets")) {
    model->facets =
        static_cast<int>(Integer(p["facets"], "prediction.facets", 3, mechanics::kMaxFacets));
  }
  if (p.contains("points")) {
    model->points =
        static_cast<int>(Integer(p["points"], "prediction.points", 2, mechanics::kMaxPoints));
  }
  if (p.contains("dt")) model->dt = Number(p["dt"], "prediction.dt");
  if (p.contains("reduce")) {
    const std::string r = String(p["reduce"], "prediction.reduce");
    const auto reduce = mechanics::ReduceFromString(r);
    if (!reduce) {
      throw CampaignError("prediction.reduce", "must be \"auto\", \"full\" or \"planar\", got \"" +
                                                   Printable(r, 40) + "\"");
    }
    model->reduce = *reduce;
  }
  if (p.contains("contacts")) {
    const std::string m = String(p["contacts"], "prediction.contacts");
    const auto mode = mechanics::ContactTrackingFromString(m);
    if (!mode) {
      throw CampaignError("prediction.contacts",
                          "must be \"tracked\" or \"fixed\", got \"" + Printable(m, 40) + "\"");
    }
    model->contacts = *mode;
  }
  // Issue 31's choices (docs/scene.md, "Which knob matters for which scene").
  // `cone` is read here for arena's model only (MuJoCo's is its own knob).
  const auto choice = [&](const char* key, const char* values, auto parse, auto* out) {
    if (!p.contains(key)) return;
    const std::string path = std::string("prediction.") + key;
    const std::string text = String(p[key], path);
    const auto value = parse(text);
    if (!value)
      throw CampaignError(
          path, std::string("must be ") + values + ", got \"" + Printable(text, 40) + "\"");
    *out = *value;
  };
  choice("pads", "\"elastic\" or \"rigid\"", mechanics::PadModelFromString, &model->pads);
  if (p.value("predictor", "arena") == "arena")
    choice("cone", "\"polyhedral\" or \"aligned\"", mechanics::ConeModelFromString, &model->cone);
  choice("inertia", "\"carried\", \"quasi_static\" or \"auto\"", mechanics::InertiaModelFromString,
         &model->inertia);
}

// Prediction model: the base scene's model, overridden field by field.
void ReadPrediction(const json& doc, Campaign* c) {
  c->prediction = c->scene.model;
  if (!doc.contains("prediction")) return;
  const json& p = doc["prediction"];
  RequireObject(
      p, "prediction",
      {"predictor", "facets", "points", "dt", "reduce", "contacts", "pads", "cone", "inertia",
       "calibration", "calibrated", "timestep", "noslip_iterations", "solref", "solimp", "start"});
  // Where each prediction starts (issue 26): the start pose the cell
  // measured (default) or the planned one.
  if (p.contains("start") &&
      !(p["start"].is_string() && (p["start"] == "measured" || p["start"] == "planned")))
    throw CampaignError("prediction.start", "must be \"measured\" or \"planned\"");
  ReadPredictor(p, c);
  if (c->predictor == "mujoco") ReadMujocoKnobs(p, c);
  ReadCalibration(p, c);
  ReadModelKnobs(p, &c->prediction);
}

// Defect profile: an object passed through, or a file holding one (then inlined into doc).
void ReadDefects(json& doc, const std::filesystem::path& dir, Campaign* c) {
  if (!doc.contains("defects")) return;
  json& d = doc["defects"];
  if (d.is_string()) {
    c->defects_file = d.get<std::string>();
    d = ParseJson(ReadFileLimited(dir / c->defects_file, "defects"), "defects");
    if (!d.is_object())
      throw CampaignError("defects", "the file must hold a JSON object, got " + TypeName(d));
  } else if (!d.is_object()) {
    throw CampaignError("defects", "must be an object or a file path, got " + TypeName(d));
  }
  c->defects_json = d.dump();
}

// The base scene (or, with every condition checked, each listed scene) must
// be valid for the cells and, with the campaign's model, for the predictor.
void CheckBaseScenes(const Campaign& c, ConditionCheck check) {
  for (std::size_t i = 0; i < std::max<std::size_t>(1, c.scenes.size()); ++i) {
    if (i > 0 && check != ConditionCheck::kAllConditions) break;
    const std::string where = c.scenes.empty() ? "scene" : "scenes[" + std::to_string(i) + "]";
    try {
      mechanics::ValidateScene(WithModel(c.scenes.empty() ? c.scene : c.scenes[i], c.prediction));
    } catch (const mechanics::SceneError& e) {
      std::string field = e.field();
      if (field.rfind("model.", 0) == 0)
        field = "prediction." + field.substr(6);
      else
        field = field.empty() ? where : where + "." + field;
      throw CampaignError(field, e.reason());
    }
  }
}

// The boundary sampler's space is a box: its corners are the extremes every
// chosen point lies between.
void CheckBoundaryCorners(const Campaign& c) {
  const int dims = static_cast<int>(SampledVariations(c).size());
  for (int corner = 0; corner < (1 << dims); ++corner) {
    std::vector<double> u(static_cast<size_t>(dims));
    for (int d = 0; d < dims; ++d) u[static_cast<size_t>(d)] = (corner >> d) & 1;
    const Values values = PointValues(c, u);
    try {
      const Scene scene = BuildScene(c.scene, values);
      mechanics::ValidateScene(scene);
      mechanics::ValidateScene(WithModel(scene, c.prediction));
    } catch (const mechanics::SceneError& e) {
      throw CampaignError("variations", "the corner " + ParametersJson(c, values) +
                                            " gives an invalid scene: " + e.what());
    }
  }
}

void CheckEveryCondition(const Campaign& c) {
  for (int64_t condition = 0; condition < c.conditions; ++condition) {
    const Values values = ConditionValues(c, condition);
    const Scene scene = BuildScene(c.scene, values);
    try {
      mechanics::ValidateScene(scene);
      mechanics::ValidateScene(WithModel(scene, c.prediction));
    } catch (const mechanics::SceneError& e) {
      throw CampaignError("variations", "condition " + std::to_string(condition) + " " +
                                            ParametersJson(c, values) +
                                            " gives an invalid scene: " + e.what());
    }
  }
}

}  // namespace

std::optional<std::string_view> VariationUnit(std::string_view name) {
  const VariationInfo* info = FindVariation(name);
  if (info == nullptr) return std::nullopt;
  return std::string_view(info->unit);
}

std::string HumanVariationValue(std::string_view name, double value) {
  const std::string unit(VariationUnit(name).value_or(""));
  const bool scalar = unit == "m" || unit == "m/s" || unit == "N" || unit == "kg";
  const assessment::HumanUnit h = assessment::HumanUnitOf(scalar ? unit : "1");
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3g", value * h.factor);
  return scalar ? std::string(buf) + " " + h.unit : std::string(buf);
}

// ---------------------------------------------------------------------------

Campaign ParseCampaign(std::string_view json_text, const std::string& base_dir,
                       ConditionCheck check) {
  json doc = ParseJson(json_text, "");
  RequireObject(
      doc, "",
      {"name", "description", "seed", "priority", "scene", "scenes", "variations", "sampler",
       "conditions", "trials", "replicates", "prediction", "defects", "scheduling"});
  const std::filesystem::path dir =
      base_dir.empty() ? std::filesystem::path(".") : std::filesystem::path(base_dir);
  Campaign c;
  if (doc.contains("scheduling")) c.scheduling = ReadSchedulingBlock(doc["scheduling"]);
  ReadIdentity(doc, &c);
  if (doc.contains("scenes")) {
    ReadListedScenes(doc, dir, &c);
  } else {
    ReadBaseScene(doc, dir, &c);
  }
  ReadSampler(doc, &c);
  const bool boundary = c.adaptive && c.adaptive->kind == AdaptiveKind::kBoundary;
  const bool grid = c.sampler == SamplerKind::kGrid && !boundary;
  ReadVariations(doc, grid, &c);
  CheckVariationsFitBaseScene(c);
  ReadCounts(doc, grid, boundary, &c);
  ReadPrediction(doc, &c);
  ReadDefects(doc, dir, &c);
  c.source_json = doc.dump();

  // A unit slip is blamed on the field written, before its consequences are
  // (at submit: a stored campaign reloads as it was accepted).
  if (check == ConditionCheck::kAllConditions) CheckPlausibility(c);
  // Every condition must give a valid scene, for the cells and for the
  // predictor: refuse the campaign now rather than fail trial 9,000.
  CheckBaseScenes(c, check);
  if (check == ConditionCheck::kAllConditions) {
    if (boundary) CheckBoundaryCorners(c);
    CheckEveryCondition(c);
  }
  return c;
}

SchedulingOptions ReadScheduling(std::string_view campaign_json) {
  const json doc = ParseJson(campaign_json, "");
  if (!doc.is_object() || !doc.contains("scheduling")) return SchedulingOptions{};
  return ReadSchedulingBlock(doc["scheduling"]);
}

Campaign LoadCampaignFile(const std::string& path) {
  const std::string text = ReadFileLimited(path, "");
  return ParseCampaign(text, std::filesystem::path(path).parent_path().string());
}

int64_t TrialCount(const Campaign& campaign) { return campaign.conditions * campaign.replicates; }

std::vector<double> ConditionPoint(const Campaign& c, int64_t condition) {
  if (condition < 0 || condition >= c.conditions) {
    throw std::out_of_range("ConditionPoint: condition " + std::to_string(condition) +
                            " not in [0, " + std::to_string(c.conditions) + ")");
  }
  std::vector<double> point;
  int64_t rest = condition;
  int dim = 0;
  for (const auto& var : c.variations) {
    if (!var.IsSampled()) continue;
    const auto i = static_cast<uint64_t>(condition);
    switch (c.sampler) {
      case SamplerKind::kGrid: {
        const int64_t radix = var.kind == Variation::Kind::kRange
                                  ? var.levels
                                  : static_cast<int64_t>(var.choices.size());
        point.push_back(static_cast<double>(rest % radix) / static_cast<double>(radix));
        rest /= radix;
        break;
      }
      case SamplerKind::kUniform:
        point.push_back(
            UniformFromCounter(Mix64(c.seed ^ Mix64(0xd1ULL + static_cast<uint64_t>(dim))), i));
        break;
      case SamplerKind::kLatinHypercube:
        point.push_back(
            LatinHypercubeCoordinate(i, static_cast<uint64_t>(c.conditions), dim, c.seed));
        break;
      case SamplerKind::kSobol:
        point.push_back(ScrambledSobolCoordinate(static_cast<uint32_t>(i), dim, c.seed));
        break;
    }
    ++dim;
  }
  return point;
}

PlannedTrial PlanTrial(const Campaign& c, int64_t index) {
  if (index < 0 || index >= TrialCount(c)) {
    throw std::out_of_range("PlanTrial: index " + std::to_string(index) + " not in [0, " +
                            std::to_string(TrialCount(c)) + ")");
  }
  PlannedTrial t;
  t.index = index;
  t.condition = index / c.replicates;
  t.replicate = static_cast<int>(index % c.replicates);
  t.seed = Mix64(Mix64(Mix64(c.seed ^ 0x7419a1ULL) + static_cast<uint64_t>(t.condition)) +
                 static_cast<uint64_t>(t.replicate));
  if (!c.scenes.empty()) {  // a listed scene, with its own seed if it has one
    const auto k = static_cast<std::size_t>(t.condition);
    if (t.replicate == 0 && c.scene_seeds[k]) t.seed = *c.scene_seeds[k];
    t.scene = c.scenes[k];
    t.parameters_json = json{{"scene_index", t.condition}}.dump();
    return t;
  }
  const Values values = ConditionValues(c, t.condition);
  t.scene = BuildScene(c.scene, values);
  t.parameters_json = ParametersJson(c, values);
  return t;
}

std::vector<std::string> SampledVariations(const Campaign& c) {
  std::vector<std::string> names;
  for (const auto& var : c.variations)
    if (var.IsSampled()) names.push_back(var.name);
  return names;
}

namespace {
uint64_t TrialSeed(const Campaign& c, int64_t condition, int replicate) {
  return Mix64(Mix64(Mix64(c.seed ^ 0x7419a1ULL) + static_cast<uint64_t>(condition)) +
               static_cast<uint64_t>(replicate));
}
}  // namespace

PlannedTrial PlanTrialAt(const Campaign& c, const std::vector<double>& u, int64_t index,
                         int64_t condition, int replicate) {
  const auto names = SampledVariations(c);
  if (u.size() != names.size()) {
    throw std::invalid_argument("PlanTrialAt: point has " + std::to_string(u.size()) +
                                " coordinates, the campaign samples " +
                                std::to_string(names.size()));
  }
  for (const auto& var : c.variations) {
    if (var.IsSampled() && var.kind != Variation::Kind::kRange)
      throw std::invalid_argument("PlanTrialAt: " + var.name + " is not a range");
  }
  for (double x : u) {
    if (!(x >= 0 && x <= 1))
      throw std::invalid_argument("PlanTrialAt: coordinate " + Num(x) + " not in [0, 1]");
  }
  PlannedTrial t;
  t.index = index;
  t.condition = condition;
  t.replicate = replicate;
  t.seed = TrialSeed(c, condition, replicate);
  const Values values = PointValues(c, u);
  t.scene = BuildScene(c.scene, values);
  t.parameters_json = ParametersJson(c, values);
  return t;
}

PlannedTrial PlanReplicate(const Campaign& c, int64_t condition, int replicate, int64_t index) {
  if (condition < 0 || condition >= c.conditions) {
    throw std::out_of_range("PlanReplicate: condition " + std::to_string(condition) +
                            " not in [0, " + std::to_string(c.conditions) + ")");
  }
  PlannedTrial t;
  t.index = index;
  t.condition = condition;
  t.replicate = replicate;
  t.seed = TrialSeed(c, condition, replicate);
  const Values values = ConditionValues(c, condition);
  t.scene = BuildScene(c.scene, values);
  t.parameters_json = ParametersJson(c, values);
  return t;
}

mechanics::Scene PredictionScene(const Campaign& campaign, const PlannedTrial& trial) {
  return WithModel(trial.scene, campaign.prediction);
}

}  // namespace arena::orchestrator
