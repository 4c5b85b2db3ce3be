// Cell backends: what turns a commanded scene into the true motion of an
// object. A lab implements Backend for its hardware (or writes a driver for
// exec:COMMAND in any language, executors/README.md); arena ships four:
//
//   model            arena's own contact model at the cell's fidelity (the default;
//                    its "truth" is self-consistency, not accuracy)
//   mujoco           MuJoCo 2.2 (simulators/): an independent engine
//   exec:COMMAND     any program speaking the JSON-lines protocol (exec_protocol.hpp)
//   replay:DATASET   the trials of an `arena export` directory, matched by scene
//
// The cell owns everything around the backend, the same for all of them: DDS,
// the duplicate filter (idempotency), deadlines, pacing, batching, and the
// defect layer (defects.hpp) that perturbs the scene and observes the truth
// for simulated backends. A backend sees one call at a time, always from the
// cell's worker thread, in the order Prepare -> Execute, or Reset.
//
//   Prepare(scene, trial)   "" = can run it; otherwise why not (the cell REFUSES)
//   Execute(scene, trial, sink)
//                           streams true samples (own timestamps, strictly
//                           increasing, starting at 0) into sink; returns ok or
//                           a failure reason. sink returns false when the cell
//                           wants it to stop (deadline, shutdown). The cell
//                           sends each sample on as it arrives (live topic,
//                           log): a backend that has samples should give
//                           them at once, not at the end.
//   Reset(request, trial)   bring the object to the requested start pose; a
//                           backend without a reset of its own returns nullopt
//                           and the cell's simulated reset planner does it.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/reset/reset.hpp"

namespace arena::executors {

// What a trial's ground truth is measured against.
enum class TruthSource {
  kSelfConsistency,  // arena's own model (the `model` backend)
  kSimulator,        // an independent engine (mujoco)
  kRobot,            // hardware, through a driver
  kRecorded,         // a dataset recorded elsewhere
  kMeasured,         // real measurements (an imported lab recording): the observed
                     // stream is the truth; there is no separate true stream
};
const char* ToString(TruthSource source);
// @throws std::invalid_argument for an unknown name.
TruthSource ParseTruthSource(std::string_view name);

struct BackendCapabilities {
  std::string name;  // "model", "mujoco", "exec:...", "replay:..."
  TruthSource truth = TruthSource::kSelfConsistency;
  std::string engine;  // e.g. "arena contact model g16_k5", "MuJoCo 2.2.2", the driver's own words
  // The contact types it can run; empty = all.
  std::vector<mechanics::ContactType> contact_types;
  // The defect layer may perturb its scene (friction, pusher velocity) and
  // emulate sensing defects on its truth. False for a robot or recorded data:
  // a campaign asking for emulated defects is then refused, never dropped.
  bool emulates_defects = true;
  std::string settings_json = "{}";  // the backend's own settings, stored with its trials
  // It can run closed-loop scenes (pusher.motion {"controller": NAME}, issue
  // 19): SimulateClosedLoop steps its model with the commanded pusher
  // velocities. Only arena's own model can (`model`); the cell refuses a
  // closed-loop scene on any other backend, with the reason.
  bool closed_loop = false;
  // Where its trials take place, when the backend knows (a recording: around
  // every recorded start and pusher path, in the lab's frame). A cell whose
  // profile leaves the workspace at its default takes this one; a profile
  // that sets a workspace keeps it.
  std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> workspace;
};

// What a prepared trial's truth holds beside its kind (TruthSource). A
// measured recording may lack its contact forces (not recorded, or the
// stream failed its import check): its samples then carry no contacts, and
// that is a stated fact of the trial, never inferred from the absence. Only
// a kMeasured backend may say so (the cell refuses it from any other).
struct TrialTruth {
  bool forces_measured = true;
  std::string forces_note;  // why not, when !forces_measured (e.g. the import check that failed)
};
// The stored kind of a trial's truth (trials.truth): "measured" for a
// measured trial with its forces, dds::kTruthMeasuredNoForces for one
// without (poses scored, forces never); otherwise ToString(source).
std::string StoredTruth(TruthSource source, const TrialTruth& truth);

struct TrialContext {
  std::uint64_t trial_id = 0;
  std::uint32_t attempt = 0;
  std::uint64_t seed = 0;
  std::string_view scene_json;  // the scene as commanded (a driver may want the text)
  // Wall-clock time by which the phase must end (time_point::max() = none).
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
  // Set by the cell during Execute (may be empty): a backend whose samples
  // come over time (a driver, hardware) calls it while it waits for more
  // (exec: after 50 ms without a line), and the cell sends the samples it
  // still holds into the log. From the worker thread, like every call.
  std::function<void()> idle;
};

// Why a backend's true sample is unusable ("" = fine): NaN or infinite
// values, a non-unit quaternion, a first t other than 0, t not increasing, a
// contact count other than the scene's (fingers, then the pusher), or, for a
// trial whose truth measured no forces (`truth`), any contact at all. The
// cell applies it to every sample a backend streams.
std::string CheckTrueSample(const mechanics::TrajectorySample& sample,
                            const std::vector<mechanics::TrajectorySample>& before,
                            const mechanics::Scene& scene, const TrialTruth& truth = {});

// Returns false when the backend must stop streaming.
using SampleSink = std::function<bool(const mechanics::TrajectorySample&)>;

// Why a backend's Execute failed, typed for the service (the cell sends it as
// TrialStatus.failure; nobody parses the reason's words).
enum class ExecuteFailure {
  kNone,
  kSimulation,  // a deterministic model failure: a re-run fails the same way (the trial fails)
  kBackend,     // the backend (a driver, hardware, a dataset) failed: a re-run may do better
};

struct ExecuteOutcome {
  bool ok = false;
  std::string reason;  // why not ok ("simulation: ...", "driver: ...")
  // Set by a simulator's failure; a !ok outcome left at kNone is the backend's (kBackend).
  ExecuteFailure failure = ExecuteFailure::kNone;
  std::string detail_json = "{}";  // backend statistics stored with the trial
  double simulate_wall_s = 0;
};

struct BackendResetRequest {
  reset::Pose target;           // the next trial's start pose (gripper frame)
  reset::Pose observed_end;     // where the cell last saw the object
  bool swap_pusher = false;     // the next trial needs another pusher
  double pusher_move_m = 0;     // or the same pusher, moved this far (m)
  std::string next_scene_json;  // "" = nominal
};
struct BackendResetOutcome {
  bool ok = false;
  reset::Pose achieved;  // the object's pose after the reset (as measured)
  int attempts = 0;
  std::string reason;  // why not ok
  double time_s = 0;   // how long it took (s)
};

class Backend {
 public:
  virtual ~Backend() = default;
  virtual BackendCapabilities Capabilities() const = 0;
  // "" = it can run the scene; otherwise the reason the cell refuses it with.
  virtual std::string Prepare(const mechanics::Scene& scene, const TrialContext& trial) = 0;
  virtual ExecuteOutcome Execute(const mechanics::Scene& scene, const TrialContext& trial,
                                 const SampleSink& sink) = 0;
  // What the truth of the trial the last Prepare accepted holds (a measured
  // recording may lack forces); the default: everything the scene has.
  virtual TrialTruth PreparedTruth() const { return {}; }
  // nullopt: the backend has no reset of its own (simulated physics, replay);
  // the cell then plans and simulates the reset itself (reset/).
  virtual std::optional<BackendResetOutcome> Reset(const BackendResetRequest& request,
                                                   const TrialContext& trial) {
    (void)request;
    (void)trial;
    return std::nullopt;
  }
  // Closed loop (issue 19; only called when Capabilities().closed_loop): the
  // scene with its pusher motion taken from `commands` after every sample.
  // The default cannot (kInvalidScene with the reason).
  virtual mechanics::SimulationResult SimulateClosedLoop(
      const mechanics::Scene& scene, const mechanics::PusherCommandSource& commands) {
    (void)scene;
    (void)commands;
    mechanics::SimulationResult r;
    r.status = mechanics::SimulationStatus::kInvalidScene;
    r.error = "this backend cannot run closed-loop scenes";
    return r;
  }
};

// A backend on a simulator (simulators/): `model` (arena at the cell's
// fidelity, at least) or `mujoco`.
struct ModelFidelity {
  int facets = 16;
  int points = 5;
  double dt = 0.002;
};
std::unique_ptr<Backend> MakeModelBackend(const ModelFidelity& fidelity);
// settings_json: MuJoCo settings (simulators::MakeSimulator), "" = defaults.
std::unique_ptr<Backend> MakeMujocoBackend(std::string_view settings_json = "");

// exec:COMMAND (exec_backend.cpp) and replay:DATASET (replay_backend.cpp).
struct ExecBackendOptions {
  std::string command;          // run by /bin/sh -c
  double hello_timeout_s = 10;  // the driver must say hello within this
  double reply_timeout_s = 30;  // max silence while a phase runs (besides the cell's deadline)
  std::string log_path;         // the driver's stderr goes here ("" = the cell's stderr)
};
std::unique_ptr<Backend> MakeExecBackend(const ExecBackendOptions& options);
// @throws std::invalid_argument naming the dataset and what is wrong with it.
std::unique_ptr<Backend> MakeReplayBackend(const std::string& dataset_dir);

// "model", "mujoco", "exec:COMMAND", "replay:DIR".
// @throws std::invalid_argument ("--backend: ...") for an unknown or unusable name.
std::unique_ptr<Backend> MakeBackend(std::string_view spec, const ModelFidelity& fidelity,
                                     std::string_view settings_json = "");

}  // namespace arena::executors
