// Scene: one prehensile-pushing setup (docs/scene.md is the contract).
//
// Plain structs, SI units, everything in the gripper frame at t = 0. A Scene
// that came out of ParseScene() is valid; code that builds one by hand should
// call ValidateScene() before simulating it.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace arena::mechanics {

// kPrism: a convex polygon in the object's xy-plane extruded along its z.
enum class ObjectShape { kBox, kCylinder, kPrism };
enum class ContactType { kPoint, kLine, kPatch };
// kAuto: model only what the scene requires; kFull: always 6 DOF;
// kPlanar: 3 DOF, refuse a scene that is not planar.
enum class Reduce { kAuto, kFull, kPlanar };
// kTracked: contact points and normals follow the object's surface every step
// and contacts are made and lost; kFixed: contact frames frozen in the
// gripper frame (right for small motion only, cheaper).
enum class ContactTracking { kTracked, kFixed };
// Line and patch pads without a `stiffness`: kRigid leaves their load split
// undetermined (the solver's vertex); kElastic gives them the default
// stiffness (model.cpp, DefaultPadStiffness: sinking 1e-4 of the object's
// extent under the grip), which decides it.
enum class PadModel { kRigid, kElastic };
// kPolyhedral: the cone's edges stay on the docs/scene.md tangent basis;
// kAligned: a tracked point's cone turns so that an edge opposes its last
// slip off an edge (the slip direction is not steered by the facets).
enum class ConeModel { kPolyhedral, kAligned };

struct Pose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // m
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();       // rad, about fixed x, y, z
};

struct ObjectSpec {
  ObjectShape shape = ObjectShape::kBox;
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // box: full extents (m)
  double radius = 0;                               // cylinder (m)
  double height = 0;                               // cylinder, prism (m), along object z
  std::vector<Eigen::Vector2d> polygon;            // prism: convex, counter-clockwise (m)
  double mass = 0;                                 // kg, > 0
  std::optional<Eigen::Matrix3d> inertia;          // kg m^2 about the centre of mass
  Pose pose;
};

struct ContactSpec {
  std::string name;
  ContactType type = ContactType::kPoint;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // on the object surface (m)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitX();   // unit, into the object
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();     // line: unit direction
  double length = 0;                                   // line (m)
  double radius = 0;                                   // patch (m); point: a sphere's (m)
  double mu = 0;                                       // friction coefficient, >= 0
  // Finger pads of a line or patch: their normal stiffness (N/m, the whole
  // pad, shared by its constituent points); 0 = rigid. An elastic pad shares
  // its load by penetration where a rigid one's sharing is undetermined.
  double stiffness = 0;
};

struct PusherMotion {
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();          // m/s, relative to the gripper
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s, about the contact point
};

// A closed-loop pusher (JSON: "motion": {"controller": NAME, ...}): a
// controller registered under `name` commands the motion each sample
// (docs/live_control.md). target, gain and tolerance mean what the controller
// makes of them (pivot_to_angle: angle in rad, speed per rad, rad).
struct PusherController {
  std::string name;         // [A-Za-z0-9_.-]{1,64}
  double target = 0;        // the controller's goal
  double gain = 1;          // its gain
  double tolerance = 0.02;  // reached when |error| <= tolerance (controller's units), > 0
  double hold_s = 0.05;     // the cell holds the last command at most this long (s), > 0
};

struct PusherSpec : ContactSpec {
  PusherMotion motion;
  // Set: closed loop; `motion` is then the command before the first answer
  // (zero) and the controller's commands replace it step by step.
  std::optional<PusherController> controller;
};

struct ModelOptions {
  int facets = 8;     // edges of the inscribed polyhedral friction cone, >= 3
  int points = 3;     // constituent points per line (patch)
  double dt = 0.004;  // time step (s)
  Reduce reduce = Reduce::kAuto;
  ContactTracking contacts = ContactTracking::kTracked;
  PadModel pads = PadModel::kRigid;
  ConeModel cone = ConeModel::kPolyhedral;
};

struct Scene {
  ObjectSpec object;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();  // m/s^2; zero = no gravity rows
  double duration = 1.0;                              // s
  double grip_force = 0;                              // N per finger (sum over constituents)
  std::vector<ContactSpec> fingers;
  std::optional<PusherSpec> pusher;
  ModelOptions model;
};

const char* ToString(ContactType type);
const char* ToString(Reduce reduce);
const char* ToString(ContactTracking tracking);
const char* ToString(PadModel pads);
const char* ToString(ConeModel cone);

}  // namespace arena::mechanics
