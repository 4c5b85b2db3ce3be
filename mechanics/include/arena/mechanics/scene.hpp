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

// kPrism: a simple (convex or not) counter-clockwise polygon in the
// object's xy-plane extruded along its z.
enum class ObjectShape { kBox, kCylinder, kPrism };
enum class ContactType { kPoint, kLine, kPatch };
// kAuto: model only what the scene requires; kFull: always 6 DOF;
// kPlanar: 3 DOF, refuse a scene that is not planar.
enum class Reduce { kAuto, kFull, kPlanar };
// kTracked: contact points and normals follow the object's surface every step
// and contacts are made and lost; kFixed: contact frames frozen in the
// gripper frame (right for small motion only, cheaper).
enum class ContactTracking { kTracked, kFixed };
// Line and patch pads without a `stiffness`: kElastic (the default, JSON
// "elastic" or absent) gives them the default stiffness (model.cpp,
// DefaultPadStiffness: sinking 1e-4 of the object's extent under the grip),
// which decides their load split; kRigid ("rigid") leaves it undetermined
// (the solver's vertex, history-dependent).
enum class PadModel { kRigid, kElastic };
// kAligned (the default since issue 31, JSON "aligned" or absent): a
// tracked sliding point's cone turns until an edge opposes its slip
// (AlignCones), so the slip direction is not steered by the facets; with
// quasi-static steps the cones turn between balances (BalanceAligned) and a
// damper across the aligned edge, the circular cone to first order,
// chooses the slip within the vertex's fan (SetSlipDampers).
// kPolyhedral ("polyhedral", the default before): the cone's edges stay on
// the docs/scene.md tangent basis, so a slide in a free direction is
// steered towards an edge (docs/scene.md, "Which knob matters").
enum class ConeModel { kPolyhedral, kAligned };
// kCarried ("carried", the default before issue 31): each step carries the
// object's momentum (quasi-dynamic). kQuasiStatic ("quasi_static"): each
// step is solved again from its own answer until the inertial force M Δv /
// dt it needs is below 1e-6 of the force scale, so the forces balance (the
// mass only regularises the solve) and the step ends on a balanced path; a
// push that needs the momentum is refused. kAuto ("auto", the default since
// issue 31): quasi-static for an object held in a grasp (fingers and no
// support), carried for one a support carries or no finger holds (on the
// pushes of a support the balance is often not found within its solves),
// and carried where a held object's push needs its momentum (the run again
// from its start: simulate.cpp) (docs/scene.md, "What decides inertia").
enum class InertiaModel { kCarried, kQuasiStatic, kAuto };

struct Pose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // m
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();       // rad, about fixed x, y, z
};

struct ObjectSpec {
  ObjectShape shape = ObjectShape::kBox;
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // box: full extents (m)
  double radius = 0;                               // cylinder (m)
  double height = 0;                               // cylinder, prism (m), along object z
  std::vector<Eigen::Vector2d> polygon;            // prism: simple, counter-clockwise (m)
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

// A recorded pusher path (JSON: "motion": {"path": {"t": [...], "position":
// [...], "rpy": [...]}}): the pusher's reference point (its `position` at
// t = 0) at times t, in the scene frame, linear between samples and at rest
// after the last one. t[0] = 0 and t strictly increases; position[0] is the
// pusher's position. rpy, when given (same length), is the pusher's
// orientation in the scene frame: the pusher turns about its reference point
// by R(rpy(t)) R(rpy[0])ᵀ (its normal and axis turn with it), interpolated
// along the shortest rotation between samples.
struct PusherPath {
  std::vector<double> t;                  // s
  std::vector<Eigen::Vector3d> position;  // m, scene frame
  std::vector<Eigen::Vector3d> rpy;       // rad; empty: the pusher does not turn
};

struct PusherSpec : ContactSpec {
  PusherMotion motion;
  // Set: the pusher follows this path; `motion` is then unused (zero).
  std::optional<PusherPath> path;
  // Set: closed loop; `motion` is then the command before the first answer
  // (zero) and the controller's commands replace it step by step.
  std::optional<PusherController> controller;
};

// A support (JSON "support"): a flat surface perpendicular to gravity that
// the object rests on, touching the object's face that faces along gravity
// at the start pose. Its normal load is the object's weight m|g|, spread
// over that face by the pressure distribution, and its friction (mu) is
// Coulomb friction integrated over it: the limit surface. Gravity must be
// non-zero and the face one of the object's z caps (a box's, cylinder's or
// prism's top or bottom).
struct SupportSpec {
  double mu = 0;  // support friction coefficient, >= 0
  // Empty: uniform pressure over the face. Otherwise weighted points
  // (x, y, w): x, y in the object frame (m) on the face, w >= 0 (the
  // model normalises them; their weighted centre lies under the centre of
  // mass).
  std::vector<Eigen::Vector3d> pressure_points;
};

struct ModelOptions {
  int facets = 8;     // edges of the inscribed polyhedral friction cone, >= 3
  int points = 3;     // constituent points per line (patch)
  double dt = 0.004;  // time step (s)
  Reduce reduce = Reduce::kAuto;
  ContactTracking contacts = ContactTracking::kTracked;
  PadModel pads = PadModel::kElastic;
  ConeModel cone = ConeModel::kAligned;
  InertiaModel inertia = InertiaModel::kAuto;
};

// How the fingers move along their closing directions (JSON "gripper":
// {"coupling": ...}; absent = independent, the meaning every scene had
// before the field existed). kIndependent: each finger a force-controlled
// pad that follows the object along its normal on its own, so the grasp
// moves with the object along the grip axis. kParallelJaw: two opposed
// fingers on one mechanism (a parallel-jaw gripper): they close and open
// symmetrically about a centre fixed in the hand, so the grasp holds the
// object's position along the grip axis (the jaw takes any net force there)
// while the grip force squeezes.
enum class GripperCoupling { kIndependent, kParallelJaw };

struct GripperSpec {
  GripperCoupling coupling = GripperCoupling::kIndependent;
};

struct Scene {
  ObjectSpec object;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();  // m/s^2; zero = no gravity rows
  double duration = 1.0;                              // s
  double grip_force = 0;                              // N per finger (sum over constituents)
  std::vector<ContactSpec> fingers;  // may be empty when a support holds the object
  std::optional<PusherSpec> pusher;
  std::optional<SupportSpec> support;
  ModelOptions model;
  GripperSpec gripper;
};

const char* ToString(ContactType type);
const char* ToString(Reduce reduce);
const char* ToString(ContactTracking tracking);
const char* ToString(GripperCoupling coupling);
const char* ToString(PadModel pads);
const char* ToString(ConeModel cone);
const char* ToString(InertiaModel inertia);
// The inertia model a scene's steps use: its model.inertia with kAuto
// decided (kQuasiStatic when fingers hold the object and no support
// carries it, else kCarried); never kAuto.
InertiaModel InertiaOf(const Scene& scene);

}  // namespace arena::mechanics
