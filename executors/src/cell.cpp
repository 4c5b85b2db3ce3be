#include "arena/executors/cell.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <stdexcept>
#include <thread>
#include <tuple>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/executors/controller.hpp"
#include "arena/executors/defect_layer.hpp"
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

// Issue 12: a trial starts where the last reset left the object (its true
// pose), so reset error reaches the trial's physics; the fingers close on the
// object there (mechanics::SeatFingers). The observed pose still goes to the
// store as before. Kept apart so the cell's structure can change around it.
mechanics::Scene StartWhereResetLeft(mechanics::Scene scene,
                                     const std::optional<reset::Pose>& reset_left) {
  if (!reset_left) return scene;  // no reset yet: the planned pose
  const Eigen::Matrix3d R = reset_left->orientation.normalized().toRotationMatrix();
  scene.object.pose.position = reset_left->position;
  scene.object.pose.rpy = {std::atan2(R(2, 1), R(2, 2)), std::asin(std::clamp(-R(2, 0), -1.0, 1.0)),
                           std::atan2(R(1, 0), R(0, 0))};
  mechanics::SeatFingers(&scene);  // throws SceneError when a finger misses the object
  return scene;
}

// Where the cell's last simulated reset left the object, and for which trial.
struct ResetLeft {
  std::uint64_t seed = 0;  // the prepared trial's seed
  reset::Pose target;      // its planned start pose
  reset::Pose pose;        // where the object really ended
};

// Where a trial starts on a simulated cell (nullopt: as planned). The
// placement error belongs to the trial the placement prepares
// (reset::PlacementForTrial): the cell's own reset if it was aimed at this
// very trial, otherwise the same pure draw for this trial -- as if the cell's
// reset had been aimed at it. That is the simulation's bookkeeping (the
// driver aims a reset at the trial it expects next; another cell may take
// it, and a fresh cell has reset nothing), so a trial's truth never depends
// on which cell ran it or what ran before. A backend that does not emulate
// defects (a robot, recorded data) has its own start and is left alone.
std::optional<reset::Pose> TrialStartPose(const std::optional<ResetLeft>& left, std::uint64_t seed,
                                          const reset::Pose& target,
                                          const reset::ResetParams& params, bool emulated) {
  if (!emulated) return std::nullopt;
  if (left && left->seed == seed && left->target.position == target.position &&
      left->target.orientation.coeffs() == target.orientation.coeffs()) {
    return left->pose;
  }
  return reset::PlacementForTrial(target, params, seed).true_pose;
}

bool SamePusher(const std::optional<mechanics::PusherSpec>& a,
                const std::optional<mechanics::PusherSpec>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  return a->type == b->type && a->length == b->length && a->radius == b->radius &&
         a->axis == b->axis && a->normal == b->normal && a->position == b->position;
}

}  // namespace

// Why a backend's true sample is unusable ("" = fine): NaN or infinite
// values, a time that does not start at 0 or does not increase.
std::string CheckTrueSample(const mechanics::TrajectorySample& s,
                            const std::vector<mechanics::TrajectorySample>& before,
                            const mechanics::Scene& scene) {
  bool finite = std::isfinite(s.t) && s.position.allFinite() &&
                s.orientation.coeffs().allFinite() && s.velocity.allFinite() &&
                s.angular_velocity.allFinite() && s.pusher_position.allFinite() &&
                s.pusher_force.allFinite();
  for (const auto& c : s.contacts) {
    finite = finite && std::isfinite(c.normal_force) && c.tangential_force.allFinite() &&
             c.torque.allFinite();
  }
  if (!finite) return "non-finite value (NaN or infinity) in the true state";
  if (std::abs(s.orientation.norm() - 1) > 1e-6) return "orientation is not a unit quaternion";
  if (before.empty() && std::abs(s.t) > 1e-9) return "the first sample's t must be 0";
  if (!before.empty() && !(s.t > before.back().t)) {
    return "timestamps out of order: t = " + std::to_string(s.t) + " s after " +
           std::to_string(before.back().t) + " s";
  }
  const size_t contacts = scene.fingers.size() + (scene.pusher ? 1 : 0);
  if (s.contacts.size() != contacts) {
    return "expected " + std::to_string(contacts) + " contacts (fingers, then the pusher), got " +
           std::to_string(s.contacts.size());
  }
  return "";
}

void ValidateCellOptions(const CellOptions& o) {
  if (o.id.empty() || o.id.size() > 64)
    throw std::invalid_argument("--id: must be 1..64 characters");
  for (char c : o.id) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) {
      throw std::invalid_argument("--id: only letters, digits, '_', '-' and '.' are allowed");
    }
  }
  if (o.domain_id < 0 || o.domain_id > dds::kMaxDomainId) {
    throw std::invalid_argument("--domain: must be 0.." + std::to_string(dds::kMaxDomainId) +
                                ", got " + std::to_string(o.domain_id));
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
  // Scenes are parsed here (the backend gets a valid Scene); a stand-in
  // MechanicsBackend may bring its own parser.
  std::function<mechanics::Scene(std::string_view)> parse;
  DefectLayer layer;  // the backend, wrapped in defect emulation
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
  std::optional<ResetLeft> reset_left;          // the last successful simulated reset
  std::optional<mechanics::PusherSpec> pusher;  // the pusher mounted now
  std::thread worker;

  // ---- serving (PHASE_CLAIM), guarded by `mutex`. The intake thread reads
  // commands as they come (a claim is never stuck behind a long trial) and
  // queues the serving session's commands for the worker; every other
  // session's command is dropped. A session once superseded is never served
  // again, so a dead service's queued commands cannot run after its successor
  // claimed the cell.
  struct Serving {
    std::uint64_t session = 0;  // 0: free
    std::string host, store;
    std::uint32_t pid = 0;
    double lease_s = 0;
    Clock::time_point until{};
  };
  static constexpr double kImplicitLease_s = 10.0;  // a command without a claim (a test driver)
  static constexpr std::size_t kRetiredKept = 256;
  Serving serving;
  std::set<std::uint64_t> retired;
  std::deque<std::uint64_t> retired_order;
  std::deque<msg::TrialCommand> queue;  // the serving session's commands, for the worker
  std::uint64_t started_unix_ns = UnixNanos();
  std::thread intake;

  static dds::ParticipantOptions ParticipantFor(const CellOptions& o) {
    ValidateCellOptions(o);
    dds::ParticipantOptions p;
    p.domain_id = o.domain_id;
    p.name = dds::CellParticipantName(o.id);
    p.network = o.network;
    p.lease_s = o.participant_lease_s;
    return p;
  }

  Impl(const CellOptions& o, std::function<mechanics::Scene(std::string_view)> parser,
       std::unique_ptr<Backend> backend)
      : options(o),
        parse(std::move(parser)),
        layer(std::move(backend), o.defects),
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

  // Caller holds `mutex` (reads `serving`); only the constructor and the
  // intake thread write announcements.
  void Announce() {
    msg::CellAnnounce a;
    a.serving_session(serving.session);
    a.serving_host(serving.host);
    a.serving_pid(serving.pid);
    a.serving_lease_s(serving.lease_s);
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
    a.started_unix_ns(started_unix_ns);
    const BackendCapabilities& caps = layer.capabilities();
    a.backend(caps.name);
    a.truth(ToString(caps.truth));
    a.backend_json(json({{"engine", caps.engine},
                         {"emulates_defects", caps.emulates_defects},
                         {"settings", json::parse(caps.settings_json, nullptr, false)}})
                       .dump());
    if (!announce.Write(a)) throw dds::DdsError("cell: announcing the cell failed");
  }

  msg::TrialStatus BaseStatus(const msg::TrialCommand& c, msg::TrialState state) {
    msg::TrialStatus s;
    s.trial_id(c.trial_id());
    s.attempt(c.attempt());
    s.cell_id(options.id);
    s.phase(c.phase());
    s.state(state);
    s.service_session(c.service_session());
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

  TrialContext Context(const msg::TrialCommand& c, Clock::time_point deadline) const {
    TrialContext t;
    t.trial_id = c.trial_id();
    t.attempt = c.attempt();
    t.seed = c.seed();
    t.scene_json = c.scene_json();
    t.deadline = deadline;
    return t;
  }

  void Execute(const msg::TrialCommand& c) {
    const auto started = Clock::now();
    mechanics::Scene scene;
    try {
      scene = parse(c.scene_json());
    } catch (const std::exception& e) {
      return Refuse(c, std::string("scene: ") + e.what());
    }
    if (!std::isfinite(c.deadline_s()) || c.deadline_s() < 0) {
      return Refuse(c, "deadline_s: must be finite and >= 0 (0 = none)");
    }
    const auto deadline = c.deadline_s() > 0
                              ? started + std::chrono::duration_cast<Clock::duration>(
                                              std::chrono::duration<double>(c.deadline_s()))
                              : Clock::time_point::max();
    // Issue 12: the trial starts where the reset that prepared it left the object.
    try {
      scene = StartWhereResetLeft(
          scene, TrialStartPose(reset_left, c.seed(), ToResetPose(scene.object.pose), reset_params,
                                layer.capabilities().emulates_defects));
    } catch (const std::exception& e) {
      return Refuse(c, std::string("start pose: ") + e.what());
    }
    TrialContext trial = Context(c, deadline);
    const bool closed_loop = scene.pusher && scene.pusher->controller;
    if (closed_loop && !layer.capabilities().closed_loop) {
      return Refuse(c, "pusher.motion.controller: the " + layer.capabilities().name +
                           " backend cannot run closed-loop trials (it cannot step with "
                           "commanded pusher velocities); run them on a `model` cell");
    }
    if (std::string why = layer.Prepare(scene, c.defects_json(), trial); !why.empty()) {
      return Refuse(c, why);
    }
    auto accepted = BaseStatus(c, msg::STATE_ACCEPTED);
    Send(accepted);
    reset_left.reset();                       // the trial moves the object
    if (options.defects.hang_after_accept) {  // fault injection: a hung controller
      spdlog::warn("cell {}: fault injection: hanging after accepting trial {}", options.id,
                   c.trial_id());
      SleepUntil(Clock::time_point::max());
      return;
    }
    if (closed_loop) return ExecuteClosedLoop(c, scene, trial, started);

    // The backend streams the truth; the cell checks every sample (finite,
    // time strictly increasing from 0), observes it and sends it on as it
    // arrives: on the live topic when due, into the log batch by batch (a
    // driver or a robot streams live; a simulator's samples come all at
    // once). A failure after some samples went out ends the phase FAILED
    // like a deadline does; the service then drops the partial stream.
    struct Collected {
      std::vector<mechanics::TrajectorySample> samples;
      std::vector<dds::Observation> observed;
      std::optional<Observer> observer;  // from the first sample: the layer's scene is set
      std::string problem;
    } got;
    Outgoing out(c, deadline, Pacing::kLive, live.Matched() > 0);
    const SampleSink sink = [&](const mechanics::TrajectorySample& s) {
      if (!got.problem.empty() || !out.failure.empty()) return false;
      if (std::string why = CheckTrueSample(s, got.samples, scene); !why.empty()) {
        got.problem = why;
        return false;
      }
      got.samples.push_back(s);
      if (!got.observer) got.observer.emplace(layer.MakeObserver(trial));
      got.observed.push_back(got.observer->Next(got.samples));
      if (!Push(out, layer.actual_scene(), got.samples.back(), got.observed.back())) return false;
      return !Stopping() && Clock::now() <= deadline;
    };
    // A backend waiting on its hardware: what the log holds leaves now.
    trial.idle = [&] {
      if (out.failure.empty()) SendBatch(out, false);
    };
    const ExecuteOutcome outcome = layer.Execute(scene, trial, sink);
    trial.idle = nullptr;
    std::string early;
    if (!got.problem.empty())
      early = "backend " + layer.capabilities().name + ": sample " +
              std::to_string(got.samples.size()) + ": " + got.problem;
    else if (!out.failure.empty())
      early = out.failure;
    else if (Stopping())
      early = "interrupted: cell shutting down";
    else if (Clock::now() > deadline)
      early = "deadline: " + std::to_string(c.deadline_s()) + " s exceeded while the backend ran";
    else if (!outcome.ok)
      early = outcome.reason.empty() ? "backend failed without a reason" : outcome.reason;
    else if (got.samples.empty())
      early = "backend " + layer.capabilities().name + ": no samples";
    if (!early.empty()) {
      auto s = BaseStatus(c, msg::STATE_FAILED);
      // Typed for the service: a model that cannot run the scene fails the
      // same way on a re-run (FAILURE_SIMULATION: the trial fails at once);
      // a driver that crashed, hung or sent garbage may do better next time.
      s.failure(!got.problem.empty()                          ? msg::FAILURE_INTERNAL
                : early.rfind("deadline", 0) == 0             ? msg::FAILURE_DEADLINE
                : early.rfind("interrupted", 0) == 0          ? msg::FAILURE_INTERRUPTED
                : Stopping()                                  ? msg::FAILURE_INTERRUPTED
                : Clock::now() > deadline                     ? msg::FAILURE_DEADLINE
                : outcome.reason.rfind("simulation:", 0) == 0 ? msg::FAILURE_SIMULATION
                                                              : msg::FAILURE_INTERNAL);
      s.reason(early);
      s.samples(static_cast<std::uint32_t>(out.sent));  // already in the log (not a trial)
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      s.detail_json(json({{"backend", layer.capabilities().name},
                          {"defects_applied", json::parse(layer.AppliedJson())},
                          {"streamed_samples", out.sent},
                          {"backend_detail", json::parse(outcome.detail_json, nullptr, false)}})
                        .dump());
      if (out.sent > 0)
        spdlog::warn("cell {}: trial {} attempt {} failed after {} samples were streamed: {}",
                     options.id, c.trial_id(), c.attempt(), out.sent, early);
      return Finish(c, s);
    }
    const std::vector<mechanics::TrajectorySample>& truth_samples = got.samples;
    const std::vector<dds::Observation>& observed = got.observed;
    EndStream(out);
    const std::string& failure = out.failure;
    const size_t n = truth_samples.size();
    size_t dropped = 0;
    for (const auto& o : observed) dropped += o.valid ? 0 : 1;
    const std::uint32_t batch_index = out.batches;

    const auto& last = truth_samples.back();
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
    if (!failure.empty())
      s.failure(failure.rfind("deadline", 0) == 0 ? msg::FAILURE_DEADLINE
                                                  : msg::FAILURE_INTERRUPTED);
    s.samples(static_cast<std::uint32_t>(n));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    const TrialPerturbation& perturbation = layer.perturbation();
    json detail = json::parse(outcome.detail_json, nullptr, false);
    if (!detail.is_object()) detail = json::object();
    detail["mu_scale"] = perturbation.mu_scale;
    detail["velocity_scale"] = perturbation.velocity_scale;
    detail["velocity_offset"] = {perturbation.velocity_offset.x(), perturbation.velocity_offset.y(),
                                 perturbation.velocity_offset.z()};
    detail["dropped_observations"] = dropped;
    detail["batches"] = batch_index;
    detail["backend"] = layer.capabilities().name;
    detail["truth"] = ToString(layer.capabilities().truth);
    detail["defects_applied"] = json::parse(layer.AppliedJson());
    s.detail_json(detail.dump());
    if (!failure.empty()) {
      spdlog::warn("cell {}: trial {} attempt {} failed: {}", options.id, c.trial_id(), c.attempt(),
                   failure);
    }
    Finish(c, s);
  }

  // How a trial's samples go out (Outgoing, below).
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
    const TrialContext& trial;
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
      const auto wait = until > now
                            ? std::chrono::duration_cast<std::chrono::nanoseconds>(until - now)
                            : std::chrono::nanoseconds(0);
      auto m = pusher_commands.Take(wait);
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
    const auto observed = layer.Observe(samples, loop.trial);
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
      // Best-effort loses messages (a controller that matched a moment late
      // misses sample 0): without an answer the sample is published again
      // every 20 ms until the hold time runs out.
      const auto give_up = Clock::now() + hold;
      for (;;) {
        answer = AwaitCommand(loop, k, true,
                              std::min(give_up, Clock::now() + std::chrono::milliseconds(20)));
        if (answer || Clock::now() >= give_up || Stopping()) break;
        PublishLive(loop.command, k, k + 1 == loop.expected_samples, encoded, spec.name,
                    loop.params);
      }
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
      if (v.norm() > layer.cell_profile().max_pusher_speed * (1 + 1e-9)) {
        *why = "controller " + spec.name + ": commanded " + std::to_string(v.norm()) +
               " m/s at sample " + std::to_string(k) + ", above this cell's " +
               std::to_string(layer.cell_profile().max_pusher_speed) + " m/s; pusher stopped";
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

  // The backend can run it (Execute checked closed_loop before ACCEPTED); the
  // defect layer perturbs the scene as for any trial.
  void ExecuteClosedLoop(const msg::TrialCommand& c, const mechanics::Scene& scene,
                         const TrialContext& trial, Clock::time_point started) {
    ClosedLoop loop{c,
                    trial,
                    layer.perturbation(),
                    MakeControlContext(scene, layer.cell_profile().max_pusher_speed),
                    "",
                    Clock::now(),
                    trial.deadline,
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
      s.failure(msg::FAILURE_NONE);  // the controller's, not the cell's: a retry may find it
      s.reason("controller " + loop.context.spec.name + ": not on domain " +
               std::to_string(options.domain_id) + " (start `arena controller --name " +
               loop.context.spec.name + "`)");
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    loop.start = Clock::now();
    loop.last_command_at = loop.start;
    pusher_commands.TakeAll();  // answers to earlier trials
    mechanics::SimulationResult result =
        layer.ExecuteClosedLoop(scene, trial,
                                [&](const std::vector<mechanics::TrajectorySample>& samples,
                                    std::string* why) { return NextCommand(loop, samples, why); });
    const mechanics::Scene& actual = layer.actual_scene();
    std::string failure = result.stopped;
    if (result.status != mechanics::SimulationStatus::kOk) {
      failure = "simulation: " + ModeName(result.status) + ": " + result.error;
    }
    if (result.samples.empty()) {
      auto s = BaseStatus(c, msg::STATE_FAILED);
      s.reason(failure.empty() ? "simulation: no samples" : failure);
      s.failure(ClosedLoopFailure(s.reason()));
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    // The log: every sample, as the closed loop saw it, unpaced (the loop
    // itself was paced).
    const auto observed = layer.Observe(result.samples, trial);
    mechanics::Scene as_run = actual;  // PusherAt's velocity: the last command
    as_run.pusher->motion = loop.in_force;
    const StreamOutcome streamed =
        StreamLog(c, result.samples, as_run, observed, trial.deadline, Pacing::kFlatOut);
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
    if (!failure.empty()) s.failure(ClosedLoopFailure(failure));
    s.samples(static_cast<std::uint32_t>(result.samples.size()));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    s.detail_json(ClosedLoopDetail(loop, result, streamed).dump());
    if (!failure.empty()) {
      spdlog::warn("cell {}: trial {} attempt {} failed: {}", options.id, c.trial_id(), c.attempt(),
                   failure);
    }
    Finish(c, s);
  }

  // Typed for the service like an open-loop failure; a controller's fault
  // (gone, silent past its hold time, a bad command) is FAILURE_NONE: no
  // fault of the cell's model, and a retry may well run through.
  static msg::FailureKind ClosedLoopFailure(const std::string& reason) {
    if (reason.rfind("simulation:", 0) == 0) return msg::FAILURE_SIMULATION;
    if (reason.rfind("deadline", 0) == 0) return msg::FAILURE_DEADLINE;
    if (reason.rfind("interrupted", 0) == 0) return msg::FAILURE_INTERRUPTED;
    return msg::FAILURE_NONE;
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
        {"backend", layer.capabilities().name},
        {"truth", ToString(layer.capabilities().truth)},
        {"defects_applied", json::parse(layer.AppliedJson())},
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

  // One trial's stream on its way out, fed sample by sample as the backend
  // produces them (Push), ended by EndStream. The log (GroundTruth, reliable)
  // takes samples in batches of --batch: a full batch leaves when the next
  // sample arrives, a partial one when the backend goes quiet (SendBatch from
  // TrialContext::idle) or at the end, flagged last. The live topic gets every
  // sample when it is due; its `last` sample is sent again at the end, when
  // the backend said the trial is over.
  struct Outgoing {
    Outgoing(const msg::TrialCommand& command, Clock::time_point until, Pacing how, bool live)
        : c(command), deadline(until), pacing(how), live_on(live) {}
    const msg::TrialCommand& c;
    Clock::time_point deadline;
    Pacing pacing;
    bool live_on;                   // a reader was matched at the start (speed 0)
    Clock::time_point start{};      // when sample 0 arrived: the pacing's origin
    msg::GroundTruth batch;         // the samples not yet in the log
    std::size_t sent = 0;           // samples in the log
    std::size_t pushed = 0;         // samples taken
    std::uint32_t batches = 0;      // batches in the log
    msg::GroundTruthSample newest;  // the latest sample, for the live topic's last
    std::string failure;            // why the stream stopped ("" = going)
  };

  bool Paced(const Outgoing& out) const { return out.pacing == Pacing::kLive && options.speed > 0; }

  // Takes one sample: paces it, publishes it live, queues it for the log.
  // @returns false when the stream stopped (out.failure says why).
  bool Push(Outgoing& out, const mechanics::Scene& actual, const mechanics::TrajectorySample& truth,
            const dds::Observation& observed) {
    if (!out.failure.empty()) return false;
    if (out.pushed == 0) out.start = Clock::now();
    if (out.batch.samples().size() >= static_cast<std::size_t>(options.batch_samples) &&
        !SendBatch(out, false))
      return false;
    const bool paced = Paced(out);
    if (paced) {
      const auto due = out.start + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(truth.t * options.speed));
      if (due > out.deadline) {
        SleepUntil(out.deadline);
        out.failure = "deadline: " + std::to_string(out.c.deadline_s()) + " s exceeded after " +
                      std::to_string(out.sent) + " samples";
        return false;
      }
      if (!SleepUntil(due)) {
        out.failure = "interrupted: cell shutting down";
        return false;
      }
    }
    msg::GroundTruthSample encoded;
    dds::EncodeSample(truth, PusherAt(actual, truth), observed, &encoded);
    if (paced ? live.Matched() > 0 : out.live_on)
      PublishLive(out.c, static_cast<std::uint32_t>(out.pushed), false, encoded);
    out.newest = encoded;
    out.batch.samples().push_back(std::move(encoded));
    ++out.pushed;
    return true;
  }

  // The queued samples into the log as one batch (nothing queued: nothing
  // sent, unless it is the last one). @returns false when the stream stopped.
  bool SendBatch(Outgoing& out, bool last) {
    if (!out.failure.empty()) return false;
    msg::GroundTruth& batch = out.batch;
    if (batch.samples().empty() && !last) return true;
    const std::size_t count = batch.samples().size();
    batch.trial_id(out.c.trial_id());
    batch.attempt(out.c.attempt());
    batch.cell_id(options.id);
    batch.service_session(out.c.service_session());
    batch.batch(out.batches);
    batch.first_sample(static_cast<std::uint32_t>(out.sent));
    batch.last(last);
    // Fault injection (defects.hpp): a malformed sample, or a missing batch.
    if (options.defects.corrupt_stream == "gap" && out.batches == 0)
      batch.first_sample(static_cast<std::uint32_t>(out.sent + 1));
    if (options.defects.corrupt_stream == "nan" && out.batches == 0 && count > 0)
      batch.samples()[0].object_pose()[0] = std::numeric_limits<double>::quiet_NaN();
    if (!Serves(out.c.service_session())) {
      out.failure = "interrupted: the cell now serves another service";
      return false;
    }
    batch.sent_unix_ns(UnixNanos());
    // Ground truth is a log: a full history throttles us, it never drops.
    while (!ground_truth.Write(batch)) {
      if (Stopping()) {
        out.failure = "interrupted: cell shutting down";
        return false;
      }
      if (Clock::now() > out.deadline) break;
      spdlog::warn("cell {}: ground-truth history full (a slow reader?), retrying", options.id);
    }
    if (Clock::now() > out.deadline) {
      out.failure = "deadline: " + std::to_string(out.c.deadline_s()) + " s exceeded after " +
                    std::to_string(out.sent + count) + " samples";
      return false;
    }
    out.sent += count;
    ++out.batches;
    batch.samples().clear();
    {
      std::lock_guard<std::mutex> lock(mutex);
      counters.samples += count;
    }
    return true;
  }

  // The backend finished: the rest of the log, flagged last; the live
  // topic's final sample again, flagged last.
  void EndStream(Outgoing& out) {
    if (!SendBatch(out, true) || out.pushed == 0) return;
    if (Paced(out) ? live.Matched() > 0 : out.live_on)
      PublishLive(out.c, static_cast<std::uint32_t>(out.pushed - 1), true, out.newest);
  }

  // A whole trial's samples, known in advance (closed loop: the loop ran live).
  StreamOutcome StreamLog(const msg::TrialCommand& c,
                          const std::vector<mechanics::TrajectorySample>& truth_samples,
                          const mechanics::Scene& actual,
                          const std::vector<dds::Observation>& observed, Clock::time_point deadline,
                          Pacing pacing) {
    Outgoing out(c, deadline, pacing, pacing == Pacing::kLive && live.Matched() > 0);
    for (std::size_t i = 0; i < truth_samples.size(); ++i) {
      if (!Push(out, actual, truth_samples[i], observed[i])) break;
      if (Stopping() && i + 1 < truth_samples.size()) {
        out.failure = "interrupted: cell shutting down";
        break;
      }
    }
    if (out.failure.empty()) EndStream(out);
    return {out.failure, out.batches};
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
        next = parse(c.scene_json());
      } catch (const std::exception& e) {
        return Refuse(c, std::string("scene: ") + e.what());
      }
      if (std::string why = CheckCapabilities(layer.cell_profile(), next); !why.empty()) {
        return Refuse(c, why);
      }
      request.target = ToResetPose(next.object.pose);
      next_pusher = next.pusher;
    }
    request.swap_pusher = !SamePusher(pusher, next_pusher);
    auto accepted = BaseStatus(c, msg::STATE_ACCEPTED);
    Send(accepted);

    BackendResetRequest backend_request;
    backend_request.target = request.target;
    backend_request.observed_end = observed_pose;
    backend_request.swap_pusher = request.swap_pusher;
    backend_request.next_scene_json = c.scene_json();
    const auto deadline = c.deadline_s() > 0 && std::isfinite(c.deadline_s())
                              ? started + std::chrono::duration_cast<Clock::duration>(
                                              std::chrono::duration<double>(c.deadline_s()))
                              : Clock::time_point::max();
    if (auto own = layer.inner().Reset(backend_request, Context(c, deadline))) {
      return FinishBackendReset(c, *own, next_pusher, started);
    }
    const reset::ResetOutcome out =
        reset::ExecuteReset(request, reset_params, c.seed(), c.trial_id());
    // The reset's own (simulated) duration is paced like a trial.
    if (options.speed > 0) {
      SleepUntil(started + std::chrono::duration_cast<Clock::duration>(
                               std::chrono::duration<double>(out.time_s * options.speed)));
    }
    true_pose = out.final_true;
    observed_pose = out.final_observed;
    if (out.success) reset_left = ResetLeft{c.seed(), request.target, out.final_true};
    if (out.success) pusher = next_pusher;
    auto s = BaseStatus(c, out.success ? msg::STATE_RESET_DONE : msg::STATE_FAILED);
    s.reason(out.failure);
    if (!out.success) s.failure(msg::FAILURE_RESET);
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

  // A backend that resets by itself (a robot) reports the achieved pose.
  void FinishBackendReset(const msg::TrialCommand& c, const BackendResetOutcome& out,
                          const std::optional<mechanics::PusherSpec>& next_pusher,
                          Clock::time_point started) {
    if (out.ok) {
      true_pose = out.achieved;
      observed_pose = out.achieved;
      pusher = next_pusher;
    }
    auto s = BaseStatus(c, out.ok ? msg::STATE_RESET_DONE : msg::STATE_FAILED);
    s.reason(out.reason);
    s.reset_attempts(static_cast<std::uint32_t>(out.attempts));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    s.detail_json(json({{"backend", layer.capabilities().name}, {"time_s", out.time_s}}).dump());
    Finish(c, s);
  }

  // ---- serving
  bool Serves(std::uint64_t session) {
    std::lock_guard<std::mutex> lock(mutex);
    return serving.session == session;
  }

  void Retire(std::uint64_t session) {  // caller holds mutex
    if (session == 0 || !retired.insert(session).second) return;
    retired_order.push_back(session);
    while (retired_order.size() > kRetiredKept) {
      retired.erase(retired_order.front());
      retired_order.pop_front();
    }
  }

  // Caller holds mutex. Serves `c`'s session from now on (a claim, or the
  // first command of a session while the cell is free).
  void ServeLocked(const msg::TrialCommand& c, double lease_s) {
    const bool changed = serving.session != c.service_session();
    if (changed) {
      Retire(serving.session);
      const auto dropped = std::erase_if(queue, [&](const msg::TrialCommand& q) {
        return q.service_session() != c.service_session();
      });
      if (dropped > 0)
        spdlog::info(
            "cell {}: dropped {} queued commands of service session {:016x}, which this "
            "cell no longer serves",
            options.id, dropped, serving.session);
      spdlog::info("cell {}: now serving service session {:016x} ({}, pid {})", options.id,
                   c.service_session(), c.service_host().empty() ? "?" : c.service_host(),
                   c.service_pid());
    }
    serving.session = c.service_session();
    if (!c.service_host().empty() || changed) {
      serving.host = c.service_host();
      serving.pid = c.service_pid();
      serving.store = c.service_store();
    }
    const bool lease_changed = serving.lease_s != lease_s;
    serving.lease_s = lease_s;
    serving.until = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(lease_s));
    if (changed || lease_changed) Announce();
  }

  // Intake thread: one command as it arrives. Claims act at once; the serving
  // session's commands go to the worker; others are dropped.
  void Intake(const msg::TrialCommand& c) {
    std::lock_guard<std::mutex> lock(mutex);
    const std::uint64_t session = c.service_session();
    if (retired.count(session)) {
      spdlog::info(
          "cell {}: dropped a {} command of trial {} from service session {:016x}, which "
          "this cell no longer serves",
          options.id, c.phase() == msg::PHASE_CLAIM ? "claim" : "phase", c.trial_id(), session);
      return;
    }
    const bool free = serving.session == 0 || Clock::now() > serving.until;
    const bool mine = serving.session == session;
    // The same store's new service: the old one is dead (one service per store).
    const bool successor =
        !free && !mine && !serving.store.empty() && serving.store == c.service_store();
    if (c.phase() == msg::PHASE_CLAIM) {
      if (!std::isfinite(c.lease_s()) || c.lease_s() < 0) return;
      if (c.lease_s() == 0) {  // release
        if (mine) {
          Retire(session);
          serving = Serving{};
          Announce();
        }
        return;
      }
      if (free || mine || successor) ServeLocked(c, std::min(c.lease_s(), 3600.0));
      return;
    }
    if (!mine) {
      if (!free) {
        spdlog::info(
            "cell {}: dropped trial {}'s command from service session {:016x}: serving "
            "{:016x}",
            options.id, c.trial_id(), session, serving.session);
        return;
      }
      ServeLocked(c, kImplicitLease_s);
    } else if (Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(serving.lease_s)) >
               serving.until) {
      serving.until = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(serving.lease_s));
    }
    queue.push_back(c);
    wake.notify_all();
  }

  void IntakeLoop() {
    while (!Stopping()) {
      auto command = commands.Take(dds::Millis(100));
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (serving.session != 0 && Clock::now() > serving.until) {
          spdlog::info("cell {}: the lease of service session {:016x} ran out; free", options.id,
                       serving.session);
          serving.session = 0;
          serving.host.clear();
          serving.pid = 0;
          serving.lease_s = 0;
          Announce();
        }
      }
      if (!command || command->cell_id() != options.id) continue;
      try {
        Intake(*command);
      } catch (const std::exception& e) {
        spdlog::error("cell {}: command intake: {}", options.id, e.what());
      }
    }
  }

  std::optional<msg::TrialCommand> NextCommand() {
    std::unique_lock<std::mutex> lock(mutex);
    wake.wait_for(lock, std::chrono::milliseconds(100), [&] { return stop || !queue.empty(); });
    if (stop || queue.empty()) return std::nullopt;
    msg::TrialCommand c = std::move(queue.front());
    queue.pop_front();
    return c;
  }

  void Run() {
    while (!Stopping()) {
      auto command = NextCommand();
      if (!command) continue;
      try {
        Handle(*command);
      } catch (const std::exception& e) {
        // A bug or a DDS failure in one command must not take the cell down
        // silently: report it and go on.
        spdlog::error("cell {}: trial {}: {}", options.id, command->trial_id(), e.what());
        auto s = BaseStatus(*command, msg::STATE_FAILED);
        s.failure(msg::FAILURE_INTERNAL);
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
    : Cell(options, MakeMechanicsStandIn(mechanics, options.fidelity), mechanics.parse) {}

Cell::Cell(const CellOptions& options, std::unique_ptr<Backend> backend)
    : Cell(options, std::move(backend),
           [](std::string_view text) { return mechanics::ParseScene(text); }) {}

Cell::Cell(const CellOptions& options, std::unique_ptr<Backend> backend,
           std::function<mechanics::Scene(std::string_view)> parse)
    : impl_(std::make_unique<Impl>(options, std::move(parse), std::move(backend))) {
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->Announce();
  }
  spdlog::info("cell {}: up on domain {} (speed {}, {} samples per batch)", options.id,
               options.domain_id, options.speed, options.batch_samples);
  impl_->worker = std::thread([this] { impl_->Run(); });
  impl_->intake = std::thread([this] { impl_->IntakeLoop(); });
}

Cell::~Cell() {
  Stop();
  if (impl_->worker.joinable()) impl_->worker.join();
  if (impl_->intake.joinable()) impl_->intake.join();
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
