// Frame math, once (docs/scene.md): the tangent basis of a contact and the
// roll-pitch-yaw convention of every pose in a scene. Every room that turns a
// normal into a basis or an rpy into a rotation (and back) calls these.
#pragma once

#include <Eigen/Core>

namespace arena::mechanics {

// docs/scene.md tangent basis: t1 is the normalised projection onto the contact
// plane of the first of the gripper's z, y, x axes with |n·axis| < 0.9.
Eigen::Vector3d FirstTangent(const Eigen::Vector3d& normal);

// Rotation of roll-pitch-yaw about fixed x, y, z: Rz(yaw) Ry(pitch) Rx(roll).
Eigen::Matrix3d RotationFromRpy(const Eigen::Vector3d& rpy);

// The roll-pitch-yaw of a rotation matrix (the inverse of RotationFromRpy;
// pitch in [-pi/2, pi/2]).
Eigen::Vector3d RpyFromRotation(const Eigen::Matrix3d& R);

}  // namespace arena::mechanics
