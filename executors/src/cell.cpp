#include "arena/executors/cell.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <tuple>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/executors/controller.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/reset/reset.hpp"
#include "arena/schemas/arena.h"
#include "arena/schemas/ground_truth.hpp"

namespace arena::executors {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

std::uint64_t UnixNanos() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

reset::Pose ToResetPose(const mechanics::Pose& p) {
  reset::Pose out;
  out.position = p.position;
  out.orientation = Eigen::AngleAxisd(p.rpy.z(), Eigen::Vector3d::UnitZ()) *
                    Eigen::AngleAxisd(p.rpy.y(), Eigen::Vector3d::UnitY()) *
                    Eigen::AngleAxisd(p.rpy.x(), Eigen::Vector3d::UnitX());
  return out;
}

bool SamePusher(const std::optional<mechanics::PusherSpec>& a,
                const std::optional<mechanics::PusherSpec>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  return a->type == b->type && a->length == b->length && a->radius == b->radius &&
         a->axis == b->axis && a->normal == b->normal && a->position == b->position;
}

std::string ModeName(mechanics::SimulationStatus s) {
  switch (s) {
    case mechanics::SimulationStatus::kOk:
      return "ok";
    case mechanics::SimulationStatus::kSolverFailure:
      return "solver failure";
    case mechanics::SimulationStatus::kInvalidScene:
      return "invalid scene";
  }
  return "?";
}

}  // namespace

void ValidateCellOptions(const CellOptions& o) {
  if (o.id.empty() || o.id.size() > 64)
    throw std::invalid_argument("--id: must be 1..64 characters");
  for (char c : o.id) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) {
      throw std::invalid_argument("--id: only letters, digits, '_', '-' and '.' are allowed");
    }
  }
  if (!std::isfinite(o.speed) || o.speed < 0 || o.speed > 1000) {
    throw std::invalid_argument(
        "--speed: must be in [0, 1000] (0 = as fast as possible, 1 = wall clock)");
  }
  if (o.batch_samples < 1 || o.batch_samples > 256) {
    throw std::invalid_argument("--batch: must be 1..256 samples");
  }
  if (o.fidelity.facets < 3 || o.fidelity.points < 1 || !(o.fidelity.dt > 0)) {
    throw std::invalid_argument("fidelity: facets >= 3, points >= 1, dt > 0");
  }
  ValidateDefectProfile(o.defects);
}

struct Cell::Impl {
  CellOptions options;
  MechanicsBackend mechanics;
  reset::ResetParams reset_params;
  dds::Participant participant;
  dds::Writer<msg::CellAnnounce> announce;
  dds::Writer<msg::TrialStatus> status;
  dds::Writer<msg::GroundTruth> ground_truth;
  dds::Reader<msg::TrialCommand> commands;
  dds::Writer<msg::LiveState> live;                 // one message per sample, best-effort
  dds::Reader<msg::PusherCommand> pusher_commands;  // closed loop: the controllers' answers

  std::mutex mutex;
  std::condition_variable wake;
  bool stop = false;
  bool finished = false;
  CellCounters counters;

  // Worker-only state.
  // Phases already finished, to answer a repeated command with its status
  // instead of running it twice. Keyed by the service's session too: trial
  // ids restart at 1 in a new store, and a cell outlives stores and services.
  // Only the latest kRemembered are kept, so months of trials cost no memory.
  using Key = std::tuple<std::uint64_t, std::uint64_t, std::uint32_t,
                         int>;  // session, trial, attempt, phase
  static constexpr std::size_t kRemembered = 1024;
  std::map<Key, msg::TrialStatus> done;
  std::deque<Key> done_order;                   // oldest first
  reset::Pose true_pose;                        // where the object really is now
  reset::Pose observed_pose;                    // where the sensors saw it last
  std::optional<mechanics::PusherSpec> pusher;  // the pusher mounted now
  std::thread worker;

  static dds::ParticipantOptions ParticipantFor(const CellOptions& o) {
    ValidateCellOptions(o);
    dds::ParticipantOptions p;
    p.domain_id = o.domain_id;
    p.name = dds::CellParticipantName(o.id);
    p.network = o.network;
    p.lease_s = o.participant_lease_s;
    return p;
  }

  Impl(const CellOptions& o, MechanicsBackend m)
      : options(o),
        mechanics(std::move(m)),
        reset_params(EffectiveResetParams(o.defects)),
        participant(ParticipantFor(o)),
        announce(participant),
        status(participant),
        ground_truth(participant),
        commands(participant, dds::ReaderOptions{false}),
        live(participant),
        pusher_commands(participant, dds::ReaderOptions{false, o.id}) {}

  bool Stopping() {
    std::lock_guard<std::mutex> lock(mutex);
    return stop;
  }
  // Sleeps until `until` or Stop(); @returns false when stopping.
  bool SleepUntil(Clock::time_point until) {
    std::unique_lock<std::mutex> lock(mutex);
    return !wake.wait_until(lock, until, [&] { return stop; });
  }

  void Announce() {
    msg::CellAnnounce a;
    a.cell_id(options.id);
    a.arena_version("0.1.0");
    for (auto t : options.defects.contact_types) {
      a.contact_types().push_back(t == mechanics::ContactType::kPoint  ? "point"
                                  : t == mechanics::ContactType::kLine ? "line"
                                                                       : "patch");
    }
    for (int k = 0; k < 3; ++k) {
      a.workspace_min()[k] = options.defects.workspace_min[k];
      a.workspace_max()[k] = options.defects.workspace_max[k];
    }
    a.max_pusher_speed(options.defects.max_pusher_speed);
    a.speed(options.speed);
    a.defects_json(DefectProfileToJson(options.defects));
    a.started_unix_ns(UnixNanos());
    if (!announce.Write(a)) throw dds::DdsError("cell: announcing the cell failed");
  }

  msg::TrialStatus BaseStatus(const msg::TrialCommand& c, msg::TrialState state) {
    msg::TrialStatus s;
    s.trial_id(c.trial_id());
    s.attempt(c.attempt());
    s.cell_id(options.id);
    s.phase(c.phase());
    s.state(state);
    s.observed_pose() = {observed_pose.position.x(),    observed_pose.position.y(),
                         observed_pose.position.z(),    observed_pose.orientation.w(),
                         observed_pose.orientation.x(), observed_pose.orientation.y(),
                         observed_pose.orientation.z()};
    return s;
  }

  void Send(msg::TrialStatus& s) {
    // A status is small and the history keep-all; retry through a stall.
    for (int i = 0; i < 10 && !status.Write(s); ++i) {
      spdlog::warn("cell {}: status write for trial {} timed out, retrying", options.id,
                   s.trial_id());
    }
  }

  void Finish(const msg::TrialCommand& c, msg::TrialStatus s) {
    Send(s);
    const Key key{c.service_session(), c.trial_id(), c.attempt(), static_cast<int>(c.phase())};
    if (done.insert_or_assign(key, s).second) done_order.push_back(key);
    while (done_order.size() > kRemembered) {
      done.erase(done_order.front());
      done_order.pop_front();
    }
    std::lock_guard<std::mutex> lock(mutex);
    switch (s.state()) {
      case msg::STATE_EXECUTED:
        ++counters.executed;
        break;
      case msg::STATE_RESET_DONE:
        ++counters.resets;
        break;
      case msg::STATE_REFUSED:
        ++counters.refused;
        break;
      default:
        ++counters.failed;
        break;
    }
  }

  void Refuse(const msg::TrialCommand& c, const std::string& reason) {
    spdlog::info("cell {}: refused trial {} attempt {}: {}", options.id, c.trial_id(), c.attempt(),
                 reason);
    auto s = BaseStatus(c, msg::STATE_REFUSED);
    s.reason(reason);
    Finish(c, s);
  }

  void Handle(const msg::TrialCommand& c) {
    const Key key{c.service_session(), c.trial_id(), c.attempt(), static_cast<int>(c.phase())};
    if (auto it = done.find(key); it != done.end()) {
      spdlog::info("cell {}: trial {} attempt {} already finished; re-sending its status",
                   options.id, c.trial_id(), c.attempt());
      msg::TrialStatus s = it->second;
      Send(s);
      std::lock_guard<std::mutex> lock(mutex);
      ++counters.duplicates;
      return;
    }
    if (c.phase() == msg::PHASE_EXECUTE)
      Execute(c);
    else if (c.phase() == msg::PHASE_RESET)
      Reset(c);
    else
      Refuse(c, "phase: unknown value");
  }

  void Execute(const msg::TrialCommand& c) {
    const auto started = Clock::now();
    mechanics::Scene scene;
    try {
      scene = mechanics.parse(c.scene_json());
    } catch (const std::exception& e) {
      return Refuse(c, std::string("scene: ") + e.what());
    }
    if (std::string why = CheckCapabilities(options.defects, scene); !why.empty()) {
      return Refuse(c, why);
    }
    if (!std::isfinite(c.deadline_s()) || c.deadline_s() < 0) {
      return Refuse(c, "deadline_s: must be finite and >= 0 (0 = none)");
    }
    auto accepted = BaseStatus(c, msg::STATE_ACCEPTED);
    Send(accepted);
    if (options.defects.hang_after_accept) {  // fault injection: a hung controller
      spdlog::warn("cell {}: fault injection: hanging after accepting trial {}", options.id,
                   c.trial_id());
      SleepUntil(Clock::time_point::max());
      return;
    }
    if (scene.pusher && scene.pusher->controller) return ExecuteClosedLoop(c, scene, started);

    const TrialPerturbation perturbation =
        DrawPerturbation(options.defects, c.seed(), c.trial_id());
    mechanics::Scene actual = ApplyPerturbation(scene, perturbation);
    actual.model.facets = std::max(actual.model.facets, options.fidelity.facets);
    actual.model.points = std::max(actual.model.points, options.fidelity.points);
    actual.model.dt = std::min(actual.model.dt, options.fidelity.dt);
    const mechanics::SimulationResult result = mechanics.simulate(actual);
    if (result.status != mechanics::SimulationStatus::kOk || result.samples.empty()) {
      auto s = BaseStatus(c, msg::STATE_FAILED);
      s.reason("simulation: " + ModeName(result.status) + ": " + result.error);
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    const auto observed = Observe(result.samples, actual, options.defects, c.seed(), c.trial_id());

    // Stream, paced: a batch leaves when its last sample is due; the live
    // topic gets every sample when it is due.
    const auto deadline = DeadlineOf(c, started);
    size_t dropped = 0;
    for (const auto& o : observed) dropped += o.valid ? 0 : 1;
    const StreamOutcome streamed =
        StreamLog(c, result, actual, observed, Clock::now(), deadline, Pacing::kLive);
    const std::string& failure = streamed.failure;
    const size_t n = result.samples.size();
    const std::uint32_t batch_index = streamed.batches;

    const auto& last = result.samples.back();
    true_pose.position = last.position;
    true_pose.orientation = last.orientation;
    // The sensors' last valid view of the end state.
    for (auto it = observed.rbegin(); it != observed.rend(); ++it) {
      if (it->valid) {
        observed_pose.position = it->position;
        observed_pose.orientation = it->orientation;
        break;
      }
    }
    pusher = scene.pusher;

    auto s = BaseStatus(c, failure.empty() ? msg::STATE_EXECUTED : msg::STATE_FAILED);
    s.reason(failure);
    s.samples(static_cast<std::uint32_t>(n));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    json detail = {{"mu_scale", perturbation.mu_scale},
                   {"velocity_scale", perturbation.velocity_scale},
                   {"velocity_offset",
                    {perturbation.velocity_offset.x(), perturbation.velocity_offset.y(),
                     perturbation.velocity_offset.z()}},
                   {"dropped_observations", dropped},
                   {"batches", batch_index},
                   {"model",
                    {{"dof", result.model.dof},
                     {"facets", result.model.facets},
                     {"points", result.model.points},
                     {"dt", result.model.dt},
                     {"unknowns", result.model.unknowns}}},
                   {"residuals",
                    {{"force_balance", result.residuals.force_balance},
                     {"complementarity", result.residuals.complementarity},
                     {"cone", result.residuals.cone}}},
                   {"solver",
                    {{"steps", result.solver.steps},
                     {"max_pivots", result.solver.max_pivots},
                     {"failures", result.solver.failures}}},
                   {"simulate_wall_s", result.wall_s}};
    s.detail_json(detail.dump());
    if (!failure.empty()) {
      spdlog::warn("cell {}: trial {} attempt {} failed: {}", options.id, c.trial_id(), c.attempt(),
                   failure);
    }
    Finish(c, s);
  }

  // How StreamLog (below) sends a trial.
  enum class Pacing {
    kLive,     // samples leave when due (speed > 0), each on the live topic too
    kFlatOut,  // as fast as the log takes them, log only (closed loop: already live)
  };
  struct StreamOutcome {
    std::string failure;  // "" when the whole trial was sent
    std::uint32_t batches = 0;
  };

  // ---------------------------------------------------------------------
  // Closed loop (issue 19): the pusher follows a controller's commands.
  // Each sample goes out on the live topic; the command answering it moves
  // the pusher from the next step on. speed 0: lockstep (the simulation waits
  // for the answer to sample k, at most hold_s, before step k+1); speed > 0:
  // wall clock (the newest command in force when a step is due). Without a
  // new command for hold_s the pusher stops and the phase fails.

  // How long a closed-loop trial waits for its controller to appear.
  static constexpr double kControllerWait_s = 5.0;

  struct AppliedCommand {
    std::uint32_t sample = 0;  // the sample it answered (applied from the next step)
    double t = 0;              // s, that sample's time
    Eigen::Vector3d commanded = Eigen::Vector3d::Zero();  // m/s, as the controller sent it
    Eigen::Vector3d applied = Eigen::Vector3d::Zero();    // m/s, with the actuation noise
    double loop_ms = -1;  // live sample written -> command accepted (wall), -1: held
  };

  struct ClosedLoop {
    const msg::TrialCommand& command;
    const mechanics::Scene& actual;
    const TrialPerturbation& perturbation;
    executors::ControlContext context;
    std::string params;
    Clock::time_point start;
    Clock::time_point deadline;
    std::size_t expected_samples = 0;
    std::vector<AppliedCommand> applied;
    mechanics::PusherMotion in_force;
    Clock::time_point last_command_at;
  };

  // The newest command of this trial answering a sample <= k (lockstep: == k),
  // waiting until `until` at most.
  std::optional<msg::PusherCommand> AwaitCommand(const ClosedLoop& loop, std::uint32_t k,
                                                 bool exact, Clock::time_point until) {
    std::optional<msg::PusherCommand> newest;
    for (;;) {
      const auto now = Clock::now();
      const auto wait =
          until > now ? std::chrono::duration_cast<dds::Millis>(until - now) : dds::Millis(0);
      auto m = pusher_commands.Take(std::max(wait, dds::Millis(exact ? 1 : 0)));
      if (m && m->cell_id() == options.id && m->trial_id() == loop.command.trial_id() &&
          m->attempt() == loop.command.attempt() && m->controller() == loop.context.spec.name &&
          m->answers_sample() <= k) {
        if (!newest || m->answers_sample() >= newest->answers_sample()) newest = std::move(*m);
        if (exact && newest->answers_sample() == k) return newest;
      }
      if (Clock::now() >= until || Stopping()) return exact ? std::nullopt : newest;
    }
  }

  // Called by the simulation after every sample: publish it, get its answer.
  std::optional<mechanics::PusherMotion> NextCommand(
      ClosedLoop& loop, const std::vector<mechanics::TrajectorySample>& samples, std::string* why) {
    const auto k = static_cast<std::uint32_t>(samples.size() - 1);
    const mechanics::TrajectorySample& truth = samples.back();
    const auto& spec = loop.context.spec;
    if (Stopping()) {
      *why = "interrupted: cell shutting down";
      return std::nullopt;
    }
    if (Clock::now() > loop.deadline) {
      *why = "deadline: " + std::to_string(loop.command.deadline_s()) + " s exceeded after " +
             std::to_string(k + 1) + " samples";
      return std::nullopt;
    }
    // What the sensors saw of this sample (latency, drops, noise: the same
    // streams as the log's, so live and log agree).
    const auto observed = Observe(samples, loop.actual, options.defects, loop.command.seed(),
                                  loop.command.trial_id());
    dds::PusherState pusher;
    pusher.position = truth.pusher_position;
    pusher.velocity = loop.in_force.velocity;
    pusher.angular_velocity = loop.in_force.angular_velocity;
    msg::GroundTruthSample encoded;
    dds::EncodeSample(truth, pusher, observed.back(), &encoded);
    const bool lockstep = options.speed == 0;
    if (!lockstep) {
      const auto due = loop.start + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(truth.t * options.speed));
      if (!SleepUntil(due)) {
        *why = "interrupted: cell shutting down";
        return std::nullopt;
      }
    }
    PublishLive(loop.command, k, k + 1 == loop.expected_samples, encoded, spec.name, loop.params);
    const auto hold =
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(spec.hold_s));
    std::optional<msg::PusherCommand> answer;
    if (lockstep) {
      answer = AwaitCommand(loop, k, true, Clock::now() + hold);
    } else {
      // Collect until the next sample is due; the newest answer wins.
      const auto next_due =
          loop.start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
                           (truth.t + 1.0 / mechanics::kSampleRateHz) * options.speed));
      answer = AwaitCommand(loop, k, false, next_due);
    }
    AppliedCommand record;
    record.sample = k;
    record.t = truth.t;
    const auto now = Clock::now();
    if (answer) {
      record.loop_ms = (UnixNanos() - answer->state_sent_unix_ns()) * 1e-6;
      if (answer->answers_sample() != k) record.loop_ms = -1;  // an older sample's answer
      const Eigen::Vector3d v(answer->velocity()[0], answer->velocity()[1], answer->velocity()[2]);
      const Eigen::Vector3d w(answer->angular_velocity()[0], answer->angular_velocity()[1],
                              answer->angular_velocity()[2]);
      if (!v.allFinite() || !w.allFinite()) {
        *why = "controller " + spec.name + ": command answering sample " + std::to_string(k) +
               " is not finite; pusher stopped";
        return Stop(loop, record);
      }
      if (v.norm() > options.defects.max_pusher_speed * (1 + 1e-9)) {
        *why = "controller " + spec.name + ": commanded " + std::to_string(v.norm()) +
               " m/s at sample " + std::to_string(k) + ", above this cell's " +
               std::to_string(options.defects.max_pusher_speed) + " m/s; pusher stopped";
        return Stop(loop, record);
      }
      record.commanded = v;
      // Actuation noise (defects.hpp) on a moving pusher: v (1 + s) + o.
      loop.in_force.velocity = v.norm() > 0 ? Eigen::Vector3d(v * loop.perturbation.velocity_scale +
                                                              loop.perturbation.velocity_offset)
                                            : Eigen::Vector3d::Zero();
      loop.in_force.angular_velocity = w;
      loop.last_command_at = now;
    } else if (now - loop.last_command_at > hold) {
      *why = "controller " + spec.name + ": no command for " + std::to_string(spec.hold_s) +
             " s (hold time) after sample " + std::to_string(k) + "; pusher stopped";
      return Stop(loop, record);
    } else {
      record.commanded =
          loop.applied.empty() ? Eigen::Vector3d::Zero() : loop.applied.back().commanded;
    }
    record.applied = loop.in_force.velocity;
    loop.applied.push_back(record);
    return loop.in_force;
  }

  std::optional<mechanics::PusherMotion> Stop(ClosedLoop& loop, AppliedCommand record) {
    loop.in_force.velocity.setZero();
    record.applied.setZero();
    loop.applied.push_back(record);
    return std::nullopt;
  }

  void ExecuteClosedLoop(const msg::TrialCommand& c, const mechanics::Scene& scene,
                         Clock::time_point started) {
    if (!mechanics.simulate_closed_loop) {
      return Refuse(c, "pusher.motion.controller: this cell's backend cannot run closed loops");
    }
    const TrialPerturbation perturbation =
        DrawPerturbation(options.defects, c.seed(), c.trial_id());
    mechanics::Scene actual = ApplyPerturbation(scene, perturbation);
    actual.pusher->motion = mechanics::PusherMotion{};  // at rest until the first answer
    actual.model.facets = std::max(actual.model.facets, options.fidelity.facets);
    actual.model.points = std::max(actual.model.points, options.fidelity.points);
    actual.model.dt = std::min(actual.model.dt, options.fidelity.dt);
    ClosedLoop loop{c,
                    actual,
                    perturbation,
                    MakeControlContext(scene, options.defects.max_pusher_speed),
                    "",
                    Clock::now(),
                    DeadlineOf(c, started),
                    0,
                    {},
                    {},
                    {}};
    loop.params = ControlContextToJson(loop.context);
    loop.expected_samples =
        static_cast<std::size_t>(std::floor(scene.duration * mechanics::kSampleRateHz + 1e-9)) + 1;
    // The controller must be on the domain, its endpoints matched, before
    // the first sample: a lockstep cell waits for it only hold_s.
    const std::string peer = "arena.controller." + loop.context.spec.name;
    const auto wait = std::chrono::duration_cast<dds::Millis>(
        std::min(std::chrono::duration<double>(kControllerWait_s),
                 std::chrono::duration<double>(loop.deadline - Clock::now())));
    if (!participant.WaitForPeer(peer, wait) || !live.WaitForMatched(1, dds::Millis(2000)) ||
        !pusher_commands.WaitForMatched(1, dds::Millis(2000))) {
      auto s = BaseStatus(c, msg::STATE_FAILED);
      s.reason("controller " + loop.context.spec.name + ": not on domain " +
               std::to_string(options.domain_id) + " (start `arena controller --name " +
               loop.context.spec.name + "`)");
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    loop.start = Clock::now();
    loop.last_command_at = loop.start;
    pusher_commands.TakeAll();  // answers to earlier trials
    mechanics::SimulationResult result = mechanics.simulate_closed_loop(
        actual, [&](const std::vector<mechanics::TrajectorySample>& samples, std::string* why) {
          return NextCommand(loop, samples, why);
        });
    std::string failure = result.stopped;
    if (result.status != mechanics::SimulationStatus::kOk) {
      failure = "simulation: " + ModeName(result.status) + ": " + result.error;
    }
    if (result.samples.empty()) {
      auto s = BaseStatus(c, msg::STATE_FAILED);
      s.reason(failure.empty() ? "simulation: no samples" : failure);
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    // The log: every sample, as the closed loop saw it, unpaced (the loop
    // itself was paced).
    const auto observed = Observe(result.samples, actual, options.defects, c.seed(), c.trial_id());
    mechanics::Scene as_run = actual;  // PusherAt's velocity: the last command
    as_run.pusher->motion = loop.in_force;
    const StreamOutcome streamed = StreamLog(c, result, as_run, observed, Clock::now(),
                                             DeadlineOf(c, started), Pacing::kFlatOut);
    if (failure.empty()) failure = streamed.failure;
    const auto& last = result.samples.back();
    true_pose.position = last.position;
    true_pose.orientation = last.orientation;
    for (auto it = observed.rbegin(); it != observed.rend(); ++it) {
      if (it->valid) {
        observed_pose.position = it->position;
        observed_pose.orientation = it->orientation;
        break;
      }
    }
    pusher = scene.pusher;

    auto s = BaseStatus(c, failure.empty() ? msg::STATE_EXECUTED : msg::STATE_FAILED);
    s.reason(failure);
    s.samples(static_cast<std::uint32_t>(result.samples.size()));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    s.detail_json(ClosedLoopDetail(loop, result, streamed).dump());
    if (!failure.empty()) {
      spdlog::warn("cell {}: trial {} attempt {} failed: {}", options.id, c.trial_id(), c.attempt(),
                   failure);
    }
    Finish(c, s);
  }

  json ClosedLoopDetail(const ClosedLoop& loop, const mechanics::SimulationResult& result,
                        const StreamOutcome& streamed) {
    json commands = json::array();
    std::vector<double> loop_ms;
    std::size_t held = 0;
    for (const auto& a : loop.applied) {
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
    const ControlOutcome outcome =
        ScoreControl(loop.context.spec.name, loop.context, result.samples);
    json score = nullptr;
    if (outcome.scored) {
      score = {{"reached", outcome.reached},
               {"final_error", outcome.final_error},
               {"settle_time_s",
                outcome.settle_time_s < 0 ? json(nullptr) : json(outcome.settle_time_s)}};
    }
    return {
        {"mu_scale", loop.perturbation.mu_scale},
        {"velocity_scale", loop.perturbation.velocity_scale},
        {"velocity_offset",
         {loop.perturbation.velocity_offset.x(), loop.perturbation.velocity_offset.y(),
          loop.perturbation.velocity_offset.z()}},
        {"batches", streamed.batches},
        {"model",
         {{"dof", result.model.dof},
          {"facets", result.model.facets},
          {"points", result.model.points},
          {"dt", result.model.dt},
          {"unknowns", result.model.unknowns}}},
        {"solver",
         {{"steps", result.solver.steps},
          {"max_pivots", result.solver.max_pivots},
          {"failures", result.solver.failures}}},
        {"simulate_wall_s", result.wall_s},
        {"closed_loop",
         {{"controller", loop.context.spec.name},
          {"lockstep", options.speed == 0},
          {"context", json::parse(loop.params)},
          {"commands_columns",
           {"sample", "t", "vx", "vy", "vz", "applied_vx", "applied_vy", "applied_vz", "loop_ms"}},
          {"commands", commands},
          {"held", held},
          {"loop_ms", {{"p50", pct(0.5)}, {"p99", pct(0.99)}, {"max", pct(1.0)}}},
          {"outcome", score}}}};
  }

  // ---------------------------------------------------------------------
  // Streaming: the reliable GroundTruth log, and the LiveState topic beside it.

  Clock::time_point DeadlineOf(const msg::TrialCommand& c, Clock::time_point started) const {
    return c.deadline_s() > 0 ? started + std::chrono::duration_cast<Clock::duration>(
                                              std::chrono::duration<double>(c.deadline_s()))
                              : Clock::time_point::max();
  }

  // One sample on the live topic: best-effort, keep-last 1, never waits.
  void PublishLive(const msg::TrialCommand& c, std::uint32_t index, bool last,
                   const msg::GroundTruthSample& sample, const std::string& controller = "",
                   const std::string& params = "") {
    msg::LiveState s;
    s.cell_id(options.id);
    s.trial_id(c.trial_id());
    s.attempt(c.attempt());
    s.sample(index);
    s.last(last);
    s.closed_loop(!controller.empty());
    s.controller(controller);
    s.controller_params(params);
    s.state(sample);
    s.sent_unix_ns(UnixNanos());
    live.Write(s);
  }

  StreamOutcome StreamLog(const msg::TrialCommand& c, const mechanics::SimulationResult& result,
                          const mechanics::Scene& actual,
                          const std::vector<dds::Observation>& observed,
                          Clock::time_point stream_start, Clock::time_point deadline,
                          Pacing pacing) {
    StreamOutcome out;
    const size_t n = result.samples.size();
    // Nobody watching: do not even serialise the live samples.
    const bool live_on = pacing == Pacing::kLive && live.Matched() > 0;
    auto due_of = [&](size_t i) {
      return stream_start + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(result.samples[i].t * options.speed));
    };
    std::string& failure = out.failure;
    for (size_t first = 0; first < n && failure.empty();) {
      const size_t count = std::min<size_t>(options.batch_samples, n - first);
      msg::GroundTruth batch;
      batch.trial_id(c.trial_id());
      batch.attempt(c.attempt());
      batch.cell_id(options.id);
      batch.batch(out.batches);
      batch.first_sample(static_cast<std::uint32_t>(first));
      batch.last(first + count == n);
      batch.samples().resize(count);
      for (size_t i = 0; i < count; ++i) {
        const auto& truth = result.samples[first + i];
        dds::EncodeSample(truth, PusherAt(actual, truth), observed[first + i], &batch.samples()[i]);
      }
      const bool paced = pacing == Pacing::kLive && options.speed > 0;
      for (size_t i = 0; i < count && (paced || live_on); ++i) {
        if (paced) {
          const auto due = due_of(first + i);
          if (due > deadline) break;  // the deadline check below ends the trial
          if (!SleepUntil(due)) {
            failure = "interrupted: cell shutting down";
            break;
          }
        }
        if (paced ? live.Matched() > 0 : live_on)
          PublishLive(c, static_cast<std::uint32_t>(first + i), first + i + 1 == n,
                      batch.samples()[i]);
      }
      if (!failure.empty()) break;
      // Fault injection (defects.hpp): a malformed sample, or a missing batch.
      if (options.defects.corrupt_stream == "gap" && out.batches == 0)
        batch.first_sample(static_cast<std::uint32_t>(first + 1));
      if (options.defects.corrupt_stream == "nan" && out.batches == 0)
        batch.samples()[0].object_pose()[0] = std::numeric_limits<double>::quiet_NaN();
      if (paced) {
        const auto due = due_of(first + count - 1);
        if (due > deadline) {
          SleepUntil(deadline);
        } else if (!SleepUntil(due)) {
          failure = "interrupted: cell shutting down";
          break;
        }
      }
      batch.sent_unix_ns(UnixNanos());
      // Ground truth is a log: a full history throttles us, it never drops.
      while (!ground_truth.Write(batch)) {
        if (Stopping()) {
          failure = "interrupted: cell shutting down";
          break;
        }
        if (Clock::now() > deadline) break;
        spdlog::warn("cell {}: ground-truth history full (a slow reader?), retrying", options.id);
      }
      if (Clock::now() > deadline) {
        failure = "deadline: " + std::to_string(c.deadline_s()) + " s exceeded after " +
                  std::to_string(first + count) + " of " + std::to_string(n) + " samples";
      }
      if (failure.empty()) {
        std::lock_guard<std::mutex> lock(mutex);
        counters.samples += count;
      }
      first += count;
      ++out.batches;
      if (Stopping() && failure.empty() && first < n) failure = "interrupted: cell shutting down";
    }
    return out;
  }

  void Reset(const msg::TrialCommand& c) {
    const auto started = Clock::now();
    reset::ResetRequest request;
    request.observed_end = observed_pose;
    request.true_end = true_pose;
    std::optional<mechanics::PusherSpec> next_pusher = pusher;
    if (!c.scene_json().empty()) {
      mechanics::Scene next;
      try {
        next = mechanics.parse(c.scene_json());
      } catch (const std::exception& e) {
        return Refuse(c, std::string("scene: ") + e.what());
      }
      if (std::string why = CheckCapabilities(options.defects, next); !why.empty()) {
        return Refuse(c, why);
      }
      request.target = ToResetPose(next.object.pose);
      next_pusher = next.pusher;
    }
    request.swap_pusher = !SamePusher(pusher, next_pusher);
    auto accepted = BaseStatus(c, msg::STATE_ACCEPTED);
    Send(accepted);

    const reset::ResetOutcome out =
        reset::ExecuteReset(request, reset_params, c.seed(), c.trial_id());
    // The reset's own (simulated) duration is paced like a trial.
    if (options.speed > 0) {
      SleepUntil(started + std::chrono::duration_cast<Clock::duration>(
                               std::chrono::duration<double>(out.time_s * options.speed)));
    }
    true_pose = out.final_true;
    observed_pose = out.final_observed;
    if (out.success) pusher = next_pusher;
    auto s = BaseStatus(c, out.success ? msg::STATE_RESET_DONE : msg::STATE_FAILED);
    s.reason(out.failure);
    s.reset_position_error(out.position_error);
    s.reset_angle_error(out.angle_error);
    s.reset_attempts(static_cast<std::uint32_t>(out.attempts));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    json plan = json::array();
    for (const auto& p : out.plan) {
      plan.push_back({{"primitive", reset::ToString(p.kind)}, {"duration_s", p.duration_s}});
    }
    s.detail_json(json({{"plan", plan},
                        {"time_s", out.time_s},
                        {"swap_pusher", request.swap_pusher},
                        {"retryable", out.retryable}})
                      .dump());
    Finish(c, s);
  }

  void Run() {
    while (!Stopping()) {
      auto command = commands.Take(dds::Millis(100));
      if (!command || command->cell_id() != options.id) continue;
      try {
        Handle(*command);
      } catch (const std::exception& e) {
        // A bug or a DDS failure in one command must not take the cell down
        // silently: report it and go on.
        spdlog::error("cell {}: trial {}: {}", options.id, command->trial_id(), e.what());
        auto s = BaseStatus(*command, msg::STATE_FAILED);
        s.reason(std::string("internal error: ") + e.what());
        Finish(*command, s);
      }
    }
    std::lock_guard<std::mutex> lock(mutex);
    finished = true;
    wake.notify_all();
  }
};

Cell::Cell(const CellOptions& options, MechanicsBackend mechanics)
    : impl_(std::make_unique<Impl>(options, std::move(mechanics))) {
  impl_->Announce();
  spdlog::info("cell {}: up on domain {} (speed {}, {} samples per batch)", options.id,
               options.domain_id, options.speed, options.batch_samples);
  impl_->worker = std::thread([this] { impl_->Run(); });
}

Cell::~Cell() {
  Stop();
  if (impl_->worker.joinable()) impl_->worker.join();
}

void Cell::Stop() {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->stop = true;
  impl_->wake.notify_all();
}

void Cell::Wait() {
  std::unique_lock<std::mutex> lock(impl_->mutex);
  impl_->wake.wait(lock, [&] { return impl_->finished; });
}

CellCounters Cell::counters() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->counters;
}

}  // namespace arena::executors
