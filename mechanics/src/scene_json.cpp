// Scene JSON: reading (with paths in every error), validation, writing.
//
// Reading is two passes. A SAX handler builds the document while it tracks
// the JSON path, so a syntax error, a non-UTF-8 byte, a number that
// overflows, a duplicate key, too deep a nesting or too long an array is
// reported at its path and byte offset, and no input can make it allocate
// more than a small multiple of kMaxSceneBytes. Then a typed reader walks the
// document: unknown keys, missing fields and wrong types, and finally
// ValidateScene() checks ranges and geometry (shared with scenes built in
// code).
#include "arena/mechanics/scene_json.hpp"

#include "arena/mechanics/frames.hpp"
#include "arena/mechanics/json_path.hpp"
#include "arena/mechanics/polygon.hpp"
#include "geometry.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <sstream>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

namespace arena::mechanics {

SceneError::SceneError(std::string field, const std::string& reason)
    : Error(ErrorCategory::kBadInput,
            (field.empty() ? std::string("scene") : field) + ": " + reason),
      field_(std::move(field)),
      reason_(reason) {}

const char* ToString(ContactType type) {
  switch (type) {
    case ContactType::kPoint:
      return "point";
    case ContactType::kLine:
      return "line";
    case ContactType::kPatch:
      return "patch";
  }
  return "?";
}

const char* ToString(Reduce reduce) {
  switch (reduce) {
    case Reduce::kAuto:
      return "auto";
    case Reduce::kFull:
      return "full";
    case Reduce::kPlanar:
      return "planar";
  }
  return "?";
}

const char* ToString(ObjectShape shape) {
  switch (shape) {
    case ObjectShape::kBox:
      return "box";
    case ObjectShape::kCylinder:
      return "cylinder";
    case ObjectShape::kPrism:
      return "prism";
  }
  return "?";
}

const char* ToString(ContactTracking tracking) {
  switch (tracking) {
    case ContactTracking::kTracked:
      return "tracked";
    case ContactTracking::kFixed:
      return "fixed";
  }
  return "?";
}

const char* ToString(GripperCoupling coupling) {
  switch (coupling) {
    case GripperCoupling::kIndependent:
      return "independent";
    case GripperCoupling::kParallelJaw:
      return "parallel_jaw";
  }
  return "?";
}

const char* ToString(PadModel pads) { return pads == PadModel::kElastic ? "elastic" : "rigid"; }
const char* ToString(InertiaModel inertia) {
  switch (inertia) {
    case InertiaModel::kCarried:
      return "carried";
    case InertiaModel::kQuasiStatic:
      return "quasi_static";
    case InertiaModel::kAuto:
      return "auto";
  }
  return "?";
}
InertiaModel InertiaOf(const Scene& scene) {
  if (scene.model.inertia != InertiaModel::kAuto) return scene.model.inertia;
  return !scene.fingers.empty() && !scene.support ? InertiaModel::kQuasiStatic
                                                  : InertiaModel::kCarried;
}
const char* ToString(ConeModel cone) {
  return cone == ConeModel::kAligned ? "aligned" : "polyhedral";
}

std::optional<ContactTracking> ContactTrackingFromString(std::string_view text) {
  if (text == "tracked") return ContactTracking::kTracked;
  if (text == "fixed") return ContactTracking::kFixed;
  return std::nullopt;
}

std::optional<PadModel> PadModelFromString(std::string_view text) {
  if (text == "elastic") return PadModel::kElastic;
  if (text == "rigid") return PadModel::kRigid;
  return std::nullopt;
}

std::optional<ConeModel> ConeModelFromString(std::string_view text) {
  if (text == "polyhedral") return ConeModel::kPolyhedral;
  if (text == "aligned") return ConeModel::kAligned;
  return std::nullopt;
}

std::optional<InertiaModel> InertiaModelFromString(std::string_view text) {
  if (text == "carried") return InertiaModel::kCarried;
  if (text == "quasi_static") return InertiaModel::kQuasiStatic;
  if (text == "auto") return InertiaModel::kAuto;
  return std::nullopt;
}

std::optional<ObjectShape> ObjectShapeFromString(std::string_view text) {
  if (text == "box") return ObjectShape::kBox;
  if (text == "cylinder") return ObjectShape::kCylinder;
  if (text == "prism") return ObjectShape::kPrism;
  return std::nullopt;
}

std::optional<ContactType> ContactTypeFromString(std::string_view text) {
  if (text == "point") return ContactType::kPoint;
  if (text == "line") return ContactType::kLine;
  if (text == "patch") return ContactType::kPatch;
  return std::nullopt;
}

std::optional<Reduce> ReduceFromString(std::string_view text) {
  if (text == "auto") return Reduce::kAuto;
  if (text == "full") return Reduce::kFull;
  if (text == "planar") return Reduce::kPlanar;
  return std::nullopt;
}

double ObjectExtent(const ObjectSpec& object) {
  if (object.shape == ObjectShape::kBox) return object.size.maxCoeff();
  if (object.shape == ObjectShape::kPrism) {
    double diameter = 0;
    for (const auto& a : object.polygon) {
      for (const auto& b : object.polygon) diameter = std::max(diameter, (a - b).norm());
    }
    return std::max(diameter, object.height);
  }
  return std::max(2 * object.radius, object.height);
}

namespace {

using nlohmann::json;

constexpr double kParseUnitTolerance = 1e-3;     // hand-written directions
constexpr double kValidateUnitTolerance = 1e-6;  // directions built in code
constexpr double kSurfaceTolerance = 1e-2;       // of the object's extent
constexpr double kCoincidentTolerance = 1e-6;    // of the object's extent

using json_path::Index;
using json_path::Join;
using json_path::Num;
using json_path::Printable;

std::string Quote(std::string_view text) { return "\"" + Printable(text, 40) + "\""; }

// ---------------------------------------------------------------------------
// Pass 1: SAX builder that knows where it is.

class PathTrackingBuilder {
 public:
  explicit PathTrackingBuilder(const JsonLimits& limits) : limits_(limits) {}

  using number_integer_t = json::number_integer_t;
  using number_unsigned_t = json::number_unsigned_t;
  using number_float_t = json::number_float_t;
  using string_t = json::string_t;
  using binary_t = json::binary_t;

  json root;
  std::string error_path;
  std::string error_reason;

  bool null() { return Add(json(nullptr)) != nullptr; }
  bool boolean(bool v) { return Add(json(v)) != nullptr; }
  bool number_integer(number_integer_t v) { return Add(json(v)) != nullptr; }
  bool number_unsigned(number_unsigned_t v) { return Add(json(v)) != nullptr; }
  bool number_float(number_float_t v, const string_t&) { return Add(json(v)) != nullptr; }
  bool string(string_t& v) { return Add(json(std::move(v))) != nullptr; }
  bool binary(binary_t&) { return Fail(ChildPath(), "binary values are not JSON"); }

  bool start_object(std::size_t) { return Open(json::object()); }
  bool start_array(std::size_t) { return Open(json::array()); }
  bool end_object() { return Close(); }
  bool end_array() { return Close(); }

  bool key(string_t& k) {
    const Frame& top = stack_.back();
    if (top.value->contains(k)) {
      return Fail(Join(top.path, k), "duplicate key");
    }
    key_ = std::move(k);
    have_key_ = true;
    return true;
  }

  bool parse_error(std::size_t position, const std::string&,
                   const nlohmann::detail::exception& ex) {
    std::string what = ex.what();
    // "[json.exception.parse_error.101] parse error at line 1, column 5: ..." -> after "]".
    if (const auto close = what.find("] "); close != std::string::npos)
      what = what.substr(close + 2);
    if (ex.id == 406)  // out_of_range.406: valid JSON, a number no double holds (1e999)
      return Fail(ChildPath(), "a number out of range (beyond a double) at byte offset " +
                                   std::to_string(position > 0 ? position - 1 : 0) + ": " +
                                   Printable(what, 200));
    return Fail(ChildPath(), "invalid JSON at byte offset " +
                                 std::to_string(position > 0 ? position - 1 : 0) + ": " +
                                 Printable(what, 200));
  }

 private:
  struct Frame {
    json* value;
    std::string path;
  };

  bool Fail(std::string path, std::string reason) {
    if (error_reason.empty()) {  // the first failure is the one to report
      error_path = std::move(path);
      error_reason = std::move(reason);
    }
    return false;
  }

  // Path of the value that comes next.
  std::string ChildPath() const {
    if (stack_.empty()) return "";
    const Frame& top = stack_.back();
    if (top.value->is_array()) return Index(top.path, top.value->size());
    return have_key_ ? Join(top.path, key_) : top.path;
  }

  json* Add(json&& value) {
    if (stack_.empty()) {
      root = std::move(value);
      return &root;
    }
    Frame& top = stack_.back();
    if (top.value->is_array()) {
      if (top.value->size() >= limits_.max_array) {
        Fail(top.path, "array longer than " + std::to_string(limits_.max_array) + " elements");
        return nullptr;
      }
      top.value->push_back(std::move(value));
      return &top.value->back();
    }
    have_key_ = false;
    json& slot = (*top.value)[key_];
    slot = std::move(value);
    return &slot;
  }

  bool Open(json&& container) {
    const std::string path = ChildPath();
    if (static_cast<int>(stack_.size()) >= limits_.max_depth) {
      return Fail(path, "nested deeper than " + std::to_string(limits_.max_depth) + " levels");
    }
    json* slot = Add(std::move(container));
    if (!slot) return false;
    stack_.push_back({slot, path});
    return true;
  }

  bool Close() {
    stack_.pop_back();
    have_key_ = false;
    return true;
  }

  JsonLimits limits_;
  std::vector<Frame> stack_;
  std::string key_;
  bool have_key_ = false;
};

// ---------------------------------------------------------------------------
// Pass 2: typed reading.

std::string TypeName(const json& v) {
  if (v.is_number()) return "a number";
  if (v.is_string()) return "a string";
  if (v.is_boolean()) return "a boolean";
  if (v.is_null()) return "null";
  if (v.is_array()) return "an array";
  return "an object";
}

// A JSON object being read: refuses keys it does not know, names the path.
class Obj {
 public:
  Obj(const json& value, std::string path, std::initializer_list<std::string_view> known)
      : value_(value), path_(std::move(path)) {
    if (!value.is_object()) throw SceneError(path_, "must be an object, got " + TypeName(value));
    for (const auto& [key, unused] : value.items()) {
      (void)unused;
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        std::string list;
        for (auto k : known) list += (list.empty() ? "" : ", ") + std::string(k);
        throw SceneError(At(key), "unknown key (expected one of: " + list + ")");
      }
    }
  }

  std::string At(std::string_view key) const { return Join(path_, key); }
  const json* Find(std::string_view key) const {
    const auto it = value_.find(key);
    return it == value_.end() ? nullptr : &*it;
  }
  const json& Require(std::string_view key) const {
    const json* v = Find(key);
    if (!v) throw SceneError(At(key), "is required");
    return *v;
  }
  void Forbid(std::string_view key, const std::string& why) const {
    if (Find(key)) throw SceneError(At(key), why);
  }

 private:
  const json& value_;
  std::string path_;
};

double Number(const json& v, const std::string& path) {
  if (!v.is_number()) throw SceneError(path, "must be a number, got " + TypeName(v));
  const double x = v.get<double>();
  if (!std::isfinite(x)) throw SceneError(path, "must be finite, got " + Num(x));
  return x;
}

int Integer(const json& v, const std::string& path, int lo, int hi) {
  const std::string range =
      "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  if (!v.is_number()) throw SceneError(path, "must be " + range + ", got " + TypeName(v));
  const double x = v.get<double>();
  if (std::floor(x) != x) throw SceneError(path, "must be " + range + ", got " + Num(x));
  if (x < lo || x > hi) throw SceneError(path, "must be " + range + ", got " + Num(x));
  return static_cast<int>(x);
}

std::string String(const json& v, const std::string& path) {
  if (!v.is_string()) throw SceneError(path, "must be a string, got " + TypeName(v));
  return v.get<std::string>();
}

Eigen::Vector3d Vec3(const json& v, const std::string& path) {
  if (!v.is_array()) throw SceneError(path, "must be an array of 3 numbers, got " + TypeName(v));
  if (v.size() != 3) {
    throw SceneError(
        path, "must be an array of 3 numbers, got " + std::to_string(v.size()) + " elements");
  }
  return {Number(v[0], Index(path, 0)), Number(v[1], Index(path, 1)), Number(v[2], Index(path, 2))};
}

// A direction: accepted when its norm is 1 within kParseUnitTolerance, then
// made exactly unit.
Eigen::Vector3d Direction(const json& v, const std::string& path) {
  const Eigen::Vector3d d = Vec3(v, path);
  const double n = d.norm();
  if (n == 0) throw SceneError(path, "must be a unit vector, got the zero vector");
  if (std::abs(n - 1) > kParseUnitTolerance) {
    throw SceneError(path, "must be a unit vector (norm 1 within 1e-3), got norm " + Num(n));
  }
  // Already unit to rounding: keep the bits, so that writing and reading a
  // scene reproduces it exactly.
  return std::abs(n - 1) > 1e-12 ? Eigen::Vector3d(d / n) : d;
}

Pose ReadPose(const json& v, const std::string& path) {
  Obj o(v, path, {"position", "rpy"});
  Pose pose;
  if (const json* p = o.Find("position")) pose.position = Vec3(*p, o.At("position"));
  if (const json* r = o.Find("rpy")) pose.rpy = Vec3(*r, o.At("rpy"));
  return pose;
}

ObjectSpec ReadObject(const json& v, const std::string& path) {
  Obj o(v, path, {"shape", "size", "radius", "height", "polygon", "mass", "inertia", "pose"});
  ObjectSpec object;
  const std::string shape = String(o.Require("shape"), o.At("shape"));
  const auto parsed = ObjectShapeFromString(shape);
  if (!parsed) {
    throw SceneError(o.At("shape"),
                     "must be \"box\", \"cylinder\" or \"prism\", got " + Quote(shape));
  }
  object.shape = *parsed;
  if (object.shape != ObjectShape::kPrism) o.Forbid("polygon", "only for shape \"prism\"");
  if (object.shape == ObjectShape::kBox) {
    o.Forbid("radius", "only for shape \"cylinder\" (a box has size)");
    o.Forbid("height", "only for shapes \"cylinder\" and \"prism\" (a box has size)");
    object.size = Vec3(o.Require("size"), o.At("size"));
  } else if (object.shape == ObjectShape::kCylinder) {
    o.Forbid("size", "only for shape \"box\" (a cylinder has radius and height)");
    object.radius = Number(o.Require("radius"), o.At("radius"));
    object.height = Number(o.Require("height"), o.At("height"));
  } else {
    o.Forbid("size", "only for shape \"box\" (a prism has polygon and height)");
    o.Forbid("radius", "only for shape \"cylinder\" (a prism has polygon and height)");
    const json& poly = o.Require("polygon");
    const std::string ppath = o.At("polygon");
    if (!poly.is_array()) {
      throw SceneError(ppath, "must be an array of [x, y] vertices, got " + TypeName(poly));
    }
    for (size_t i = 0; i < poly.size(); ++i) {
      const std::string vpath = Index(ppath, i);
      if (!poly[i].is_array() || poly[i].size() != 2)
        throw SceneError(vpath, "must be an array of 2 numbers [x, y]");
      object.polygon.emplace_back(Number(poly[i][0], Index(vpath, 0)),
                                  Number(poly[i][1], Index(vpath, 1)));
    }
    object.height = Number(o.Require("height"), o.At("height"));
  }
  object.mass = Number(o.Require("mass"), o.At("mass"));
  if (const json* in = o.Find("inertia")) {
    const std::string ipath = o.At("inertia");
    if (!in->is_array() || in->size() != 3) {
      throw SceneError(ipath, "must be a 3x3 array of numbers (3 rows of 3)");
    }
    Eigen::Matrix3d inertia;
    for (int r = 0; r < 3; ++r) {
      const Eigen::Vector3d row = Vec3((*in)[r], Index(ipath, r));
      inertia.row(r) = row.transpose();
    }
    object.inertia = inertia;
  }
  if (const json* p = o.Find("pose")) object.pose = ReadPose(*p, o.At("pose"));
  return object;
}

// Fingers and the pusher share the contact fields; the pusher has motion and
// no name.
void ReadContact(const Obj& o, ContactSpec* contact) {
  const std::string type = String(o.Require("type"), o.At("type"));
  const auto parsed = ContactTypeFromString(type);
  if (!parsed) {
    throw SceneError(o.At("type"), "must be \"point\", \"line\" or \"patch\", got " + Quote(type));
  }
  contact->type = *parsed;
  if (contact->type != ContactType::kLine) {
    o.Forbid("axis", "only for type \"line\"");
    o.Forbid("length", "only for type \"line\"");
  }
  if (contact->type == ContactType::kLine)
    o.Forbid("radius", "only for type \"patch\" (and \"point\": a sphere)");
  contact->position = Vec3(o.Require("position"), o.At("position"));
  contact->normal = Direction(o.Require("normal"), o.At("normal"));
  contact->mu = Number(o.Require("mu"), o.At("mu"));
  if (contact->type == ContactType::kLine) {
    Eigen::Vector3d axis = Direction(o.Require("axis"), o.At("axis"));
    const double dot = axis.dot(contact->normal);
    if (std::abs(dot) > kParseUnitTolerance) {
      throw SceneError(o.At("axis"),
                       "must be perpendicular to normal (|axis.normal| <= 1e-3), got " + Num(dot));
    }
    if (std::abs(dot) > 1e-12)
      axis = (axis - dot * contact->normal).normalized();  // into the contact plane
    contact->axis = axis;
    contact->length = Number(o.Require("length"), o.At("length"));
  }
  if (contact->type == ContactType::kPatch) {
    contact->radius = Number(o.Require("radius"), o.At("radius"));
  }
  if (contact->type == ContactType::kPoint) {
    if (const json* r = o.Find("radius")) contact->radius = Number(*r, o.At("radius"));
  }
}

ContactSpec ReadFinger(const json& v, const std::string& path) {
  Obj o(v, path,
        {"name", "type", "position", "normal", "axis", "length", "radius", "mu", "stiffness"});
  ContactSpec finger;
  finger.name = String(o.Require("name"), o.At("name"));
  ReadContact(o, &finger);
  if (const json* k = o.Find("stiffness")) {
    if (finger.type == ContactType::kPoint)
      o.Forbid("stiffness", "only for a line or patch finger (a pad of several points)");
    finger.stiffness = Number(*k, o.At("stiffness"));
    if (!(finger.stiffness > 0))
      throw SceneError(o.At("stiffness"), "must be > 0 N/m (leave it out for a rigid pad), got " +
                                              Num(finger.stiffness));
  }
  return finger;
}

// "motion": {"controller": NAME, "target": x, "gain": k, "tolerance": e,
// "hold_s": h} (closed loop; everything but the name optional).
PusherController ReadController(const json& v, const std::string& path) {
  Obj o(v, path, {"controller", "target", "gain", "tolerance", "hold_s"});
  PusherController c;
  c.name = String(o.Require("controller"), o.At("controller"));
  if (c.name.empty() || c.name.size() > kMaxNameLength) {
    throw SceneError(o.At("controller"), "must be 1..64 characters");
  }
  for (char ch : c.name) {
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-' || ch == '.')) {
      throw SceneError(o.At("controller"), "only letters, digits, '_', '-' and '.' are allowed");
    }
  }
  if (const json* x = o.Find("target")) c.target = Number(*x, o.At("target"));
  if (const json* x = o.Find("gain")) c.gain = Number(*x, o.At("gain"));
  if (const json* x = o.Find("tolerance")) c.tolerance = Number(*x, o.At("tolerance"));
  if (const json* x = o.Find("hold_s")) c.hold_s = Number(*x, o.At("hold_s"));
  if (!(c.tolerance > 0)) throw SceneError(o.At("tolerance"), "must be > 0");
  if (!(c.hold_s > 0) || c.hold_s > 60) throw SceneError(o.At("hold_s"), "must be in (0, 60] s");
  return c;
}

// An array of [a, b, c] rows (a path's positions or angles).
std::vector<Eigen::Vector3d> Rows3(const json& v, const std::string& path) {
  if (!v.is_array())
    throw SceneError(path, "must be an array of [x, y, z] rows, got " + TypeName(v));
  std::vector<Eigen::Vector3d> rows;
  rows.reserve(v.size());
  for (size_t i = 0; i < v.size(); ++i) rows.push_back(Vec3(v[i], Index(path, i)));
  return rows;
}

// "path": {"t": [...], "position": [[x, y, z], ...], "rpy": [[r, p, y], ...]}.
PusherPath ReadPath(const json& v, const std::string& path) {
  Obj o(v, path, {"t", "position", "rpy"});
  PusherPath out;
  const json& t = o.Require("t");
  if (!t.is_array())
    throw SceneError(o.At("t"), "must be an array of times (s), got " + TypeName(t));
  for (size_t i = 0; i < t.size(); ++i) out.t.push_back(Number(t[i], Index(o.At("t"), i)));
  out.position = Rows3(o.Require("position"), o.At("position"));
  if (const json* r = o.Find("rpy")) out.rpy = Rows3(*r, o.At("rpy"));
  return out;
}

// "support": {"mu": m, "pressure": "uniform" | {"points": [[x, y, w], ...]}}.
SupportSpec ReadSupport(const json& v, const std::string& path) {
  Obj o(v, path, {"mu", "pressure"});
  SupportSpec support;
  support.mu = Number(o.Require("mu"), o.At("mu"));
  if (const json* p = o.Find("pressure")) {
    const std::string ppath = o.At("pressure");
    if (p->is_string()) {
      const std::string text = p->get<std::string>();
      if (text != "uniform") {
        throw SceneError(
            ppath, "must be \"uniform\" or {\"points\": [[x, y, w], ...]}, got " + Quote(text));
      }
    } else {
      Obj pressure(*p, ppath, {"points"});
      const json& points = pressure.Require("points");
      const std::string list = pressure.At("points");
      if (!points.is_array() || points.empty()) {
        throw SceneError(list, "must be a non-empty array of [x, y, w] points");
      }
      for (size_t i = 0; i < points.size(); ++i)
        support.pressure_points.push_back(Vec3(points[i], Index(list, i)));
    }
  }
  return support;
}

PusherSpec ReadPusher(const json& v, const std::string& path) {
  Obj o(v, path, {"type", "position", "normal", "axis", "length", "radius", "mu", "motion"});
  PusherSpec pusher;
  pusher.name = "pusher";
  ReadContact(o, &pusher);
  if (const json* m = o.Find("motion")) {
    if (m->is_object() && m->contains("controller")) {
      pusher.controller = ReadController(*m, o.At("motion"));
      return pusher;
    }
    Obj motion(*m, o.At("motion"), {"velocity", "angular_velocity", "path"});
    if (const json* path = motion.Find("path")) {
      motion.Forbid("velocity", "a recorded path replaces velocity and angular_velocity");
      motion.Forbid("angular_velocity", "a recorded path replaces velocity and angular_velocity");
      pusher.path = ReadPath(*path, motion.At("path"));
      return pusher;
    }
    if (const json* vel = motion.Find("velocity")) {
      pusher.motion.velocity = Vec3(*vel, motion.At("velocity"));
    }
    if (const json* w = motion.Find("angular_velocity")) {
      pusher.motion.angular_velocity = Vec3(*w, motion.At("angular_velocity"));
    }
  }
  return pusher;
}

ModelOptions ReadModel(const json& v, const std::string& path) {
  Obj o(v, path, {"facets", "points", "dt", "reduce", "contacts", "pads", "cone", "inertia"});
  ModelOptions model;
  if (const json* f = o.Find("facets")) model.facets = Integer(*f, o.At("facets"), 3, kMaxFacets);
  if (const json* p = o.Find("points")) model.points = Integer(*p, o.At("points"), 2, kMaxPoints);
  if (const json* dt = o.Find("dt")) model.dt = Number(*dt, o.At("dt"));
  if (const json* r = o.Find("reduce")) {
    const std::string text = String(*r, o.At("reduce"));
    const auto parsed = ReduceFromString(text);
    if (!parsed) {
      throw SceneError(o.At("reduce"),
                       "must be \"auto\", \"full\" or \"planar\", got " + Quote(text));
    }
    model.reduce = *parsed;
  }
  if (const json* c = o.Find("contacts")) {
    const std::string text = String(*c, o.At("contacts"));
    const auto parsed = ContactTrackingFromString(text);
    if (!parsed) {
      throw SceneError(o.At("contacts"), "must be \"tracked\" or \"fixed\", got " + Quote(text));
    }
    model.contacts = *parsed;
  }
  // Two-valued choices (issue 31), each with its default first.
  const auto choice = [&](const char* key, const char* first, const char* second) {
    const json* c = o.Find(key);
    if (c == nullptr) return true;
    const std::string text = String(*c, o.At(key));
    if (text != first && text != second) {
      throw SceneError(o.At(key), std::string("must be \"") + first + "\" or \"" + second +
                                      "\", got " + Quote(text));
    }
    return text == first;
  };
  model.pads = choice("pads", "elastic", "rigid") ? PadModel::kElastic : PadModel::kRigid;
  model.cone =
      choice("cone", "aligned", "polyhedral") ? ConeModel::kAligned : ConeModel::kPolyhedral;
  // Three values: "auto" added for issue 31 beside the two that keep their
  // meaning ("auto" the default since then).
  if (const json* c = o.Find("inertia")) {
    const std::string text = String(*c, o.At("inertia"));
    if (text == "auto")
      model.inertia = InertiaModel::kAuto;
    else if (text == "carried")
      model.inertia = InertiaModel::kCarried;
    else if (text == "quasi_static")
      model.inertia = InertiaModel::kQuasiStatic;
    else
      throw SceneError(o.At("inertia"),
                       "must be \"auto\", \"carried\" or \"quasi_static\", got " + Quote(text));
  }
  return model;
}

GripperSpec ReadGripper(const json& v, const std::string& path) {
  Obj o(v, path, {"coupling"});
  GripperSpec gripper;
  if (const json* c = o.Find("coupling")) {
    const std::string text = String(*c, o.At("coupling"));
    if (text == "independent") {
      gripper.coupling = GripperCoupling::kIndependent;
    } else if (text == "parallel_jaw") {
      gripper.coupling = GripperCoupling::kParallelJaw;
    } else {
      throw SceneError(o.At("coupling"),
                       "must be \"independent\" or \"parallel_jaw\", got " + Quote(text));
    }
  }
  return gripper;
}

// ---------------------------------------------------------------------------
// Validation helpers.

void RequireFinite(double x, const std::string& path) {
  if (!std::isfinite(x)) throw SceneError(path, "must be finite, got " + Num(x));
}
void RequirePositive(double x, const std::string& path) {
  RequireFinite(x, path);
  if (!(x > 0)) throw SceneError(path, "must be > 0, got " + Num(x));
}
void RequireNonNegative(double x, const std::string& path) {
  RequireFinite(x, path);
  if (!(x >= 0)) throw SceneError(path, "must be >= 0, got " + Num(x));
}
void RequireFinite(const Eigen::Vector3d& v, const std::string& path) {
  for (int i = 0; i < 3; ++i) RequireFinite(v[i], Index(path, static_cast<size_t>(i)));
}
void RequireUnit(const Eigen::Vector3d& v, const std::string& path) {
  RequireFinite(v, path);
  const double n = v.norm();
  if (std::abs(n - 1) > kValidateUnitTolerance) {
    throw SceneError(path, "must be a unit vector (norm 1 within 1e-6), got norm " + Num(n));
  }
}

// Unsigned distance (m) from point p_G (gripper frame) to the object's surface.
double DistanceToSurface(const ObjectSpec& object, const Eigen::Vector3d& p_G) {
  const Eigen::Matrix3d R_GO = RotationFromRpy(object.pose.rpy);
  const Eigen::Vector3d p_O = R_GO.transpose() * (p_G - object.pose.position);
  // Signed distance of an axis-aligned box with half extents h (2-D or 3-D).
  auto box_sdf = [](const Eigen::VectorXd& q) {
    const double outside = q.cwiseMax(0.0).norm();
    const double inside = std::min(q.maxCoeff(), 0.0);
    return outside + inside;
  };
  if (object.shape == ObjectShape::kBox) {
    const Eigen::Vector3d q = p_O.cwiseAbs() - object.size / 2;
    return std::abs(box_sdf(q));
  }
  if (object.shape == ObjectShape::kPrism) {
    return std::abs(geometry::Solid(object).ClosestTo(p_O).distance);
  }
  Eigen::Vector2d q(std::hypot(p_O.x(), p_O.y()) - object.radius,
                    std::abs(p_O.z()) - object.height / 2);
  return std::abs(box_sdf(q));
}

// Where a contact's constituent points lie (an approximation of the model's
// placement, good enough to catch coincident contacts): a point; `points`
// points evenly along a line; `points` points on a patch's rim.
std::vector<Eigen::Vector3d> ConstituentPoints(const ContactSpec& c, int points) {
  std::vector<Eigen::Vector3d> out;
  if (c.type == ContactType::kPoint) {
    out.push_back(c.position);
  } else if (c.type == ContactType::kLine) {
    for (int j = 0; j < points; ++j) {
      const double s = -0.5 + static_cast<double>(j) / (points - 1);
      out.push_back(c.position + s * c.length * c.axis);
    }
  } else {
    const Eigen::Vector3d t1 = FirstTangent(c.normal);
    const Eigen::Vector3d t2 = c.normal.cross(t1);
    for (int j = 0; j < points; ++j) {
      const double a = 2 * std::numbers::pi * j / points;
      out.push_back(c.position + c.radius * (std::cos(a) * t1 + std::sin(a) * t2));
    }
  }
  return out;
}

bool ValidNameChar(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
         c == '-' || c == '.';
}

// A pusher path: times from 0, strictly increasing; rows of one length;
// the first position is the pusher's.
void ValidatePath(const PusherPath& path, const Eigen::Vector3d& start, double extent) {
  const std::string base = "pusher.motion.path";
  if (path.t.empty()) throw SceneError(Join(base, "t"), "must hold at least one time");
  if (path.t.size() > kMaxSceneArray) {
    throw SceneError(Join(base, "t"),
                     "must hold at most " + std::to_string(kMaxSceneArray) + " samples");
  }
  for (size_t i = 0; i < path.t.size(); ++i) RequireFinite(path.t[i], Index(Join(base, "t"), i));
  if (path.t[0] != 0) {
    throw SceneError(Index(Join(base, "t"), 0),
                     "must be 0 (the path starts with the scene), got " + Num(path.t[0]));
  }
  for (size_t i = 1; i < path.t.size(); ++i) {
    if (!(path.t[i] > path.t[i - 1])) {
      throw SceneError(Index(Join(base, "t"), i), "must be later than t[" + std::to_string(i - 1) +
                                                      "] = " + Num(path.t[i - 1]) +
                                                      " (times strictly increase), got " +
                                                      Num(path.t[i]));
    }
  }
  if (path.position.size() != path.t.size()) {
    throw SceneError(Join(base, "position"), "must have one row per time (" +
                                                 std::to_string(path.t.size()) + "), got " +
                                                 std::to_string(path.position.size()));
  }
  for (size_t i = 0; i < path.position.size(); ++i)
    RequireFinite(path.position[i], Index(Join(base, "position"), i));
  if (!path.rpy.empty() && path.rpy.size() != path.t.size()) {
    throw SceneError(Join(base, "rpy"), "must have one row per time (" +
                                            std::to_string(path.t.size()) + "), got " +
                                            std::to_string(path.rpy.size()));
  }
  for (size_t i = 0; i < path.rpy.size(); ++i)
    RequireFinite(path.rpy[i], Index(Join(base, "rpy"), i));
  const double off = (path.position[0] - start).norm();
  if (off > 1e-9 * extent) {
    throw SceneError(Index(Join(base, "position"), 0),
                     "must equal pusher.position (the path starts where the pusher is), " +
                         Num(off) + " m away");
  }
}

// The support: gravity to press the object on it, the object resting on a
// z cap, pressure points on that face with their centre under the centre
// of mass.
void ValidateSupport(const Scene& scene) {
  const SupportSpec& s = *scene.support;
  RequireNonNegative(s.mu, "support.mu");
  const double g = scene.gravity.norm();
  if (!(g > 0)) {
    throw SceneError("support", "needs gravity (the object's weight is the support's load)");
  }
  const Eigen::Matrix3d R_GO = RotationFromRpy(scene.object.pose.rpy);
  const double along = R_GO.col(2).dot(scene.gravity / g);
  if (std::abs(along) < 1 - 1e-9) {
    throw SceneError("support",
                     "the object rests on no face the model supports: its z axis must be along "
                     "gravity (a z cap on the support), |z . g| = " +
                         Num(std::abs(along)));
  }
  if (s.pressure_points.size() > kMaxSupportPoints) {
    throw SceneError("support.pressure.points",
                     "must hold at most " + std::to_string(kMaxSupportPoints) + " points");
  }
  if (s.pressure_points.empty()) return;
  const ObjectSpec& object = scene.object;
  const double extent = ObjectExtent(object);
  const std::string list = "support.pressure.points";
  double total = 0;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (size_t i = 0; i < s.pressure_points.size(); ++i) {
    const Eigen::Vector3d& p = s.pressure_points[i];
    const std::string at = Index(list, i);
    RequireFinite(p, at);
    if (!(p.z() >= 0)) throw SceneError(Index(at, 2), "weight must be >= 0, got " + Num(p.z()));
    const Eigen::Vector2d xy = p.head<2>();
    bool inside = false;
    if (object.shape == ObjectShape::kBox) {
      inside = std::abs(xy.x()) <= object.size.x() / 2 * (1 + 1e-9) &&
               std::abs(xy.y()) <= object.size.y() / 2 * (1 + 1e-9);
    } else if (object.shape == ObjectShape::kCylinder) {
      inside = xy.norm() <= object.radius * (1 + 1e-9);
    } else {
      inside = polygon::Contains(object.polygon, xy) ||
               polygon::ClosestOnBoundary(object.polygon, xy).distance <= 1e-9 * extent;
    }
    if (!inside) {
      throw SceneError(at, "lies off the object's face on the support (object frame x, y " +
                               Num(xy.x()) + ", " + Num(xy.y()) + ")");
    }
    total += p.z();
    centre += p.z() * xy;
  }
  if (!(total > 0)) throw SceneError(list, "weights must not all be zero");
  centre /= total;
  const Eigen::Vector3d com_O = geometry::Solid(object).centroid_O();
  const double off = (centre - com_O.head<2>()).norm();
  if (off > kSurfaceTolerance * extent) {
    throw SceneError(list,
                     "the centre of pressure must lie under the centre of mass (a rigid "
                     "body at rest on a plane), it is " +
                         Num(off) + " m off (tolerance " + Num(kSurfaceTolerance * extent) +
                         " m = 1% of the object's extent)");
  }
}

void ValidateContact(const ContactSpec& c, const std::string& path, const Scene& scene) {
  RequireFinite(c.position, Join(path, "position"));
  RequireUnit(c.normal, Join(path, "normal"));
  RequireNonNegative(c.mu, Join(path, "mu"));
  RequireNonNegative(c.stiffness, Join(path, "stiffness"));
  if (c.stiffness > 0 && c.type == ContactType::kPoint)
    throw SceneError(Join(path, "stiffness"),
                     "only for a line or patch finger (a pad of several points)");
  const double extent = ObjectExtent(scene.object);
  const double surface_tol = kSurfaceTolerance * extent;
  auto on_surface = [&](const Eigen::Vector3d& p, const std::string& field,
                        const std::string& what) {
    const double d = DistanceToSurface(scene.object, p);
    if (d > surface_tol) {
      throw SceneError(field, what + " must lie on the object's surface (distance " + Num(d) +
                                  " m, tolerance " + Num(surface_tol) +
                                  " m = 1% of the object's extent)");
    }
  };
  // Contacts lie on the object's surface at its pose in both contact modes
  // (SeatFingers() closes planned fingers onto an object at another pose).
  const Eigen::Matrix3d R_GO = RotationFromRpy(scene.object.pose.rpy);
  const geometry::Solid solid(scene.object);
  if (c.type == ContactType::kPoint) {
    RequireNonNegative(c.radius, Join(path, "radius"));
    if (c.radius > extent) {
      throw SceneError(Join(path, "radius"), "must not exceed the object's extent " + Num(extent) +
                                                 " m, got " + Num(c.radius));
    }
  }
  // A point pusher with tracked contacts may start apart from an object a
  // support holds, or along a recorded path (the contact is made when it
  // arrives), never inside it. In a grasp, a constant-velocity pusher must
  // touch at t = 0: one placed off the object (a varied offset past its edge)
  // is a campaign's mistake, not a push.
  const bool may_start_apart =
      path == "pusher" && c.type == ContactType::kPoint &&
      scene.model.contacts == ContactTracking::kTracked &&
      (scene.support.has_value() || (scene.pusher && scene.pusher->path.has_value()));
  const Eigen::Vector3d p_O = R_GO.transpose() * (c.position - scene.object.pose.position);
  if (may_start_apart) {
    const double depth = -solid.ClosestTo(p_O).distance;
    if (depth > surface_tol) {
      throw SceneError(Join(path, "position"), "lies inside the object (" + Num(depth) +
                                                   " m deep, tolerance " + Num(surface_tol) +
                                                   " m = 1% of the object's extent)");
    }
  } else {
    on_surface(c.position, Join(path, "position"), "the contact point");
  }
  const Eigen::Vector3d centre = scene.object.pose.position + R_GO * solid.centroid_O();
  if (scene.object.shape == ObjectShape::kPrism && !polygon::IsConvex(scene.object.polygon)) {
    // A non-convex outline: into the object is against the outward normal
    // of the closest surface point (its centre may lie anywhere).
    const Eigen::Vector3d outward = R_GO * solid.ClosestTo(p_O).normal_O;
    if (c.normal.dot(outward) >= 0) {
      throw SceneError(Join(path, "normal"),
                       "must point into the object (against the surface's outward normal)");
    }
  } else if (c.normal.dot(centre - c.position) <= 0) {
    // An inward normal of a convex body at a surface point has the centre
    // on its positive side.
    throw SceneError(Join(path, "normal"), "must point into the object (towards its centre)");
  }
  if (c.type == ContactType::kLine) {
    RequireUnit(c.axis, Join(path, "axis"));
    const double dot = c.axis.dot(c.normal);
    if (std::abs(dot) > kValidateUnitTolerance) {
      throw SceneError(Join(path, "axis"),
                       "must be perpendicular to normal (|axis.normal| <= 1e-6), got " + Num(dot));
    }
    RequirePositive(c.length, Join(path, "length"));
    const double spacing = c.length / (scene.model.points - 1);
    if (spacing < kCoincidentTolerance * extent) {
      throw SceneError(Join(path, "length"),
                       "too short: its " + std::to_string(scene.model.points) +
                           " constituent points would be " + Num(spacing) +
                           " m apart, coincident (< 1e-6 of the object's extent)");
    }
    for (double s : {-0.5, 0.5}) {
      on_surface(c.position + s * c.length * c.axis, Join(path, "length"), "each end of the line");
    }
  }
  if (c.type == ContactType::kPatch) {
    RequirePositive(c.radius, Join(path, "radius"));
    const double spacing = 2 * c.radius * std::sin(std::numbers::pi / scene.model.points);
    if (spacing < kCoincidentTolerance * extent) {
      throw SceneError(Join(path, "radius"),
                       "too small: its constituent points would be " + Num(spacing) +
                           " m apart, coincident (< 1e-6 of the object's extent)");
    }
    if (c.radius > extent) {
      throw SceneError(Join(path, "radius"), "must not exceed the object's extent " + Num(extent) +
                                                 " m, got " + Num(c.radius));
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------

namespace {

// ValidateScene's checks, one per part of the scene, in the order it runs
// them (the order decides which of two faults is reported).

void ValidateInertia(const Eigen::Matrix3d& I) {
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      RequireFinite(I(r, c),
                    Index(Index("object.inertia", static_cast<size_t>(r)), static_cast<size_t>(c)));
    }
  }
  const double scale = I.cwiseAbs().maxCoeff();
  if ((I - I.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) {
    throw SceneError("object.inertia", "must be symmetric");
  }
  const Eigen::Vector3d moments = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(I).eigenvalues();
  if (!(moments.minCoeff() > 0)) {
    throw SceneError("object.inertia", "must be positive definite, smallest principal moment " +
                                           Num(moments.minCoeff()));
  }
  // A rigid body's principal moments satisfy the triangle inequality.
  if (moments[0] + moments[1] < moments[2] * (1 - 1e-9)) {
    throw SceneError("object.inertia",
                     "principal moments " + Num(moments[0]) + ", " + Num(moments[1]) + ", " +
                         Num(moments[2]) +
                         " violate the triangle inequality (no rigid body has them)");
  }
}

void ValidateObject(const ObjectSpec& object) {
  if (object.shape == ObjectShape::kBox) {
    for (int i = 0; i < 3; ++i)
      RequirePositive(object.size[i], Index("object.size", static_cast<size_t>(i)));
  } else if (object.shape == ObjectShape::kPrism) {
    if (object.polygon.size() > kMaxPolygonVertices) {
      throw SceneError("object.polygon",
                       "must have at most " + std::to_string(kMaxPolygonVertices) + " vertices");
    }
    if (const auto problem = geometry::CheckPolygon(object.polygon)) {
      throw SceneError(Index("object.polygon", problem->vertex), problem->reason);
    }
    RequirePositive(object.height, "object.height");
  } else {
    RequirePositive(object.radius, "object.radius");
    RequirePositive(object.height, "object.height");
  }
  RequirePositive(object.mass, "object.mass");
  if (object.inertia) ValidateInertia(*object.inertia);
}

// Pose, gravity, duration, grip force and the model's settings.
void ValidateSettings(const Scene& scene) {
  RequireFinite(scene.object.pose.position, "object.pose.position");
  RequireFinite(scene.object.pose.rpy, "object.pose.rpy");
  RequireFinite(scene.gravity, "gravity");
  RequirePositive(scene.duration, "duration");
  if (scene.duration > kMaxDuration) {
    throw SceneError("duration",
                     "must be <= " + Num(kMaxDuration) + " s, got " + Num(scene.duration));
  }
  RequireNonNegative(scene.grip_force, "grip_force");

  const ModelOptions& model = scene.model;
  if (model.facets < 3 || model.facets > kMaxFacets) {
    throw SceneError("model.facets", "must be an integer in [3, " + std::to_string(kMaxFacets) +
                                         "], got " + std::to_string(model.facets));
  }
  if (model.points < 2 || model.points > kMaxPoints) {
    throw SceneError("model.points", "must be an integer in [2, " + std::to_string(kMaxPoints) +
                                         "], got " + std::to_string(model.points));
  }
  RequirePositive(model.dt, "model.dt");
  if (model.dt > scene.duration) {
    throw SceneError("model.dt",
                     "must be <= duration (" + Num(scene.duration) + " s), got " + Num(model.dt));
  }
  if (scene.duration / model.dt > kMaxSteps) {
    throw SceneError("model.dt", "too small: duration / dt = " + Num(scene.duration / model.dt) +
                                     " steps, more than " + Num(kMaxSteps));
  }
}

// Lines and patches need enough constituent points to be a line or a patch.
void CheckPatchPoints(const ContactSpec& c, const std::string& path, const ModelOptions& model) {
  if (c.type == ContactType::kPatch && model.points < 3) {
    throw SceneError("model.points", "must be >= 3 when the scene has a patch contact (" + path +
                                         "), got " + std::to_string(model.points));
  }
}

// fingers[i].name: non-empty, short, plain, not "pusher", unique.
void ValidateFingerName(const std::vector<ContactSpec>& fingers, size_t i,
                        const std::string& path) {
  const ContactSpec& f = fingers[i];
  if (f.name.empty()) throw SceneError(Join(path, "name"), "must not be empty");
  if (f.name.size() > kMaxNameLength) {
    throw SceneError(Join(path, "name"),
                     "must be at most " + std::to_string(kMaxNameLength) + " characters");
  }
  if (!std::all_of(f.name.begin(), f.name.end(), ValidNameChar)) {
    throw SceneError(Join(path, "name"),
                     "may contain only letters, digits, '_', '-' and '.', got " + Quote(f.name));
  }
  if (f.name == "pusher")
    throw SceneError(Join(path, "name"), "\"pusher\" is reserved for the pusher");
  for (size_t j = 0; j < i; ++j) {
    if (fingers[j].name == f.name) {
      throw SceneError(Join(path, "name"), "duplicates the name of fingers[" + std::to_string(j) +
                                               "], " + Quote(f.name));
    }
  }
}

void ValidatePusher(const Scene& scene) {
  const PusherSpec& p = *scene.pusher;
  CheckPatchPoints(p, "pusher", scene.model);
  ValidateContact(p, "pusher", scene);
  if (p.stiffness != 0)
    throw SceneError("pusher.stiffness", "only for finger pads (the pusher is rigid)");
  RequireFinite(p.motion.velocity, "pusher.motion.velocity");
  RequireFinite(p.motion.angular_velocity, "pusher.motion.angular_velocity");
  if (p.path) {
    if (p.controller)
      throw SceneError("pusher.motion.path", "a recorded path and a controller exclude each other");
    if (p.motion.velocity != Eigen::Vector3d::Zero() ||
        p.motion.angular_velocity != Eigen::Vector3d::Zero())
      throw SceneError("pusher.motion.path",
                       "replaces velocity and angular_velocity (set them zero)");
    ValidatePath(*p.path, p.position, ObjectExtent(scene.object));
  }
  if (p.controller) {
    if (p.controller->name.empty() || p.controller->name.size() > kMaxNameLength)
      throw SceneError("pusher.motion.controller", "must be 1..64 characters");
    if (!std::isfinite(p.controller->target) || !std::isfinite(p.controller->gain))
      throw SceneError("pusher.motion", "target and gain must be finite");
    if (!(p.controller->tolerance > 0) || !std::isfinite(p.controller->tolerance))
      throw SceneError("pusher.motion.tolerance", "must be > 0");
    if (!(p.controller->hold_s > 0) || p.controller->hold_s > 60)
      throw SceneError("pusher.motion.hold_s", "must be in (0, 60] s");
  }
}

// Two contacts whose constituent points (nearly) coincide make a
// degenerate grasp matrix: refuse them rather than let the solver guess.
void CheckCoincidentContacts(
    const std::vector<std::pair<std::string, std::vector<Eigen::Vector3d>>>& constituents,
    const ObjectSpec& object) {
  const double coincident = kCoincidentTolerance * ObjectExtent(object);
  for (size_t a = 0; a < constituents.size(); ++a) {
    for (size_t b = 0; b < a; ++b) {
      double closest = std::numeric_limits<double>::infinity();
      for (const auto& pa : constituents[a].second) {
        for (const auto& pb : constituents[b].second) closest = std::min(closest, (pa - pb).norm());
      }
      if (closest < coincident) {
        throw SceneError(Join(constituents[a].first, "position"),
                         "coincides with " + constituents[b].first + " (constituent points " +
                             Num(closest) + " m apart, tolerance " + Num(coincident) +
                             " m = 1e-6 of the object's extent)");
      }
    }
  }
}

void CheckGrasp(const Scene& scene) {
  // A parallel-jaw mechanism moves two opposed fingers.
  if (scene.gripper.coupling == GripperCoupling::kParallelJaw) {
    const bool opposed =
        scene.fingers.size() == 2 &&
        (scene.fingers[0].normal.normalized() + scene.fingers[1].normal.normalized()).norm() < 1e-3;
    if (!opposed) {
      throw SceneError("gripper.coupling",
                       "parallel_jaw needs exactly two fingers with opposed normals, got " +
                           std::to_string(scene.fingers.size()) + " finger(s)" +
                           (scene.fingers.size() == 2 ? " whose normals do not oppose" : ""));
    }
  }
  // Grip forces are prescribed (each finger pushes grip_force along its
  // normal), so unless they cancel the grasp itself accelerates the object
  // without bound: one finger, or fingers that do not oppose, is no grasp.
  if (scene.grip_force > 0) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const auto& f : scene.fingers) sum += f.normal;
    const double tolerance = 1e-3 * static_cast<double>(scene.fingers.size());
    if (sum.norm() > tolerance) {
      throw SceneError("fingers", "the grip forces do not balance: the finger normals sum to (" +
                                      Num(sum.x()) + ", " + Num(sum.y()) + ", " + Num(sum.z()) +
                                      "), norm " + Num(sum.norm()) + " > " + Num(tolerance) +
                                      " (opposing fingers' normals must cancel)");
    }
  }
}

}  // namespace

void ValidateScene(const Scene& scene) {
  ValidateObject(scene.object);
  ValidateSettings(scene);
  if (scene.fingers.empty() && !scene.support) {
    throw SceneError("fingers", "must list at least one finger (or the scene needs a support)");
  }
  if (scene.support) ValidateSupport(scene);
  if (scene.fingers.size() > static_cast<size_t>(kMaxFingers)) {
    throw SceneError("fingers", "must list at most " + std::to_string(kMaxFingers) +
                                    " fingers, got " + std::to_string(scene.fingers.size()));
  }
  std::vector<std::pair<std::string, std::vector<Eigen::Vector3d>>> constituents;
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    const std::string path = Index("fingers", i);
    ValidateFingerName(scene.fingers, i, path);
    CheckPatchPoints(scene.fingers[i], path, scene.model);
    ValidateContact(scene.fingers[i], path, scene);
    constituents.emplace_back(path, ConstituentPoints(scene.fingers[i], scene.model.points));
  }
  if (scene.pusher) {
    ValidatePusher(scene);
    constituents.emplace_back("pusher", ConstituentPoints(*scene.pusher, scene.model.points));
  }
  CheckCoincidentContacts(constituents, scene.object);
  CheckGrasp(scene);
}

namespace {
// Pass 1 for any document: the tree, or the first problem with its path.
json BuildDocument(std::string_view text, const JsonLimits& limits,
                   std::optional<JsonProblem>* problem) {
  if (text.size() > limits.max_bytes) {
    *problem =
        JsonProblem{"", "is " + std::to_string(text.size()) + " bytes, larger than the limit of " +
                            std::to_string(limits.max_bytes) + " bytes"};
    return nullptr;
  }
  PathTrackingBuilder builder(limits);
  const bool ok = json::sax_parse(text.begin(), text.end(), &builder, json::input_format_t::json,
                                  /*strict=*/true, /*ignore_comments=*/false);
  if (!ok || !builder.error_reason.empty()) {
    *problem = JsonProblem{builder.error_path,
                           builder.error_reason.empty() ? "invalid JSON" : builder.error_reason};
    return nullptr;
  }
  return std::move(builder.root);
}
}  // namespace

std::optional<JsonProblem> FindJsonProblem(std::string_view text, const JsonLimits& limits) {
  std::optional<JsonProblem> problem;
  BuildDocument(text, limits, &problem);
  return problem;
}

Scene ParseScene(std::string_view json_text) {
  std::optional<JsonProblem> problem;
  const json doc = BuildDocument(json_text, JsonLimits{}, &problem);
  if (problem) throw SceneError(problem->path, problem->reason);

  Obj root(doc, "",
           {"object", "gravity", "duration", "grip_force", "fingers", "pusher", "support", "model",
            "gripper"});
  Scene scene;
  scene.object = ReadObject(root.Require("object"), "object");
  if (const json* g = root.Find("gravity")) scene.gravity = Vec3(*g, "gravity");
  scene.duration = Number(root.Require("duration"), "duration");
  scene.grip_force = Number(root.Require("grip_force"), "grip_force");
  const json& fingers = root.Require("fingers");
  if (!fingers.is_array())
    throw SceneError("fingers", "must be an array of fingers, got " + TypeName(fingers));
  if (const json* sup = root.Find("support")) scene.support = ReadSupport(*sup, "support");
  if (fingers.empty() && !scene.support) {
    throw SceneError("fingers", "must list at least one finger (or the scene needs a support)");
  }
  if (fingers.size() > static_cast<size_t>(kMaxFingers)) {
    throw SceneError("fingers", "must list at most " + std::to_string(kMaxFingers) +
                                    " fingers, got " + std::to_string(fingers.size()));
  }
  for (size_t i = 0; i < fingers.size(); ++i)
    scene.fingers.push_back(ReadFinger(fingers[i], Index("fingers", i)));
  if (const json* p = root.Find("pusher")) scene.pusher = ReadPusher(*p, "pusher");
  if (const json* m = root.Find("model")) scene.model = ReadModel(*m, "model");
  if (const json* g = root.Find("gripper")) scene.gripper = ReadGripper(*g, "gripper");
  ValidateScene(scene);
  return scene;
}

Scene LoadSceneFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw SceneError("", "cannot open '" + path + "'");
  const std::streamoff size = in.tellg();
  if (size < 0) throw SceneError("", "cannot read '" + path + "'");
  if (static_cast<std::uintmax_t>(size) > kMaxSceneBytes) {
    throw SceneError("", "'" + path + "' is " + std::to_string(size) +
                             " bytes, larger than the limit of " + std::to_string(kMaxSceneBytes) +
                             " bytes (1 MiB)");
  }
  in.seekg(0);
  std::string text(static_cast<size_t>(size), '\0');
  in.read(text.data(), size);
  if (!in) throw SceneError("", "cannot read '" + path + "'");
  return ParseScene(text);
}

namespace {
nlohmann::ordered_json Vec(const Eigen::Vector3d& v) {
  return nlohmann::ordered_json::array({v.x(), v.y(), v.z()});
}

nlohmann::ordered_json ContactJson(const ContactSpec& c, bool with_name) {
  nlohmann::ordered_json j;
  if (with_name) j["name"] = c.name;
  j["type"] = ToString(c.type);
  j["position"] = Vec(c.position);
  j["normal"] = Vec(c.normal);
  if (c.type == ContactType::kLine) {
    j["axis"] = Vec(c.axis);
    j["length"] = c.length;
  }
  if (c.type == ContactType::kPatch || (c.type == ContactType::kPoint && c.radius != 0))
    j["radius"] = c.radius;
  j["mu"] = c.mu;
  if (c.stiffness > 0) j["stiffness"] = c.stiffness;
  return j;
}
}  // namespace

void SeatFingers(Scene* scene) {
  const ObjectSpec& object = scene->object;
  const Eigen::Matrix3d R_GO = RotationFromRpy(object.pose.rpy);
  const geometry::Solid solid(object);
  const double tolerance = 1e-9 * ObjectExtent(object);
  for (size_t i = 0; i < scene->fingers.size(); ++i) {
    ContactSpec& f = scene->fingers[i];
    const Eigen::Vector3d n = f.normal.normalized();
    // The pad's constituent points; the one that meets the object first
    // sets how far the pad closes.
    std::vector<Eigen::Vector3d> at = {f.position};
    if (f.type == ContactType::kLine) {
      at = {f.position - f.length / 2 * f.axis, f.position + f.length / 2 * f.axis};
    }
    double first = std::numeric_limits<double>::infinity();
    for (const auto& p : at) {
      const auto e = solid.EntryOf(R_GO.transpose() * (p - object.pose.position),
                                   R_GO.transpose() * n, tolerance);
      if (e) first = std::min(first, e->s);
    }
    if (!std::isfinite(first)) {
      throw SceneError(Join(Index("fingers", i), "position"),
                       "closing along its normal, the finger misses the object at its pose");
    }
    f.position += first * n;
  }
  // A pusher cannot start inside the object: it stops where it touches.
  if (scene->pusher) {
    PusherSpec& p = *scene->pusher;
    const Eigen::Vector3d n = p.normal.normalized();
    const auto e = solid.EntryOf(R_GO.transpose() * (p.position - object.pose.position),
                                 R_GO.transpose() * n, tolerance);
    if (e && e->s < 0) {
      // A recorded path moves with its start (position[0] is the pusher's
      // position): the pusher's motion relative to its start is what was
      // recorded, and a start pose measured a fraction of a millimetre into
      // the pusher must not break the path's first point.
      p.position += e->s * n;
      if (p.path) {
        for (auto& q : p.path->position) q += e->s * n;
      }
    }
  }
}

std::string SceneToJson(const Scene& scene, int indent) {
  using ojson = nlohmann::ordered_json;
  ojson object;
  object["shape"] = ToString(scene.object.shape);
  if (scene.object.shape == ObjectShape::kBox) {
    object["size"] = Vec(scene.object.size);
  } else if (scene.object.shape == ObjectShape::kCylinder) {
    object["radius"] = scene.object.radius;
    object["height"] = scene.object.height;
  } else {
    object["polygon"] = ojson::array();
    for (const auto& v : scene.object.polygon) object["polygon"].push_back({v.x(), v.y()});
    object["height"] = scene.object.height;
  }
  object["mass"] = scene.object.mass;
  if (scene.object.inertia) {
    const Eigen::Matrix3d& I = *scene.object.inertia;
    object["inertia"] = ojson::array();
    for (int r = 0; r < 3; ++r)
      object["inertia"].push_back(ojson::array({I(r, 0), I(r, 1), I(r, 2)}));
  }
  object["pose"] = {{"position", Vec(scene.object.pose.position)},
                    {"rpy", Vec(scene.object.pose.rpy)}};

  ojson j;
  j["object"] = std::move(object);
  j["gravity"] = Vec(scene.gravity);
  j["duration"] = scene.duration;
  j["grip_force"] = scene.grip_force;
  j["fingers"] = ojson::array();
  for (const auto& f : scene.fingers) j["fingers"].push_back(ContactJson(f, true));
  if (scene.pusher) {
    ojson p = ContactJson(*scene.pusher, false);
    if (const auto& c = scene.pusher->controller) {
      p["motion"] = {{"controller", c->name},
                     {"target", c->target},
                     {"gain", c->gain},
                     {"tolerance", c->tolerance},
                     {"hold_s", c->hold_s}};
    } else if (const auto& path = scene.pusher->path) {
      ojson rows = ojson::array();
      for (const auto& x : path->position) rows.push_back(Vec(x));
      ojson jp = {{"t", path->t}, {"position", std::move(rows)}};
      if (!path->rpy.empty()) {
        ojson angles = ojson::array();
        for (const auto& a : path->rpy) angles.push_back(Vec(a));
        jp["rpy"] = std::move(angles);
      }
      p["motion"] = {{"path", std::move(jp)}};
    } else {
      p["motion"] = {{"velocity", Vec(scene.pusher->motion.velocity)},
                     {"angular_velocity", Vec(scene.pusher->motion.angular_velocity)}};
    }
    j["pusher"] = std::move(p);
  }
  if (const auto& support = scene.support) {
    ojson js = {{"mu", support->mu}};
    if (support->pressure_points.empty()) {
      js["pressure"] = "uniform";
    } else {
      ojson points = ojson::array();
      for (const auto& p : support->pressure_points) points.push_back(Vec(p));
      js["pressure"] = {{"points", std::move(points)}};
    }
    j["support"] = std::move(js);
  }
  j["model"] = {{"facets", scene.model.facets},
                {"points", scene.model.points},
                {"dt", scene.model.dt},
                {"reduce", ToString(scene.model.reduce)},
                {"contacts", ToString(scene.model.contacts)}};
  // Written when not the default (scenes written before them read the same).
  if (scene.model.pads != PadModel::kElastic) j["model"]["pads"] = ToString(scene.model.pads);
  if (scene.model.cone != ConeModel::kAligned) j["model"]["cone"] = ToString(scene.model.cone);
  if (scene.model.inertia != InertiaModel::kAuto)
    j["model"]["inertia"] = ToString(scene.model.inertia);
  // Written only when it says something: a scene without it means independent pads.
  if (scene.gripper.coupling != GripperCoupling::kIndependent)
    j["gripper"] = {{"coupling", ToString(scene.gripper.coupling)}};
  return j.dump(indent);
}

}  // namespace arena::mechanics
