// A closed-loop trial on a cell (issue 19): the pusher follows a controller's
// commands.
//
// Each sample goes out on the live topic; the command answering it moves the
// pusher from the next step on. speed 0: lockstep (the simulation waits for
// the answer to sample k, at most hold_s, before step k+1); speed > 0: wall
// clock (the newest command in force when a step is due). Without a new
// command for hold_s the pusher stops and the phase fails. Every command is
// recorded (the sample it answered, commanded and applied velocity, loop
// time) and goes to the EXECUTE status's detail.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "arena/executors/controller.hpp"
#include "arena/executors/defect_layer.hpp"
#include "trial_stream.hpp"

namespace arena::executors {

class ClosedLoopTrial {
 public:
  // How long a closed-loop trial waits for its controller to appear.
  static constexpr double kControllerWait_s = 5.0;
  // Before its first answer a controller is starting up: its endpoints are
  // matched, but discovery may not have completed on its side (best-effort
  // samples are lost until it has) and its first sample costs it the most.
  // Until then the hold time does not run; this bound does.
  static constexpr double kFirstAnswerWait_s = 2.0;

  // `port` publishes the live samples; `commands` reads the controllers'
  // answers (filtered to this cell). The defect layer has prepared the trial.
  ClosedLoopTrial(const StreamPort& port, dds::Reader<msg::PusherCommand>& commands,
                  const DefectLayer& layer, const msg::TrialCommand& command,
                  const TrialContext& trial, const mechanics::Scene& scene);

  const ControlContext& context() const { return context_; }
  // The loop starts now: answers to earlier trials are dropped.
  void Start();
  // Called by the simulation after every sample: publishes it, gets its
  // answer. nullopt (with *why) stops the run.
  std::optional<mechanics::PusherMotion> Next(
      const std::vector<mechanics::TrajectorySample>& samples, std::string* why);
  // The pusher motion in force at the end (the last applied command).
  const mechanics::PusherMotion& in_force() const { return in_force_; }
  // What the sensors saw of each sample published so far, and the pusher's
  // state at each (its velocity: the command in force while it was made).
  const std::vector<dds::Observation>& observed() const { return observed_; }
  const std::vector<dds::PusherState>& pushers() const { return pushers_; }
  // The EXECUTE status's detail: the model's figures and `closed_loop`.
  nlohmann::json Detail(const mechanics::SimulationResult& result, std::uint32_t log_batches) const;

  // Why Next stopped the run, typed for the service like an open-loop
  // failure (FAILURE_NONE while it runs): the cell shutting down, its
  // deadline, or the controller (gone, silent past its hold time, a bad
  // command: FAILURE_CONTROLLER, no fault of the cell, and a retry may well
  // run through).
  msg::FailureKind stop_kind() const { return stop_kind_; }

 private:
  struct AppliedCommand {
    std::uint32_t sample = 0;  // the sample it answered (applied from the next step)
    double t = 0;              // s, that sample's time
    Eigen::Vector3d commanded = Eigen::Vector3d::Zero();  // m/s, as the controller sent it
    Eigen::Vector3d applied = Eigen::Vector3d::Zero();    // m/s, with the actuation noise
    double loop_ms = -1;  // live sample written -> command accepted (wall), -1: held
  };

  // The newest command of this trial answering a sample <= k (exact: == k),
  // waiting until `until` at most.
  std::optional<msg::PusherCommand> Await(std::uint32_t k, bool exact,
                                          StreamClock::time_point until);
  // How long without a command stops the pusher: the hold time once the
  // controller has answered, kFirstAnswerWait_s (at least) before.
  double HoldLimit() const;
  // The answer to sample k: lockstep waits for it (republishing the sample),
  // wall clock takes the newest until the next sample is due.
  std::optional<msg::PusherCommand> Answer(std::uint32_t k, double t,
                                           const msg::GroundTruthSample& encoded, bool last);
  // A command taken into force; nullopt (with *why) when it is refused.
  std::optional<mechanics::PusherMotion> Apply(const msg::PusherCommand& answer,
                                               AppliedCommand record, std::string* why);
  std::optional<mechanics::PusherMotion> Stop(AppliedCommand record);
  // Records why the run stops; @returns nullopt.
  std::optional<mechanics::PusherMotion> Stopped(msg::FailureKind kind);

  const StreamPort& port_;
  dds::Reader<msg::PusherCommand>& commands_;
  const DefectLayer& layer_;
  const msg::TrialCommand& command_;
  const TrialContext& trial_;
  ControlContext context_;
  std::string params_;  // context_ as JSON, on every live sample
  std::size_t expected_samples_ = 0;
  StreamClock::time_point start_{};
  StreamClock::time_point last_command_at_{};
  bool answered_ = false;  // a command of this trial taken into force
  mechanics::PusherMotion in_force_;
  std::vector<AppliedCommand> applied_;
  std::optional<Observer> observer_;  // from the first sample: the layer's scene is set
  std::vector<dds::Observation> observed_;
  std::vector<dds::PusherState> pushers_;
  msg::FailureKind stop_kind_ = msg::FAILURE_NONE;
};

}  // namespace arena::executors
