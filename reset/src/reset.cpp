#include "arena/reset/reset.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "arena/reset/rng.hpp"

namespace arena::reset {
namespace {

bool Inside(const Eigen::Vector3d& p, const ResetParams& params) {
  return (p.array() >= params.workspace_min.array()).all() &&
         (p.array() <= params.workspace_max.array()).all();
}

Eigen::Quaterniond Perturb(const Eigen::Quaterniond& q, Rng* rng, double std_dev) {
  const Eigen::Vector3d w(rng->Normal(std_dev), rng->Normal(std_dev), rng->Normal(std_dev));
  const double angle = w.norm();
  if (angle == 0.0) return q;
  return (q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle))).normalized();
}

std::string Vec(const Eigen::Vector3d& v) {
  std::ostringstream out;
  out.precision(4);
  out << "(" << v.x() << ", " << v.y() << ", " << v.z() << ")";
  return out.str();
}

// The stream of placements a reset aimed at one trial draws (reset.hpp):
// twelve normal draws per placement in a fixed order, keyed by the prepared
// trial's seed alone.
class PlacementDraws {
 public:
  PlacementDraws(const Pose& target, const ResetParams& params, std::uint64_t trial_seed)
      : target_(target), params_(params), rng_(trial_seed, 0, StreamPurpose::kPlacement) {}

  Placement Next() {
    Placement p;
    p.true_pose.position =
        target_.position + Eigen::Vector3d(rng_.Normal(params_.placement_position_std),
                                           rng_.Normal(params_.placement_position_std),
                                           rng_.Normal(params_.placement_position_std));
    p.true_pose.orientation = Perturb(target_.orientation, &rng_, params_.placement_angle_std);
    p.observed.position =
        p.true_pose.position + Eigen::Vector3d(rng_.Normal(params_.sensing_position_std),
                                               rng_.Normal(params_.sensing_position_std),
                                               rng_.Normal(params_.sensing_position_std));
    p.observed.orientation = Perturb(p.true_pose.orientation, &rng_, params_.sensing_angle_std);
    p.position_error = (p.observed.position - target_.position).norm();
    p.angle_error = AngleBetween(p.observed.orientation, target_.orientation);
    p.verified =
        p.position_error <= params_.position_tolerance && p.angle_error <= params_.angle_tolerance;
    p.placements = ++drawn_;
    return p;
  }

 private:
  Pose target_;
  ResetParams params_;
  Rng rng_;
  int drawn_ = 0;
};

}  // namespace

Placement PlacementForTrial(const Pose& target, const ResetParams& params,
                            std::uint64_t trial_seed) {
  PlacementDraws draws(target, params, trial_seed);
  Placement p;
  for (int k = 0; k < params.max_attempts; ++k) {
    p = draws.Next();
    if (p.verified) break;
  }
  return p;
}

const char* ToString(PrimitiveKind kind) {
  switch (kind) {
    case PrimitiveKind::kSwapPusher:
      return "swap_pusher";
    case PrimitiveKind::kMovePusher:
      return "move_pusher";
    case PrimitiveKind::kRelease:
      return "release";
    case PrimitiveKind::kRotate:
      return "rotate_in_grasp";
    case PrimitiveKind::kTranslate:
      return "pick_and_place";
    case PrimitiveKind::kRegrasp:
      return "regrasp";
  }
  return "?";
}

double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.normalized().angularDistance(b.normalized());
}

void ValidateResetParams(const ResetParams& p) {
  auto fail = [](const std::string& field, const std::string& why) {
    throw std::invalid_argument("reset." + field + ": " + why);
  };
  auto positive = [&](double v, const char* field) {
    if (!std::isfinite(v) || v <= 0) fail(field, "must be finite and > 0");
  };
  auto nonneg = [&](double v, const char* field) {
    if (!std::isfinite(v) || v < 0) fail(field, "must be finite and >= 0");
  };
  positive(p.position_tolerance, "position_tolerance");
  positive(p.angle_tolerance, "angle_tolerance");
  if (p.max_attempts < 1 || p.max_attempts > 100) fail("max_attempts", "must be 1..100");
  if (!(p.failure_probability >= 0 && p.failure_probability <= 1)) {
    fail("failure_probability", "must be in [0, 1]");
  }
  nonneg(p.placement_position_std, "placement_position_std");
  nonneg(p.placement_angle_std, "placement_angle_std");
  nonneg(p.sensing_position_std, "sensing_position_std");
  nonneg(p.sensing_angle_std, "sensing_angle_std");
  positive(p.translate_speed, "translate_speed");
  positive(p.rotate_speed, "rotate_speed");
  nonneg(p.grasp_time, "grasp_time");
  nonneg(p.swap_time, "swap_time");
  if (!p.workspace_min.allFinite() || !p.workspace_max.allFinite() ||
      !(p.workspace_min.array() < p.workspace_max.array()).all()) {
    fail("workspace", "min must be finite and below max on every axis");
  }
}

std::vector<Primitive> PlanReset(const Pose& observed, const Pose& target, bool swap_pusher,
                                 const ResetParams& params, double pusher_move_m) {
  std::vector<Primitive> plan;
  if (swap_pusher) {
    plan.push_back({PrimitiveKind::kSwapPusher, observed, params.swap_time});
  } else if (pusher_move_m > 0) {
    plan.push_back({PrimitiveKind::kMovePusher, observed, pusher_move_m / params.translate_speed});
  }
  const double angle = AngleBetween(observed.orientation, target.orientation);
  const double distance = (target.position - observed.position).norm();
  const bool rotate = angle > params.angle_tolerance;
  const bool translate = distance > params.position_tolerance;
  if (!rotate && !translate) return plan;
  plan.push_back({PrimitiveKind::kRelease, observed, params.grasp_time});
  Pose current = observed;
  if (rotate) {
    current.orientation = target.orientation;
    plan.push_back(
        {PrimitiveKind::kRotate, current, params.grasp_time + angle / params.rotate_speed});
  }
  if (translate) {
    current.position = target.position;
    plan.push_back({PrimitiveKind::kTranslate, current,
                    params.grasp_time + distance / params.translate_speed});
  }
  plan.push_back({PrimitiveKind::kRegrasp, target, params.grasp_time});
  return plan;
}

ResetOutcome ExecuteReset(const ResetRequest& request, const ResetParams& params,
                          std::uint64_t seed, std::uint64_t trial_id) {
  Rng slips(seed, trial_id, StreamPurpose::kReset);
  PlacementDraws placements(request.target, params, seed);
  ResetOutcome out;
  out.final_true = request.true_end;
  out.final_observed = request.observed_end;
  if (!Inside(request.true_end.position, params)) {
    out.failure = "object left the workspace: at " + Vec(request.true_end.position) +
                  " m, workspace " + Vec(params.workspace_min) + ".." + Vec(params.workspace_max);
    out.retryable = false;
    return out;
  }
  if (!Inside(request.target.position, params)) {
    out.failure = "target pose " + Vec(request.target.position) + " m is outside the workspace";
    out.retryable = false;
    return out;
  }
  Pose observed = request.observed_end;
  bool swap = request.swap_pusher;
  double move = swap ? 0.0 : request.pusher_move_m;
  for (int attempt = 1; attempt <= params.max_attempts; ++attempt) {
    out.attempts = attempt;
    out.plan = PlanReset(observed, request.target, swap, params, move);
    // Two draws per attempt whatever the plan, so that one outcome does not
    // shift the stream of the others.
    const double slip = slips.Uniform();
    const std::uint64_t slip_draw = slips.Next();
    if (slip < params.failure_probability && !out.plan.empty()) {
      // The object slipped during one primitive: time up to and including it
      // is spent, the object stays where it was (observed again as before).
      const size_t slip_at = static_cast<size_t>(slip_draw % out.plan.size());
      for (size_t i = 0; i <= slip_at; ++i) out.time_s += out.plan[i].duration_s;
      if (slip_at > 0) {  // the pusher's swap or move (always first) was completed
        swap = false;
        move = 0;
      }
      out.failure = std::string("object slipped during ") + ToString(out.plan[slip_at].kind) +
                    " (attempt " + std::to_string(attempt) + ")";
      continue;
    }
    for (const auto& p : out.plan) out.time_s += p.duration_s;
    swap = false;
    move = 0;
    // The prepared trial's next placement (also with an empty plan: reset.hpp).
    const Placement placed = placements.Next();
    observed = placed.observed;
    out.final_true = placed.true_pose;
    out.final_observed = placed.observed;
    out.position_error = placed.position_error;
    out.angle_error = placed.angle_error;
    if (placed.verified) {
      out.success = true;
      out.failure.clear();
      return out;
    }
    std::ostringstream why;
    why << "verification failed: position error " << out.position_error << " m, angle error "
        << out.angle_error << " rad (attempt " << attempt << ")";
    out.failure = why.str();
  }
  out.failure = "reset failed after " + std::to_string(out.attempts) + " attempts: " + out.failure;
  return out;
}

}  // namespace arena::reset
