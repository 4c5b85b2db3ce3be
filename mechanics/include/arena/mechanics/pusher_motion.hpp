// Where a pusher is at time t: its constant motion or its recorded path
// (scene.hpp, PusherPath). One function for every predictor, so that the
// model and the MuJoCo backend drive the pusher along the same path.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arena/mechanics/scene.hpp"

namespace arena::mechanics {

struct PusherPose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();      // the reference point (m, scene frame)
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // from the pose at t = 0
  bool turned = false;  // rotation is not the identity (a constant-rate turn or a path's rpy)
};

// The pusher's pose at time t >= 0: position + velocity t and the turn
// |ω| t about ω for a constant motion (bit for bit what the model always
// computed); a path's position interpolated linearly between samples (held
// after the last), its rotation R(rpy(t)) R(rpy[0])ᵀ along the shortest
// rotation between samples.
PusherPose PusherPoseAt(const PusherSpec& pusher, double t);

// The pusher's mean velocity over [t, t + dt] (m/s) and its mean angular
// velocity (rad/s, scene frame): what a step of length dt moves it by.
struct PusherTwist {
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();
};
PusherTwist PusherTwistOver(const PusherSpec& pusher, double t, double dt);

// The largest speed the pusher reaches (m/s) and turning rate (rad/s): for
// force scales and planarity.
PusherTwist PusherPeakRates(const PusherSpec& pusher);

}  // namespace arena::mechanics
