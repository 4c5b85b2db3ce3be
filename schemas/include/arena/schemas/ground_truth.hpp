// GroundTruth samples: mechanics::TrajectorySample (the true state) plus what
// the sensors saw, to and from the DDS message (schemas/arena.idl). One place
// for both directions so the cell (executors) and the service (orchestrator)
// can never disagree on the layout.
//
// Layout of msg::GroundTruthSample (gripper frame, SI units):
//   object_pose   x y z qw qx qy qz        object_twist  vx vy vz wx wy wz
//   pusher_pose   contact point + orientation; pusher_twist as actuated
//   pusher_force  true force of the pusher on the object
//   contacts      fingers in scene order, then the pusher (normal force,
//                 tangential force, torque about the contact, mode)
//   observed_*    motion-capture pose and F/T readings taken at observed_t
//                 (= t - latency); observed_valid false = the sample was dropped
//                 by the sensors (observed fields are then zero).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arena/mechanics/simulate.hpp"

namespace arena::msg {
class GroundTruthSample;
class GroundTruth;
}  // namespace arena::msg

namespace arena::dds {

using Wrench = Eigen::Matrix<double, 6, 1>;  // force (N), torque (N m)

// The truth of a measured trial whose contact forces were not measured (or
// failed their import check), as the cell states it in its EXECUTE status
// ("truth") and the store keeps it (trials.truth): its samples carry no
// contacts; its poses are scored, its forces never. Beside the kinds of
// CellAnnounce.truth ("measured" has its forces).
inline constexpr const char* kTruthMeasuredNoForces = "measured:no-forces";

// The pusher's true pose and twist (the mechanics sample has its position only).
struct PusherState {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // m
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();          // m/s
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s
};

// What the sensors reported for one sample.
struct Observation {
  bool valid = false;                                  // false = dropped
  double t = 0;                                        // s, when it was taken
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // object (m)
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  Wrench pusher_wrench = Wrench::Zero();  // pusher F/T sensor
  std::vector<Wrench> finger_wrenches;    // scene order
};

inline constexpr int kMaxContacts = 16;
inline constexpr int kMaxObservedFingers = 10;  // sequence<double, 64> / 6

// @pre truth.contacts.size() <= kMaxContacts,
//      observed.finger_wrenches.size() <= kMaxObservedFingers.
void EncodeSample(const mechanics::TrajectorySample& truth, const PusherState& pusher,
                  const Observation& observed, msg::GroundTruthSample* out);

// Decodes a sample that passed CheckSample(); pusher/observed may be null.
mechanics::TrajectorySample DecodeSample(const msg::GroundTruthSample& in,
                                         PusherState* pusher = nullptr,
                                         Observation* observed = nullptr);

// "" when the sample is well formed (finite numbers, unit quaternions within
// 1e-6, bounded counts, finger wrenches a multiple of 6); otherwise the first
// offending field and why ("samples[].object_pose[3]: not finite").
std::string CheckSample(const msg::GroundTruthSample& sample);

// "" when the batch is well formed and continues a stream whose next expected
// sample index is next_sample; otherwise the reason.
std::string CheckBatch(const msg::GroundTruth& batch, std::uint32_t next_sample);

}  // namespace arena::dds
