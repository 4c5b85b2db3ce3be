// Reading and writing scene JSON (docs/scene.md). This is the edge of the
// mechanics room: the model itself never sees JSON.
//
// Validation rules (docs/scene.md leaves these open; this list is their reference):
//  - Input: at most kMaxSceneBytes bytes of UTF-8 JSON, nesting at most
//    kMaxSceneDepth levels, arrays at most kMaxSceneArray elements, no
//    duplicate keys, no unknown keys (typo protection: every key must be one
//    docs/scene.md defines). Malformed JSON names the byte offset and the path
//    where it broke ("fingers[0].mu: invalid JSON at byte 212: ...").
//  - Shapes: box (size), cylinder (radius, height), prism (polygon: simple,
//    convex or not, counter-clockwise, 3..256 vertices, refused naming the
//    vertex; height).
//    A point contact may have a radius (a sphere). model.contacts: tracked
//    (default) or fixed.
//  - Required: object.shape, object.mass, the shape's dimensions, duration,
//    grip_force, fingers (1..kMaxFingers), and for each contact type,
//    position, normal, mu (+ axis, length for a line; radius for a patch).
//    Optional with defaults: object.pose (identity), object.inertia (from
//    shape), gravity (zero), pusher (none), pusher.motion (zero), model and
//    each of its fields (ModelOptions defaults).
//  - Directions: ParseScene accepts a normal / axis whose norm is 1 within
//    1e-3 (hand-written 0.7071 values) and normalises it; a line axis must be
//    perpendicular to the normal within 1e-3 and is projected exactly onto the
//    contact plane. ValidateScene (scenes built in code) demands both within
//    1e-6.
//  - Geometry: every contact position (and both ends of a line) lies on the
//    object's surface within 1% of the object's size; normals point into the
//    object; constituent points of different contacts (and of one line or
//    patch) must be at least 1e-6 of the object's size apart (coincident).
//  - Support (optional): mu >= 0, gravity non-zero, the object's z axis
//    along gravity; pressure points on the resting face, weights >= 0 not
//    all zero, their centre under the centre of mass (1% of the extent).
//    fingers may then be empty. A point pusher with tracked contacts may
//    start apart from the object (not inside it).
//  - Pusher path: t from 0, strictly increasing, at most kMaxSceneArray
//    samples; position (and rpy, if given) one row per time; position[0]
//    equals pusher.position (1e-9 of the extent); excludes velocity,
//    angular_velocity and a controller.
//  - Grasp: with grip_force > 0 the finger normals must cancel (|sum| <=
//    1e-3 per finger): grip forces are prescribed, so an unbalanced grasp
//    (one finger, or fingers that do not oppose) would fling the object.
#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

#include "arena/errors/error.hpp"
#include "arena/mechanics/scene.hpp"

namespace arena::mechanics {

inline constexpr std::size_t kMaxSceneBytes = 1 << 20;  // 1 MiB of JSON
inline constexpr int kMaxSceneDepth = 16;               // nesting levels
inline constexpr std::size_t kMaxSceneArray = 4096;     // elements per array
inline constexpr int kMaxFingers = 16;
inline constexpr std::size_t kMaxPolygonVertices = 256;  // prism polygons
inline constexpr int kMaxFacets = 64;
inline constexpr int kMaxPoints = 32;
inline constexpr double kMaxDuration = 3600.0;  // s: one trial is not an hour
inline constexpr double kMaxSteps = 1e7;        // duration / dt: bounds run time
inline constexpr std::size_t kMaxNameLength = 64;
inline constexpr std::size_t kMaxSupportPoints = 1024;  // support.pressure.points

// A scene that is missing a field, has a field of the wrong type, a
// non-finite number or a value out of range. field() is the JSON path
// ("fingers[1].mu"; empty for the document as a whole), what() is
// "fingers[1].mu: must be >= 0, got -0.2" ("scene: ..." when field() is empty).
class SceneError : public Error {
 public:
  SceneError(std::string field, const std::string& reason);
  const std::string& field() const { return field_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string field_;
  std::string reason_;
};

// @throws SceneError naming the first offending field.
Scene ParseScene(std::string_view json_text);

// Limits and problems of JSON text in general (campaigns use them too).
struct JsonLimits {
  std::size_t max_bytes = kMaxSceneBytes;
  int max_depth = kMaxSceneDepth;
  std::size_t max_array = kMaxSceneArray;
};
struct JsonProblem {
  std::string path;    // where ("fingers[0].mu"; empty: the document)
  std::string reason;  // "invalid JSON at byte offset 212: ...", "duplicate key", ...
};
// The first problem of `text`: malformed JSON or non-UTF-8 (with its byte
// offset), a duplicate key, or a limit exceeded; nullopt when it is fine.
// Memory stays bounded by a small multiple of limits.max_bytes.
std::optional<JsonProblem> FindJsonProblem(std::string_view text, const JsonLimits& limits = {});

// Reads a scene file; refuses files larger than kMaxSceneBytes before
// reading them. @throws SceneError (field "") when the file cannot be read.
Scene LoadSceneFile(const std::string& path);

// Checks ranges and consistency of a scene built in code.
// @throws SceneError naming the first offending field.
void ValidateScene(const Scene& scene);

// Fingers close on the object at object.pose: each finger moves along its
// normal (its closing direction) until its pad meets the object's surface
// (a line: its first end to meet it); a pusher that would start inside the
// object moves back along its normal to touch it. For an object whose pose differs from
// the one the contacts were planned for (a reset that left it elsewhere).
// @throws SceneError naming fingers[i].position when a finger misses.
void SeatFingers(Scene* scene);

// The scene as docs/scene.md JSON (compact when indent < 0);
// ParseScene(SceneToJson(s)) reproduces s bit for bit.
std::string SceneToJson(const Scene& scene, int indent = -1);

// "box" / "cylinder"; "point" / "line" / "patch"; "auto" / "full" / "planar".
const char* ToString(ObjectShape shape);
std::optional<ObjectShape> ObjectShapeFromString(std::string_view text);
std::optional<ContactType> ContactTypeFromString(std::string_view text);
std::optional<Reduce> ReduceFromString(std::string_view text);
// "tracked" / "fixed".
std::optional<ContactTracking> ContactTrackingFromString(std::string_view text);
// "elastic" / "rigid"; "polyhedral" / "aligned"; "carried" / "quasi_static" / "auto".
std::optional<PadModel> PadModelFromString(std::string_view text);
std::optional<ConeModel> ConeModelFromString(std::string_view text);
std::optional<InertiaModel> InertiaModelFromString(std::string_view text);

// The scene's length scale (m): the largest extent of the object (box: its
// largest side; cylinder: max(diameter, height)). Tolerances scale with it.
double ObjectExtent(const ObjectSpec& object);

}  // namespace arena::mechanics
