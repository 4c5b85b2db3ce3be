// Closed-loop controllers (issue 19): a controller reads the LiveState topic
// (one message per sample: the true state and what the sensors saw) and
// answers each sample of a closed-loop trial with a pusher command on the
// PusherCommand topic. A cell running a scene whose pusher motion is
// {"controller": NAME, ...} applies the answers of the controller registered
// under NAME (docs/live_control.md).
//
// Writing your own controller: derive from Controller, then host it with
// RunController() (or `arena controller --name NAME --law LAW` for the laws
// of arena's own library, MakeLibraryController()):
//
//   class MyLaw : public arena::executors::Controller {
//    public:
//     arena::mechanics::PusherMotion Command(const arena::executors::ControlInput& in) override {
//       arena::mechanics::PusherMotion m;
//       if (in.observed_valid) m.velocity = 0.01 * in.context->direction;
//       return m;
//     }
//   };
//   ControllerHostOptions o;  o.name = "mine";  o.domain_id = 7;
//   RunController(o, [](const ControlContext&) { return std::make_unique<MyLaw>(); }, &stop);
//
// Commands are in the gripper frame: the pusher's velocity (m/s) and its
// angular velocity (rad/s, which must equal the scene's: the model turns the
// pusher at a constant rate only). A command faster than the cell's
// max_pusher_speed fails the phase. One Controller object serves one trial
// attempt; the host makes a new one when a new trial starts.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arena/errors/error.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/schemas/dds.hpp"

namespace arena::executors {

// What the cell tells a controller about the trial (LiveState.controller_params,
// a JSON object): the scene's controller settings plus the geometry a law
// needs, all in the gripper frame.
struct ControlContext {
  mechanics::PusherController spec;  // name, target, gain, tolerance, hold_s
  // The way the pusher pushes (unit, its contact normal into the object).
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();
  // The axis the object turns about when pushed (unit): the sign that makes
  // a push increase the angle.
  Eigen::Vector3d axis = Eigen::Vector3d::UnitY();
  Eigen::Vector3d start_position = Eigen::Vector3d::Zero();  // object at t = 0 (m)
  Eigen::Quaterniond start_orientation = Eigen::Quaterniond::Identity();
  double max_speed = 0.5;  // m/s, the cell's limit
};
std::string ControlContextToJson(const ControlContext& context);
// @throws std::invalid_argument naming the field.
ControlContext ControlContextFromJson(const std::string& json_text);
// The context of a closed-loop scene (scene.pusher->controller set).
ControlContext MakeControlContext(const mechanics::Scene& scene, double max_speed);

// One sample as a controller sees it.
struct ControlInput {
  std::uint64_t trial_id = 0;
  std::uint32_t attempt = 0;
  std::uint32_t sample = 0;
  double t = 0;                       // s since the phase started
  mechanics::TrajectorySample truth;  // the true state (ground truth)
  bool observed_valid = false;        // false: the sensors dropped this sample
  double observed_t = 0;              // when the reading was taken (t - latency)
  Eigen::Vector3d observed_position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond observed_orientation = Eigen::Quaterniond::Identity();
  const ControlContext* context = nullptr;  // never null in Command()
};

class Controller {
 public:
  virtual ~Controller() = default;
  // The pusher motion answering `in`; called once per sample, in order.
  virtual mechanics::PusherMotion Command(const ControlInput& in) = 0;
  // True once the goal is reached (informative: PusherCommand.done).
  virtual bool Done() const { return false; }
};

// Laws of arena's own library, by name:
//   "pivot_to_angle"       speed = gain * (target - angle) along `direction`
//                          (rad -> m/s), angle the observed rotation about
//                          `axis` since t = 0; never pulls (speed >= 0),
//                          capped at max_speed.
//   "sliding_to_position"  speed = gain * (target - d) along `direction`
//                          (m -> m/s), d the observed travel of the object
//                          along `direction` since t = 0; same limits.
// Both hold the last command when a sample is dropped.
// @returns nullptr for an unknown name.
std::unique_ptr<Controller> MakeLibraryController(const std::string& law,
                                                  const ControlContext& context);
std::vector<std::string> LibraryLaws();

// The error a library law drives to zero, from a state (its units: rad for
// pivot_to_angle, m for sliding_to_position); nullopt for an unknown law.
std::optional<double> ControlError(const std::string& law, const ControlContext& context,
                                   const Eigen::Vector3d& position,
                                   const Eigen::Quaterniond& orientation);

// The controller's own success over a trial's true samples.
struct ControlOutcome {
  bool scored = false;        // false: not a library law (nothing below is set)
  bool reached = false;       // |error| <= tolerance at the end
  double final_error = 0;     // at the last sample
  double settle_time_s = -1;  // first t after which |error| stays <= tolerance; -1: never
};
ControlOutcome ScoreControl(const std::string& law, const ControlContext& context,
                            const std::vector<mechanics::TrajectorySample>& truth);

struct ControllerHostOptions {
  std::string name;  // registered name: answers LiveState samples naming it
  int domain_id = 0;
  dds::NetworkOptions network;
  double participant_lease_s = 2.5;
  // How long it looks for another controller of the same name on the
  // domain before answering anything (ControllerNameConflict).
  double claim_wait_s = 1.0;
};

// Another controller holds the name on the domain: what() names the name,
// the domain and the other controller ("pid P on host H").
class ControllerNameConflict : public Error {
 public:
  explicit ControllerNameConflict(const std::string& what)
      : Error(ErrorCategory::kBadInput, what) {}
};

struct ControllerCounters {
  std::uint64_t samples = 0;  // closed-loop samples answered
  std::uint64_t trials = 0;   // trial attempts seen
  dds::ReaderCounters live;   // the LiveState reader's (superseded: samples it fell behind on)
};

using ControllerFactory = std::function<std::unique_ptr<Controller>(const ControlContext&)>;

// Joins the domain as "arena.controller.<name>" and answers every closed-loop
// LiveState sample naming `name` until *stop is true. Each new trial attempt
// (per cell) gets a fresh Controller from the factory.
// Commands go on the name's own topic (dds::ControllerTopic); under
// DDS-Security only an identity issued for the name may publish there.
// @throws dds::DdsError when DDS refuses (dds::SecurityError: the identity is
// not this name's), std::invalid_argument for a bad name,
// ControllerNameConflict when another controller holds the name.
ControllerCounters RunController(const ControllerHostOptions& options,
                                 const ControllerFactory& factory, const std::atomic<bool>* stop);

}  // namespace arena::executors
