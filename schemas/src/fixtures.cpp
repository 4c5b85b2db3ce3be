// A cell's fixtures and their changes; the contract is in fixtures.hpp.
#include "arena/schemas/fixtures.hpp"

#include <cmath>
#include <cstdio>

namespace arena::schemas {
namespace {

// Six significant digits: a key names a physical part, not a rounding error.
std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v == 0 ? 0.0 : v);  // no "-0"
  return buf;
}

// Appended piece by piece: GCC 12 warns falsely (-Wrestrict) on "(" + string chains.
std::string Vec(const Eigen::Vector3d& v) {
  std::string out = "(";
  out += Num(v.x());
  out += ',';
  out += Num(v.y());
  out += ',';
  out += Num(v.z());
  out += ')';
  return out;
}

std::string ContactKey(const mechanics::ContactSpec& c) {
  std::string key = mechanics::ToString(c.type);
  if (c.type == mechanics::ContactType::kLine) key += " l=" + Num(c.length);
  if (c.type != mechanics::ContactType::kLine) key += " r=" + Num(c.radius);
  return key;
}

}  // namespace

Fixtures FixturesOf(const mechanics::Scene& scene) {
  Fixtures f;
  for (const auto& finger : scene.fingers) {
    if (!f.finger.empty()) f.finger += " | ";
    f.finger += ContactKey(finger) + " mu=" + Num(finger.mu) + " k=" + Num(finger.stiffness);
  }
  if (f.finger.empty()) f.finger = "none";
  // The tool as ChangeOfPusher (executors/trial_start.hpp) sees it: its
  // geometry and direction (so a change here is exactly a reset's swap).
  if (scene.pusher) {
    const auto& p = *scene.pusher;
    f.pusher = ContactKey(p);
    f.pusher += " n=";
    f.pusher += Vec(p.normal);
    f.pusher += " a=";
    f.pusher += Vec(p.axis);
  } else {
    f.pusher = "none";
  }
  const auto& o = scene.object;
  switch (o.shape) {
    case mechanics::ObjectShape::kBox:
      f.object = "box ";
      f.object += Vec(o.size);
      break;
    case mechanics::ObjectShape::kCylinder:
      f.object = "cylinder r=";
      f.object += Num(o.radius);
      f.object += " h=";
      f.object += Num(o.height);
      break;
    default: {
      f.object = "prism h=";
      f.object += Num(o.height);
      f.object += " [";
      for (const auto& v : o.polygon) {
        f.object += '(';
        f.object += Num(v.x());
        f.object += ',';
        f.object += Num(v.y());
        f.object += ')';
      }
      f.object += ']';
    }
  }
  f.object += " m=" + Num(o.mass);
  return f;
}

std::string CheckChangeCosts(const ChangeCosts& costs) {
  const std::pair<const char*, double> all[] = {
      {"finger_s", costs.finger_s}, {"pusher_s", costs.pusher_s}, {"object_s", costs.object_s}};
  for (const auto& [name, v] : all) {
    if (!std::isfinite(v) || v < 0) return std::string(name) + ": must be finite and >= 0";
  }
  return "";
}

std::vector<FixtureChange> ChangesBetween(const std::optional<Fixtures>& mounted,
                                          const Fixtures& next, const ChangeCosts& costs) {
  std::vector<FixtureChange> out;
  if (!mounted) return out;  // set up for its first trial (fixtures.hpp)
  auto add = [&](const char* what, const std::string& now, const std::string& to, double s) {
    if (now != to) out.push_back({what, now, to, s});
  };
  add("finger", mounted->finger, next.finger, costs.finger_s);
  add("pusher", mounted->pusher, next.pusher, costs.pusher_s);
  add("object", mounted->object, next.object, costs.object_s);
  return out;
}

double ChangeSeconds(const std::vector<FixtureChange>& changes) {
  double s = 0;
  for (const auto& c : changes) s += c.seconds;
  return s;
}

}  // namespace arena::schemas
