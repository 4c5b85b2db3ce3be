// What the store keeps of a trial's scene, handed to it by its caller. db
// reads no scene (docs/scene.md is mechanics' contract): the caller, which has
// the scene parsed already (the orchestrator, the importer, the CLI's export),
// computes these facts once with mechanics' own functions and passes them in.
#pragma once

#include <array>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "arena/db/outcomes.hpp"

namespace arena::db {

struct SceneFacts {
  // The trial's indexed parameter columns (db/README.md, table trials);
  // absent: stored as NULL (the scene has no such part).
  std::optional<std::string> object_shape;  // box, cylinder, prism
  std::optional<double> object_mass;        // kg
  std::optional<double> grip_force;         // N
  std::optional<std::string> finger_type;   // point, line, patch; "mixed" when fingers differ
  int finger_count = 0;
  std::optional<double> finger_mu;             // mean over the fingers
  std::optional<std::string> pusher_type;      // point, line, patch; absent: no pusher
  std::optional<double> pusher_mu;             //
  std::optional<double> pusher_speed;          // m/s, |velocity| of a velocity motion
  std::optional<double> pusher_angular_speed;  // rad/s, |angular_velocity| of one
  std::optional<double> duration;              // s
  // Contact types of fingers and pusher as ContactTypeBit flags (never 0).
  int contact_mask = 0;
  // The object's nominal start pose in the gripper frame: x, y, z (m), then
  // the unit quaternion w, x, y, z of its rpy.
  std::array<double, 7> nominal{0, 0, 0, 1, 0, 0, 0};
  // The contacts in scene order (fingers, then the pusher): the outcomes at
  // ingest and the export's column names. Not stored.
  std::vector<ContactSite> contacts;
};

// The facts of a scene given as JSON text (as stored in trials.scene_json).
// Throws (std::exception) for a scene it cannot read; the store's users that
// only have stored text (export, the migration that computes old outcomes)
// take one from their caller.
using SceneFactsFn = std::function<SceneFacts(const std::string& scene_json)>;

}  // namespace arena::db
