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

}  // namespace

const char* ToString(PrimitiveKind kind) {
  switch (kind) {
    case PrimitiveKind::kSwapPusher:
      return "swap_pusher";
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
                                 const ResetParams& params) {
  std::vector<Primitive> plan;
  if (swap_pusher) plan.push_back({PrimitiveKind::kSwapPusher, observed, params.swap_time});
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
  Rng rng(seed, trial_id, StreamPurpose::kReset);
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
  Pose actual = request.true_end;
  bool swap = request.swap_pusher;
  for (int attempt = 1; attempt <= params.max_attempts; ++attempt) {
    out.attempts = attempt;
    out.plan = PlanReset(observed, request.target, swap, params);
    // Draw every random number of the attempt in a fixed order so that one
    // outcome does not shift the streams of the others.
    const double slip = rng.Uniform();
    const size_t slip_at = out.plan.empty() ? 0 : static_cast<size_t>(rng.Next() % out.plan.size());
    Pose placed;
    placed.position =
        request.target.position + Eigen::Vector3d(rng.Normal(params.placement_position_std),
                                                  rng.Normal(params.placement_position_std),
                                                  rng.Normal(params.placement_position_std));
    placed.orientation = Perturb(request.target.orientation, &rng, params.placement_angle_std);
    Pose seen;
    const Eigen::Vector3d sensing(rng.Normal(params.sensing_position_std),
                                  rng.Normal(params.sensing_position_std),
                                  rng.Normal(params.sensing_position_std));

    if (slip < params.failure_probability && !out.plan.empty()) {
      // The object slipped during one primitive: time up to and including it
      // is spent, the object stays where it was (observed again as before).
      for (size_t i = 0; i <= slip_at; ++i) out.time_s += out.plan[i].duration_s;
      if (swap && slip_at > 0) swap = false;  // the swap (always first) was completed
      out.failure = std::string("object slipped during ") + ToString(out.plan[slip_at].kind) +
                    " (attempt " + std::to_string(attempt) + ")";
      continue;
    }
    for (const auto& p : out.plan) out.time_s += p.duration_s;
    swap = false;
    if (!out.plan.empty()) actual = placed;
    seen.position = actual.position + sensing;
    seen.orientation = Perturb(actual.orientation, &rng, params.sensing_angle_std);
    observed = seen;
    out.final_true = actual;
    out.final_observed = seen;
    out.position_error = (seen.position - request.target.position).norm();
    out.angle_error = AngleBetween(seen.orientation, request.target.orientation);
    if (out.position_error <= params.position_tolerance &&
        out.angle_error <= params.angle_tolerance) {
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
