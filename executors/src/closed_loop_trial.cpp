#include "closed_loop_trial.hpp"

#include <algorithm>
#include <cmath>

#include "arena/executors/defects.hpp"
#include "clock.hpp"
#include "defects_json.hpp"

namespace arena::executors {
namespace {

using nlohmann::json;

using internal::UnixNanos;

using internal::Seconds;

}  // namespace

ClosedLoopTrial::ClosedLoopTrial(const StreamPort& port, dds::Reader<msg::PusherCommand>& commands,
                                 const DefectLayer& layer, const msg::TrialCommand& command,
                                 const TrialContext& trial, const mechanics::Scene& scene)
    : port_(port),
      commands_(commands),
      layer_(layer),
      command_(command),
      trial_(trial),
      context_(MakeControlContext(scene, layer.cell_profile().max_pusher_speed)),
      params_(ControlContextToJson(context_)),
      expected_samples_(
          static_cast<std::size_t>(std::floor(scene.duration * mechanics::kSampleRateHz + 1e-9)) +
          1) {}

void ClosedLoopTrial::Start() {
  start_ = StreamClock::now();
  last_command_at_ = start_;
  commands_.TakeAll();  // answers to earlier trials
}

double ClosedLoopTrial::HoldLimit() const {
  return answered_ ? context_.spec.hold_s : std::max(context_.spec.hold_s, kFirstAnswerWait_s);
}

std::optional<msg::PusherCommand> ClosedLoopTrial::Await(std::uint32_t k, bool exact,
                                                         StreamClock::time_point until) {
  std::optional<msg::PusherCommand> newest;
  for (;;) {
    const auto now = StreamClock::now();
    const auto wait = until > now
                          ? std::chrono::duration_cast<std::chrono::nanoseconds>(until - now)
                          : std::chrono::nanoseconds(0);
    auto m = commands_.Take(wait);
    if (m && m->cell_id() == port_.cell_id && m->trial_id() == command_.trial_id() &&
        m->attempt() == command_.attempt() && m->controller() == context_.spec.name &&
        m->answers_sample() <= k) {
      if (!newest || m->answers_sample() >= newest->answers_sample()) newest = std::move(*m);
      if (exact && newest->answers_sample() == k) return newest;
    }
    if (StreamClock::now() >= until || port_.stopping()) return exact ? std::nullopt : newest;
  }
}

std::optional<msg::PusherCommand> ClosedLoopTrial::Answer(std::uint32_t k, double t,
                                                          const msg::GroundTruthSample& encoded,
                                                          bool last) {
  PublishLive(port_, command_, k, last, encoded, context_.spec.name, params_);
  if (port_.speed == 0) {
    // Best-effort loses messages (a controller that matched a moment late
    // misses sample 0): without an answer the sample is published again
    // every 20 ms until the hold time runs out.
    const auto give_up = StreamClock::now() + Seconds(HoldLimit());
    for (;;) {
      auto answer =
          Await(k, true, std::min(give_up, StreamClock::now() + std::chrono::milliseconds(20)));
      if (answer || StreamClock::now() >= give_up || port_.stopping()) return answer;
      PublishLive(port_, command_, k, last, encoded, context_.spec.name, params_);
    }
  }
  // Collect until the next sample is due; the newest answer wins.
  return Await(k, false, start_ + Seconds((t + 1.0 / mechanics::kSampleRateHz) * port_.speed));
}

std::optional<mechanics::PusherMotion> ClosedLoopTrial::Next(
    const std::vector<mechanics::TrajectorySample>& samples, std::string* why) {
  const auto k = static_cast<std::uint32_t>(samples.size() - 1);
  const mechanics::TrajectorySample& truth = samples.back();
  const auto& spec = context_.spec;
  if (port_.stopping()) {
    *why = "interrupted: cell shutting down";
    return Stopped(msg::FAILURE_INTERRUPTED);
  }
  if (StreamClock::now() > trial_.deadline) {
    *why = "deadline: " + std::to_string(command_.deadline_s()) + " s exceeded after " +
           std::to_string(k + 1) + " samples";
    return Stopped(msg::FAILURE_DEADLINE);
  }
  // What the sensors saw of this sample (latency, drops, noise: the same
  // streams as the log's, so live and log agree), one sample at a time.
  if (!observer_) observer_.emplace(layer_.MakeObserver(trial_));
  observed_.push_back(observer_->Next(samples));
  dds::PusherState pusher = PusherAt(layer_.actual_scene(), truth);  // its pose
  pusher.velocity = in_force_.velocity;  // the command that moved it to this sample
  pusher.angular_velocity = in_force_.angular_velocity;
  pushers_.push_back(pusher);
  msg::GroundTruthSample encoded;
  dds::EncodeSample(truth, pusher, observed_.back(), &encoded);
  if (port_.speed > 0 && !port_.sleep_until(start_ + Seconds(truth.t * port_.speed))) {
    *why = "interrupted: cell shutting down";
    return Stopped(msg::FAILURE_INTERRUPTED);
  }
  const std::optional<msg::PusherCommand> answer =
      Answer(k, truth.t, encoded, k + 1 == expected_samples_);
  AppliedCommand record;
  record.sample = k;
  record.t = truth.t;
  if (answer) return Apply(*answer, record, why);
  if (StreamClock::now() - last_command_at_ > Seconds(HoldLimit())) {
    *why = answered_
               ? "controller " + spec.name + ": no command for " + std::to_string(spec.hold_s) +
                     " s (hold time) after sample " + std::to_string(k) + "; pusher stopped"
               : "controller " + spec.name + ": no answer to the first sample within " +
                     std::to_string(HoldLimit()) + " s of the trial's start (sample " +
                     std::to_string(k) + "); pusher stopped";
    return Stop(record);
  }
  record.commanded = applied_.empty() ? Eigen::Vector3d::Zero() : applied_.back().commanded;
  record.applied = in_force_.velocity;
  applied_.push_back(record);
  return in_force_;
}

std::optional<mechanics::PusherMotion> ClosedLoopTrial::Apply(const msg::PusherCommand& answer,
                                                              AppliedCommand record,
                                                              std::string* why) {
  const auto& spec = context_.spec;
  const std::uint32_t k = record.sample;
  record.loop_ms = (UnixNanos() - answer.state_sent_unix_ns()) * 1e-6;
  if (answer.answers_sample() != k) record.loop_ms = -1;  // an older sample's answer
  const Eigen::Vector3d v(answer.velocity()[0], answer.velocity()[1], answer.velocity()[2]);
  const Eigen::Vector3d w(answer.angular_velocity()[0], answer.angular_velocity()[1],
                          answer.angular_velocity()[2]);
  if (!v.allFinite() || !w.allFinite()) {
    *why = "controller " + spec.name + ": command answering sample " + std::to_string(k) +
           " is not finite; pusher stopped";
    return Stop(record);
  }
  const double max_speed = layer_.cell_profile().max_pusher_speed;
  if (v.norm() > max_speed * (1 + 1e-9)) {
    *why = "controller " + spec.name + ": commanded " + std::to_string(v.norm()) +
           " m/s at sample " + std::to_string(k) + ", above this cell's " +
           std::to_string(max_speed) + " m/s; pusher stopped";
    return Stop(record);
  }
  record.commanded = v;
  // Actuation noise (defects.hpp) on a moving pusher: v (1 + s) + o.
  const TrialPerturbation& perturbation = layer_.perturbation();
  in_force_.velocity =
      v.norm() > 0 ? Eigen::Vector3d(v * perturbation.velocity_scale + perturbation.velocity_offset)
                   : Eigen::Vector3d::Zero();
  in_force_.angular_velocity = w;
  last_command_at_ = StreamClock::now();
  answered_ = true;
  record.applied = in_force_.velocity;
  applied_.push_back(record);
  return in_force_;
}

// Every Stop is the controller's doing: gone, silent past its hold time, a bad command.
std::optional<mechanics::PusherMotion> ClosedLoopTrial::Stop(AppliedCommand record) {
  in_force_.velocity.setZero();
  record.applied.setZero();
  applied_.push_back(record);
  return Stopped(msg::FAILURE_CONTROLLER);
}

std::optional<mechanics::PusherMotion> ClosedLoopTrial::Stopped(msg::FailureKind kind) {
  stop_kind_ = kind;
  return std::nullopt;
}

json ClosedLoopTrial::Detail(const mechanics::SimulationResult& result,
                             std::uint32_t log_batches) const {
  json commands = json::array();
  std::vector<double> loop_ms;
  std::size_t held = 0;
  for (const auto& a : applied_) {
    commands.push_back({a.sample, a.t, a.commanded.x(), a.commanded.y(), a.commanded.z(),
                        a.applied.x(), a.applied.y(), a.applied.z(), a.loop_ms});
    if (a.loop_ms >= 0)
      loop_ms.push_back(a.loop_ms);
    else
      ++held;
  }
  std::sort(loop_ms.begin(), loop_ms.end());
  auto pct = [&](double q) {
    return loop_ms.empty() ? json(nullptr)
                           : json(loop_ms[static_cast<size_t>(q * (loop_ms.size() - 1))]);
  };
  const ControlOutcome outcome = ScoreControl(context_.spec.name, context_, result.samples);
  json score = nullptr;
  if (outcome.scored) {
    score = {
        {"reached", outcome.reached},
        {"final_error", outcome.final_error},
        {"settle_time_s", outcome.settle_time_s < 0 ? json(nullptr) : json(outcome.settle_time_s)}};
  }
  const TrialPerturbation& perturbation = layer_.perturbation();
  json detail = {
      {"mu_scale", perturbation.mu_scale},
      {"velocity_scale", perturbation.velocity_scale},
      {"velocity_offset",
       {perturbation.velocity_offset.x(), perturbation.velocity_offset.y(),
        perturbation.velocity_offset.z()}},
      {"batches", log_batches},
      {"backend", layer_.capabilities().name},
      {"truth", ToString(layer_.capabilities().truth)},
      {"defects_applied", internal::AppliedDefectsTree(layer_)},
      {"model",
       {{"dof", result.model.dof},
        {"facets", result.model.facets},
        {"points", result.model.points},
        {"dt", result.model.dt},
        {"unknowns", result.model.unknowns}}},
      {"solver", json::parse(mechanics::SolverStatisticsJson(result.solver))},
      {"simulate_wall_s", result.wall_s},
      {"closed_loop",
       {{"controller", context_.spec.name},
        {"lockstep", port_.speed == 0},
        {"context", json::parse(params_)},
        {"commands_columns",
         {"sample", "t", "vx", "vy", "vz", "applied_vx", "applied_vy", "applied_vz", "loop_ms"}},
        {"commands", commands},
        {"held", held},
        {"loop_ms", {{"p50", pct(0.5)}, {"p99", pct(0.99)}, {"max", pct(1.0)}}},
        {"outcome", score}}}};
  // The truth's final pose is one phase of a swing when it ends in one, and
  // its start an impact dt did not resolve when it was one: said.
  detail.update(json::parse(mechanics::RunFlagsJson(result)));
  return detail;
}

}  // namespace arena::executors
