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
#include "clock.hpp"
#include "closed_loop_trial.hpp"
#include "command_intake.hpp"
#include "defects_json.hpp"
#include "trial_start.hpp"
#include "trial_stream.hpp"

namespace arena::executors {
namespace {

using Clock = StreamClock;
using nlohmann::json;

using internal::UnixNanos;

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

}  // namespace

namespace {
// How far a stream's last sample may sit from the scene's duration: two of
// its sample intervals (a backend samples at its own rate, the last sample
// falls within one interval of the end), and at least 1 ms or 1 %.
double StreamLengthTolerance(const mechanics::Scene& scene,
                             const std::vector<mechanics::TrajectorySample>& samples) {
  double interval = 0;
  if (samples.size() >= 2) interval = samples.back().t - samples[samples.size() - 2].t;
  return std::max({1e-3, 0.01 * scene.duration, 2 * interval});
}

// "" when the stream covers the scene's duration, else why not.
std::string CheckStreamLength(const mechanics::Scene& scene,
                              const std::vector<mechanics::TrajectorySample>& samples) {
  if (samples.empty()) return "";
  const double end = samples.back().t;
  if (end < scene.duration - StreamLengthTolerance(scene, samples)) {
    return "the stream ends at t = " + std::to_string(end) + " s (" +
           std::to_string(samples.size()) + " samples), the scene lasts " +
           std::to_string(scene.duration) + " s";
  }
  return "";
}
}  // namespace

// Why a backend's true sample is unusable ("" = fine): NaN or infinite
// values, a time that does not start at 0 or does not increase.
std::string CheckTrueSample(const mechanics::TrajectorySample& s,
                            const std::vector<mechanics::TrajectorySample>& before,
                            const mechanics::Scene& scene, const TrialTruth& truth) {
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
  // A stream is the scene's push, no longer: a driver that reports a 0.2 s
  // push as a 200 s stream describes another experiment.
  if (s.t > scene.duration + StreamLengthTolerance(scene, before)) {
    return "t = " + std::to_string(s.t) + " s is past the scene's duration of " +
           std::to_string(scene.duration) + " s";
  }
  if (!truth.forces_measured) {
    if (!s.contacts.empty())
      return "the trial's truth measured no contact forces (" + truth.forces_note + "), got " +
             std::to_string(s.contacts.size()) + " contacts";
    return "";
  }
  const size_t contacts = scene.fingers.size() + (scene.pusher ? 1 : 0);
  if (s.contacts.size() != contacts) {
    return "expected " + std::to_string(contacts) + " contacts (fingers, then the pusher), got " +
           std::to_string(s.contacts.size());
  }
  return "";
}

std::string StoredTruth(TruthSource source, const TrialTruth& truth) {
  if (source == TruthSource::kMeasured && !truth.forces_measured)
    return dds::kTruthMeasuredNoForces;
  return ToString(source);
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
  dds::Writer<msg::LiveState> live;  // one message per sample, best-effort
  // Closed loop: the answers of each controller a scene named, on that
  // controller's own topic (dds::ControllerTopic), made at its first trial;
  // only the worker uses them. Another controller's commands never reach
  // this cell, and under DDS-Security only the identity the name is bound to
  // may publish on the topic.
  std::map<std::string, std::unique_ptr<dds::Reader<msg::PusherCommand>>> pusher_commands;
  StreamPort stream_port;  // how trials' samples leave (trial_stream.hpp)

  // Guarded by `mutex`: shared by the worker, the intake thread and Stop().
  std::mutex mutex;
  std::condition_variable wake;
  bool stop = false;
  bool finished = false;
  CellCounters counters;
  CommandIntake intake_state;  // which service is served; its queued commands

  // Worker-only state.
  ResetGate reset_gate;  // an EXECUTE queued behind a RESET runs only after it ended done
  // Phases already finished, to answer a repeated command with its status
  // instead of running it twice. Keyed by the service's session too: trial
  // ids restart at 1 in a new store, and a cell outlives stores and services.
  // Only the latest kRemembered are kept, so months of trials cost no memory.
  using Key = std::tuple<std::uint64_t, std::uint64_t, std::uint32_t,
                         int>;  // session, trial, attempt, phase
  static constexpr std::size_t kRemembered = 1024;
  std::map<Key, msg::TrialStatus> done;
  std::deque<Key> done_order;  // oldest first
  reset::Pose true_pose;       // where the object really is now
  reset::Pose observed_pose;   // where the sensors saw it last
  TrialTruth trial_truth;      // of the trial being executed (Backend::PreparedTruth)
  TrialStart trial_start;      // where trials start (the last reset)
  std::optional<mechanics::PusherSpec> pusher;  // the pusher mounted now
  std::optional<schemas::Fixtures> mounted;     // the fixtures mounted now (nullopt: not known)
  std::uint64_t started_unix_ns = UnixNanos();
  std::thread worker;
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

  // The backend's own workspace (a recording's extent) when the cell's
  // profile leaves the workspace at its default.
  static CellOptions WithBackendWorkspace(CellOptions o, const Backend& backend) {
    o.defects = executors::WithBackendWorkspace(std::move(o.defects), backend.Capabilities());
    return o;
  }

  Impl(const CellOptions& o, std::function<mechanics::Scene(std::string_view)> parser,
       std::unique_ptr<Backend> backend)
      : options(WithBackendWorkspace(o, *backend)),
        parse(std::move(parser)),
        layer(std::move(backend), options.defects),
        reset_params(EffectiveResetParams(options.defects)),
        participant(ParticipantFor(o)),
        announce(participant),
        status(participant),
        ground_truth(participant),
        commands(participant, dds::ReaderOptions{false}),
        live(participant) {
    stream_port.cell_id = o.id;
    stream_port.batch_samples = o.batch_samples;
    stream_port.speed = o.speed;
    stream_port.corrupt_stream = o.defects.corrupt_stream;
    stream_port.log = &ground_truth;
    stream_port.live = &live;
    stream_port.stopping = [this] { return Stopping(); };
    stream_port.sleep_until = [this](Clock::time_point until) { return SleepUntil(until); };
    stream_port.serves = [this](std::uint64_t session) {
      std::lock_guard<std::mutex> lock(mutex);
      return intake_state.Serves(session);
    };
    stream_port.count_samples = [this](std::size_t n) {
      std::lock_guard<std::mutex> lock(mutex);
      counters.samples += n;
    };
  }

  bool Stopping() {
    std::lock_guard<std::mutex> lock(mutex);
    return stop;
  }
  // Sleeps until `until` or Stop(); @returns false when stopping.
  bool SleepUntil(Clock::time_point until) {
    std::unique_lock<std::mutex> lock(mutex);
    return !wake.wait_until(lock, until, [&] { return stop; });
  }

  // What a fixture change costs here (issue 29, schemas/fixtures.hpp): the
  // backend's own (an exec: driver's hello) or the simulated profile's.
  schemas::ChangeCosts ChangeCosts() const {
    if (layer.capabilities().change_costs) return *layer.capabilities().change_costs;
    return {options.defects.finger_change_s, reset_params.swap_time,
            options.defects.object_change_s};
  }
  // Sleeps for a simulated change (scaled like every phase); false: stopping.
  bool EmulateChange(double seconds) {
    if (options.speed <= 0 || seconds <= 0) return true;
    return SleepUntil(Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(seconds * options.speed)));
  }
  static nlohmann::json ChangesJson(const std::vector<schemas::FixtureChange>& changes) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& c : changes)
      out.push_back({{"what", c.what}, {"from", c.from}, {"to", c.to}, {"seconds", c.seconds}});
    return out;
  }

  // Caller holds `mutex` (reads the serving session); only the constructor
  // and the intake thread write announcements.
  void Announce() {
    const CommandIntake::Serving& serving = intake_state.serving();
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
    const schemas::ChangeCosts costs = ChangeCosts();
    a.backend_json(json({{"engine", caps.engine},
                         {"emulates_defects", caps.emulates_defects},
                         {"settings", json::parse(caps.settings_json, nullptr, false)},
                         {schemas::kChangeCostsKey,
                          {{"finger_s", costs.finger_s},
                           {"pusher_s", costs.pusher_s},
                           {"object_s", costs.object_s}}}})
                       .dump());
    if (!announce.Write(a)) throw dds::DdsError("cell: announcing the cell failed");
  }

  // ---- statuses

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
    if (c.phase() == msg::PHASE_RESET)
      reset_gate.ResetEnded(c, s.state() == msg::STATE_RESET_DONE, s.reason());
    else
      reset_gate.OtherEnded();
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
    if (c.phase() == msg::PHASE_EXECUTE) {
      if (std::string why = reset_gate.Check(c); !why.empty()) return Refuse(c, why);
      Execute(c);
    } else if (c.phase() == msg::PHASE_RESET) {
      Reset(c);
    } else {
      Refuse(c, "phase: unknown value");
    }
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

  // Where the trial left the object: its last sample (true) and the sensors'
  // last valid view of it (observed).
  void EndedAt(const mechanics::TrajectorySample& last,
               const std::vector<dds::Observation>& observed) {
    true_pose.position = last.position;
    true_pose.orientation = last.orientation;
    for (auto it = observed.rbegin(); it != observed.rend(); ++it) {
      if (it->valid) {
        observed_pose.position = it->position;
        observed_pose.orientation = it->orientation;
        break;
      }
    }
  }

  // ---- EXECUTE

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
      scene = TrialStart::PlacedAt(
          scene, trial_start.StartPose(c.seed(), ToResetPose(scene.object.pose), reset_params,
                                       layer.capabilities().emulates_defects));
    } catch (const std::exception& e) {
      return Refuse(c, std::string("start pose: ") + e.what());
    }
    TrialContext trial = Context(c, deadline);
    const bool closed_loop = scene.pusher && scene.pusher->controller;
    if (closed_loop && !layer.capabilities().closed_loop) {
      return Refuse(c, "pusher.motion.controller: the " + layer.capabilities().name +
                           " backend cannot run closed-loop trials (it cannot step with "
                           "commanded pusher velocities); run them on a `model` or `mujoco` cell");
    }
    if (std::string why = layer.Prepare(scene, c.defects_json(), trial); !why.empty()) {
      return Refuse(c, why);
    }
    // A truth without forces is a measured recording's stated fact; a
    // simulator or robot always reports every contact.
    trial_truth = layer.PreparedTruth();
    if (!trial_truth.forces_measured && layer.capabilities().truth != TruthSource::kMeasured) {
      return Refuse(c, "backend " + layer.capabilities().name + ": its " +
                           ToString(layer.capabilities().truth) +
                           " truth says it measured no contact forces; only a measured "
                           "recording may lack them");
    }
    if (!trial_truth.forces_measured && closed_loop) {
      return Refuse(c,
                    "pusher.motion.controller: a truth without contact forces cannot run "
                    "closed loop");
    }
    auto accepted = BaseStatus(c, msg::STATE_ACCEPTED);
    Send(accepted);
    // Fixtures other than those mounted (a fresh cell; a trial its reset was
    // not aimed at) are changed first; a simulated cell spends their time.
    {
      const schemas::Fixtures needed = schemas::FixturesOf(scene);
      const auto changes = schemas::ChangesBetween(mounted, needed, ChangeCosts());
      if (!changes.empty()) {
        spdlog::info("cell {}: trial {}: {} fixture change(s) before it runs", options.id,
                     c.trial_id(), changes.size());
        if (layer.capabilities().emulates_defects &&
            !EmulateChange(EmulatedChangeSeconds(changes, false)))
          return;  // stopping
      }
      mounted = needed;
      pusher = scene.pusher;
    }
    trial_start.TrialRan();                   // the trial moves the object
    if (options.defects.hang_after_accept) {  // fault injection: a hung controller
      spdlog::warn("cell {}: fault injection: hanging after accepting trial {}", options.id,
                   c.trial_id());
      SleepUntil(Clock::time_point::max());
      return;
    }
    if (closed_loop) return ExecuteClosedLoop(c, scene, trial, started);
    ExecuteOpenLoop(c, scene, trial, started);
  }

  // What an open-loop run collected from the backend, sample by sample.
  struct Collected {
    std::vector<mechanics::TrajectorySample> samples;
    std::vector<dds::Observation> observed;
    std::optional<Observer> observer;  // from the first sample: the layer's scene is set
    std::string problem;               // why a sample was unusable ("" = none)
  };

  // The backend streams the truth; the cell checks every sample (finite,
  // time strictly increasing from 0), observes it and sends it on as it
  // arrives: on the live topic when due, into the log batch by batch (a
  // driver or a robot streams live; a simulator's samples come all at
  // once). A failure after some samples went out ends the phase FAILED
  // like a deadline does; the service then drops the partial stream.
  void ExecuteOpenLoop(const msg::TrialCommand& c, const mechanics::Scene& scene,
                       TrialContext& trial, Clock::time_point started) {
    Collected got;
    TrialStream out(stream_port, c, trial.deadline, Pacing::kLive);
    const SampleSink sink = [&](const mechanics::TrajectorySample& s) {
      if (!got.problem.empty() || !out.failure().empty()) return false;
      if (std::string why = CheckTrueSample(s, got.samples, scene, trial_truth); !why.empty()) {
        got.problem = why;
        return false;
      }
      got.samples.push_back(s);
      if (!got.observer) got.observer.emplace(layer.MakeObserver(trial));
      got.observed.push_back(got.observer->Next(got.samples));
      if (!out.Push(layer.actual_scene(), got.samples.back(), got.observed.back())) return false;
      return !Stopping() && Clock::now() <= trial.deadline;
    };
    // A backend waiting on its hardware: what the log holds leaves now.
    trial.idle = [&] { out.Flush(); };
    const ExecuteOutcome outcome = layer.Execute(scene, trial, sink);
    trial.idle = nullptr;
    if (const Stopped early = WhyStoppedEarly(c, trial.deadline, got, out, outcome);
        !early.reason.empty())
      return FinishEarlyFailure(c, early, out, outcome, started);
    out.End();
    const std::string& failure = out.failure();
    EndedAt(got.samples.back(), got.observed);
    pusher = scene.pusher;

    auto s = BaseStatus(c, failure.empty() ? msg::STATE_EXECUTED : msg::STATE_FAILED);
    s.reason(failure);
    if (!failure.empty()) s.failure(out.failure_kind());
    s.samples(static_cast<std::uint32_t>(got.samples.size()));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    std::size_t dropped = 0;
    for (const auto& o : got.observed) dropped += o.valid ? 0 : 1;
    const TrialPerturbation& perturbation = layer.perturbation();
    json detail = json::parse(outcome.detail_json, nullptr, false);
    if (!detail.is_object()) detail = json::object();
    detail["mu_scale"] = perturbation.mu_scale;
    detail["velocity_scale"] = perturbation.velocity_scale;
    detail["velocity_offset"] = {perturbation.velocity_offset.x(), perturbation.velocity_offset.y(),
                                 perturbation.velocity_offset.z()};
    detail["dropped_observations"] = dropped;
    detail["batches"] = out.batches();
    detail["backend"] = layer.capabilities().name;
    detail["truth"] = StoredTruth(layer.capabilities().truth, trial_truth);
    if (!trial_truth.forces_measured) detail["forces_not_measured"] = trial_truth.forces_note;
    // The applied defects go in as text, their profiles' part dumped once
    // per campaign profile (DefectLayer::AppliedProfilesText; issue 27).
    detail.erase("defects_applied");
    std::string text = detail.dump();
    text.insert(text.size() - 1, ",\"defects_applied\":" + internal::AppliedDefectsText(layer));
    s.detail_json(std::move(text));
    if (!failure.empty()) {
      spdlog::warn("cell {}: trial {} attempt {} failed: {}", options.id, c.trial_id(), c.attempt(),
                   failure);
    }
    Finish(c, s);
  }

  // Why the backend's run cannot be a whole trial (reason "" = it can), typed
  // for the service: a model that cannot run the scene fails the same way on
  // a re-run (FAILURE_SIMULATION: the trial fails at once); a driver that
  // crashed, hung or sent garbage may do better next time.
  struct Stopped {
    std::string reason;
    msg::FailureKind kind = msg::FAILURE_NONE;
  };
  Stopped WhyStoppedEarly(const msg::TrialCommand& c, Clock::time_point deadline,
                          const Collected& got, const TrialStream& out,
                          const ExecuteOutcome& outcome) {
    if (!got.problem.empty())
      return {"backend " + layer.capabilities().name + ": sample " +
                  std::to_string(got.samples.size()) + ": " + got.problem,
              msg::FAILURE_INTERNAL};
    if (!out.failure().empty()) return {out.failure(), out.failure_kind()};
    if (Stopping()) return {"interrupted: cell shutting down", msg::FAILURE_INTERRUPTED};
    if (Clock::now() > deadline)
      return {"deadline: " + std::to_string(c.deadline_s()) + " s exceeded while the backend ran",
              msg::FAILURE_DEADLINE};
    if (!outcome.ok)
      return {outcome.reason.empty() ? "backend failed without a reason" : outcome.reason,
              outcome.failure == ExecuteFailure::kSimulation ? msg::FAILURE_SIMULATION
                                                             : msg::FAILURE_INTERNAL};
    if (got.samples.empty())
      return {"backend " + layer.capabilities().name + ": no samples", msg::FAILURE_INTERNAL};
    if (std::string why = CheckStreamLength(layer.actual_scene(), got.samples); !why.empty())
      return {"backend " + layer.capabilities().name + ": " + why, msg::FAILURE_INTERNAL};
    return {};
  }

  void FinishEarlyFailure(const msg::TrialCommand& c, const Stopped& early, const TrialStream& out,
                          const ExecuteOutcome& outcome, Clock::time_point started) {
    auto s = BaseStatus(c, msg::STATE_FAILED);
    s.failure(early.kind);
    s.reason(early.reason);
    s.samples(static_cast<std::uint32_t>(out.sent()));  // already in the log (not a trial)
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    s.detail_json(json({{"backend", layer.capabilities().name},
                        {"defects_applied", internal::AppliedDefectsTree(layer)},
                        {"streamed_samples", out.sent()},
                        {"backend_detail", json::parse(outcome.detail_json, nullptr, false)}})
                      .dump());
    if (out.sent() > 0)
      spdlog::warn("cell {}: trial {} attempt {} failed after {} samples were streamed: {}",
                   options.id, c.trial_id(), c.attempt(), out.sent(), early.reason);
    Finish(c, s);
  }

  // The reader of the commands of the controller registered under `name`
  // (its own topic), made at the first trial that names it.
  dds::Reader<msg::PusherCommand>& ControllerCommands(const std::string& name) {
    auto& reader = pusher_commands[name];
    if (!reader) {
      dds::ReaderOptions o{false, options.id};
      o.controller = name;
      reader = std::make_unique<dds::Reader<msg::PusherCommand>>(participant, o);
    }
    return *reader;
  }

  // The backend can run it (Execute checked closed_loop before ACCEPTED); the
  // defect layer perturbs the scene as for any trial. closed_loop_trial.hpp
  // runs the loop.
  void ExecuteClosedLoop(const msg::TrialCommand& c, const mechanics::Scene& scene,
                         const TrialContext& trial, Clock::time_point started) {
    const std::string& name = scene.pusher->controller->name;
    dds::Reader<msg::PusherCommand>* commands_of = nullptr;
    try {
      commands_of = &ControllerCommands(name);
    } catch (const dds::DdsError& e) {  // the cell's own identity or DDS: not the controller's
      auto s = BaseStatus(c, msg::STATE_FAILED);
      s.failure(msg::FAILURE_INTERNAL);
      s.reason(std::string("controller ") + name + ": cannot read its commands: " + e.what());
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    dds::Reader<msg::PusherCommand>& answers = *commands_of;
    ClosedLoopTrial loop(stream_port, answers, layer, c, trial, scene);
    // The controller must be on the domain, its endpoints matched, before
    // the first sample: a lockstep cell waits for it only hold_s.
    const auto wait = std::chrono::duration_cast<dds::Millis>(
        std::min(std::chrono::duration<double>(ClosedLoopTrial::kControllerWait_s),
                 std::chrono::duration<double>(trial.deadline - Clock::now())));
    if (!participant.WaitForPeer(dds::ControllerParticipantName(name), wait) ||
        !live.WaitForMatched(1, dds::Millis(2000)) ||
        !answers.WaitForMatched(1, dds::Millis(2000))) {
      auto s = BaseStatus(c, msg::STATE_FAILED);
      s.failure(msg::FAILURE_CONTROLLER);  // not the cell's fault: a retry may find it
      s.reason("controller " + name + ": not on domain " + std::to_string(options.domain_id) +
               " (start `arena controller --name " + name + "`)");
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    loop.Start();
    mechanics::SimulationResult result =
        layer.ExecuteClosedLoop(scene, trial,
                                [&](const std::vector<mechanics::TrajectorySample>& samples,
                                    std::string* why) { return loop.Next(samples, why); });
    std::string failure = result.stopped;
    msg::FailureKind kind = failure.empty() ? msg::FAILURE_NONE : loop.stop_kind();
    if (result.status != mechanics::SimulationStatus::kOk) {
      failure = "simulation: " + ModeName(result.status) + ": " + result.error;
      kind = msg::FAILURE_SIMULATION;
    }
    if (result.samples.empty()) {
      auto s = BaseStatus(c, msg::STATE_FAILED);
      s.reason(failure.empty() ? "simulation: no samples" : failure);
      s.failure(failure.empty() ? msg::FAILURE_SIMULATION : kind);
      s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
      return Finish(c, s);
    }
    // The log: every sample, as the closed loop saw it (what the sensors saw,
    // the pusher's state under the command in force), unpaced (the loop
    // itself was paced). A run that ended past its last published sample is
    // taken whole: observed again, its pusher at the last command.
    std::vector<dds::Observation> observed = loop.observed();
    std::vector<dds::PusherState> pushers = loop.pushers();
    if (observed.size() != result.samples.size()) {
      observed = layer.Observe(result.samples, trial);
      mechanics::Scene as_run = layer.actual_scene();
      as_run.pusher->motion = loop.in_force();
      pushers.resize(std::min(pushers.size(), result.samples.size()));
      for (std::size_t i = pushers.size(); i < result.samples.size(); ++i)
        pushers.push_back(PusherAt(as_run, result.samples[i]));
    }
    const StreamOutcome streamed = StreamLog(stream_port, c, result.samples, pushers, observed,
                                             trial.deadline, Pacing::kFlatOut);
    if (failure.empty()) {
      failure = streamed.failure;
      kind = streamed.kind;
    }
    EndedAt(result.samples.back(), observed);
    pusher = scene.pusher;

    auto s = BaseStatus(c, failure.empty() ? msg::STATE_EXECUTED : msg::STATE_FAILED);
    s.reason(failure);
    if (!failure.empty()) s.failure(kind);
    s.samples(static_cast<std::uint32_t>(result.samples.size()));
    s.phase_wall_s(std::chrono::duration<double>(Clock::now() - started).count());
    s.detail_json(loop.Detail(result, streamed.batches).dump());
    if (!failure.empty()) {
      spdlog::warn("cell {}: trial {} attempt {} failed: {}", options.id, c.trial_id(), c.attempt(),
                   failure);
    }
    Finish(c, s);
  }

  // ---- RESET

  void Reset(const msg::TrialCommand& c) {
    const auto started = Clock::now();
    reset::ResetRequest request;
    request.observed_end = observed_pose;
    request.true_end = true_pose;
    std::optional<mechanics::PusherSpec> next_pusher = pusher;
    std::optional<schemas::Fixtures> next_fixtures;  // what the next trial needs mounted
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
      next_fixtures = schemas::FixturesOf(next);
    }
    const std::vector<schemas::FixtureChange> changes =
        next_fixtures ? schemas::ChangesBetween(mounted, *next_fixtures, ChangeCosts())
                      : std::vector<schemas::FixtureChange>{};
    const PusherChange change = ChangeOfPusher(pusher, next_pusher);
    request.swap_pusher = change.swap || ChangesPusher(changes);
    request.pusher_move_m = change.move_m;
    auto accepted = BaseStatus(c, msg::STATE_ACCEPTED);
    Send(accepted);

    BackendResetRequest backend_request;
    backend_request.target = request.target;
    backend_request.observed_end = observed_pose;
    backend_request.swap_pusher = request.swap_pusher;
    backend_request.pusher_move_m = request.pusher_move_m;
    backend_request.next_scene_json = c.scene_json();
    const auto deadline = c.deadline_s() > 0 && std::isfinite(c.deadline_s())
                              ? started + std::chrono::duration_cast<Clock::duration>(
                                              std::chrono::duration<double>(c.deadline_s()))
                              : Clock::time_point::max();
    if (auto own = layer.inner().Reset(backend_request, Context(c, deadline))) {
      if (own->ok && next_fixtures) mounted = next_fixtures;  // the backend changed them itself
      return FinishBackendReset(c, *own, next_pusher, started);
    }
    const reset::ResetOutcome out =
        reset::ExecuteReset(request, reset_params, c.seed(), c.trial_id());
    // The changes of fingers and object come before the reset plan (the
    // pusher's swap is in the plan); the reset's own (simulated) duration
    // is paced like a trial.
    const double change_s = EmulatedChangeSeconds(changes, true);
    if (options.speed > 0) {
      SleepUntil(started +
                 std::chrono::duration_cast<Clock::duration>(
                     std::chrono::duration<double>((change_s + out.time_s) * options.speed)));
    }
    true_pose = out.final_true;
    observed_pose = out.final_observed;
    if (out.success) trial_start.ResetEnded(c.seed(), request.target, out.final_true);
    if (out.success) pusher = next_pusher;
    if (out.success && next_fixtures) mounted = next_fixtures;
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
                        {"pusher_move_m", request.pusher_move_m},
                        {"changes", ChangesJson(changes)},
                        {"change_s", change_s},
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

  // ---- serving: the intake thread reads commands as they come (a claim is
  // never stuck behind a long trial) and queues the served session's for the
  // worker (command_intake.hpp).

  void IntakeLoop() {
    while (!Stopping()) {
      auto command = commands.Take(dds::Millis(100));
      try {
        std::lock_guard<std::mutex> lock(mutex);
        if (intake_state.Expire(Clock::now(), options.id)) Announce();
        if (!command || command->cell_id() != options.id) continue;
        const CommandIntake::Taken taken = intake_state.Take(*command, Clock::now(), options.id);
        if (taken.announce) Announce();
        if (taken.queued) wake.notify_all();
      } catch (const std::exception& e) {
        spdlog::error("cell {}: command intake: {}", options.id, e.what());
      }
    }
  }

  std::optional<msg::TrialCommand> NextCommand() {
    std::unique_lock<std::mutex> lock(mutex);
    wake.wait_for(lock, std::chrono::milliseconds(100),
                  [&] { return stop || !intake_state.empty(); });
    if (stop) return std::nullopt;
    return intake_state.Pop();
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
