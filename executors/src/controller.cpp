// Closed-loop controllers: arena's own laws, their scoring, and the host that
// answers LiveState samples with PusherCommands (controller.hpp).
#include "arena/executors/controller.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <optional>
#include <stdexcept>
#include <thread>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/mechanics/model.hpp"
#include "arena/schemas/arena.h"
#include "arena/schemas/ground_truth.hpp"
#include "clock.hpp"
#include "vector_json.hpp"

namespace arena::executors {
namespace {

using nlohmann::json;

using internal::Vec;

Eigen::Vector3d ReadVec(const json& j, const char* key) {
  if (!j.contains(key) || !j[key].is_array() || j[key].size() != 3)
    throw std::invalid_argument(std::string("controller_params.") + key + ": must be [x, y, z]");
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) {
    if (!j[key][k].is_number())
      throw std::invalid_argument(std::string("controller_params.") + key + ": not a number");
    v[k] = j[key][k].get<double>();
  }
  if (!v.allFinite())
    throw std::invalid_argument(std::string("controller_params.") + key + ": not finite");
  return v;
}

double ReadNumber(const json& j, const char* key) {
  if (!j.contains(key) || !j[key].is_number())
    throw std::invalid_argument(std::string("controller_params.") + key + ": must be a number");
  const double x = j[key].get<double>();
  if (!std::isfinite(x))
    throw std::invalid_argument(std::string("controller_params.") + key + ": not finite");
  return x;
}

// Signed rotation about `axis` of q relative to q0 (swing-twist decomposition).
double AngleAbout(const Eigen::Vector3d& axis, const Eigen::Quaterniond& q0,
                  const Eigen::Quaterniond& q) {
  const Eigen::Quaterniond rel = q * q0.conjugate();
  return 2.0 * std::atan2(rel.vec().dot(axis), rel.w());
}

// A proportional push along the context's direction that never pulls.
class Proportional : public Controller {
 public:
  Proportional(std::string law, const ControlContext& context)
      : law_(std::move(law)), context_(context) {}
  mechanics::PusherMotion Command(const ControlInput& in) override {
    if (in.observed_valid) {
      const auto error =
          ControlError(law_, context_, in.observed_position, in.observed_orientation);
      if (error) {
        done_ = std::abs(*error) <= context_.spec.tolerance;
        const double speed = std::clamp(context_.spec.gain * *error, 0.0, context_.max_speed);
        last_.velocity = speed * context_.direction;
      }
    }
    return last_;  // a dropped sample: hold
  }
  bool Done() const override { return done_; }

 private:
  std::string law_;
  ControlContext context_;
  mechanics::PusherMotion last_;
  bool done_ = false;
};

}  // namespace

std::string ControlContextToJson(const ControlContext& c) {
  const auto& q = c.start_orientation;
  return json({{"controller", c.spec.name},
               {"target", c.spec.target},
               {"gain", c.spec.gain},
               {"tolerance", c.spec.tolerance},
               {"hold_s", c.spec.hold_s},
               {"direction", Vec(c.direction)},
               {"axis", Vec(c.axis)},
               {"start_position", Vec(c.start_position)},
               {"start_orientation", json::array({q.w(), q.x(), q.y(), q.z()})},
               {"max_speed", c.max_speed}})
      .dump();
}

ControlContext ControlContextFromJson(const std::string& text) {
  const json j = json::parse(text, nullptr, false);
  if (!j.is_object()) throw std::invalid_argument("controller_params: not a JSON object");
  ControlContext c;
  if (!j.contains("controller") || !j["controller"].is_string())
    throw std::invalid_argument("controller_params.controller: must be a string");
  c.spec.name = j["controller"].get<std::string>();
  c.spec.target = ReadNumber(j, "target");
  c.spec.gain = ReadNumber(j, "gain");
  c.spec.tolerance = ReadNumber(j, "tolerance");
  c.spec.hold_s = ReadNumber(j, "hold_s");
  c.direction = ReadVec(j, "direction");
  c.axis = ReadVec(j, "axis");
  c.start_position = ReadVec(j, "start_position");
  const json& q = j.contains("start_orientation") ? j["start_orientation"] : json();
  if (!q.is_array() || q.size() != 4 || !q[0].is_number() || !q[1].is_number() ||
      !q[2].is_number() || !q[3].is_number())
    throw std::invalid_argument("controller_params.start_orientation: must be [w, x, y, z]");
  c.start_orientation = Eigen::Quaterniond(q[0].get<double>(), q[1].get<double>(),
                                           q[2].get<double>(), q[3].get<double>());
  c.max_speed = ReadNumber(j, "max_speed");
  return c;
}

ControlContext MakeControlContext(const mechanics::Scene& scene, double max_speed) {
  ControlContext c;
  if (!scene.pusher || !scene.pusher->controller)
    throw std::invalid_argument("pusher.motion.controller: the scene is not closed-loop");
  c.spec = *scene.pusher->controller;
  c.max_speed = max_speed;
  c.direction = scene.pusher->normal.normalized();
  const Eigen::Matrix3d R = mechanics::RotationFromRpy(scene.object.pose.rpy);
  c.start_position = scene.object.pose.position;
  c.start_orientation = Eigen::Quaterniond(R);
  // The object turns about the grip axis (through the fingers) when pushed:
  // the sign is that of the push's moment about the fingers' midpoint.
  Eigen::Vector3d pivot = scene.object.pose.position;
  if (!scene.fingers.empty()) {
    pivot.setZero();
    for (const auto& f : scene.fingers) pivot += f.position;
    pivot /= static_cast<double>(scene.fingers.size());
  }
  const Eigen::Vector3d moment = (scene.pusher->position - pivot).cross(c.direction);
  if (!scene.fingers.empty() && std::abs(moment.dot(scene.fingers[0].normal)) > 1e-12) {
    const Eigen::Vector3d g = scene.fingers[0].normal.normalized();
    c.axis = moment.dot(g) > 0 ? g : Eigen::Vector3d(-g);
  } else if (moment.norm() > 1e-12) {
    c.axis = moment.normalized();
  }
  return c;
}

std::vector<std::string> LibraryLaws() { return {"pivot_to_angle", "sliding_to_position"}; }

std::unique_ptr<Controller> MakeLibraryController(const std::string& law,
                                                  const ControlContext& context) {
  const auto laws = LibraryLaws();
  if (std::find(laws.begin(), laws.end(), law) == laws.end()) return nullptr;
  return std::make_unique<Proportional>(law, context);
}

std::optional<double> ControlError(const std::string& law, const ControlContext& c,
                                   const Eigen::Vector3d& position,
                                   const Eigen::Quaterniond& orientation) {
  if (law == "pivot_to_angle")
    return c.spec.target - AngleAbout(c.axis, c.start_orientation, orientation);
  if (law == "sliding_to_position")
    return c.spec.target - (position - c.start_position).dot(c.direction);
  return std::nullopt;
}

ControlOutcome ScoreControl(const std::string& law, const ControlContext& c,
                            const std::vector<mechanics::TrajectorySample>& truth) {
  ControlOutcome out;
  if (truth.empty() ||
      !ControlError(law, c, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity()))
    return out;
  out.scored = true;
  double settled_since = -1;
  for (const auto& s : truth) {
    const double e = *ControlError(law, c, s.position, s.orientation);
    out.final_error = e;
    if (std::abs(e) <= c.spec.tolerance) {
      if (settled_since < 0) settled_since = s.t;
    } else {
      settled_since = -1;
    }
  }
  out.reached = std::abs(out.final_error) <= c.spec.tolerance;
  out.settle_time_s = settled_since;
  return out;
}

// ---------------------------------------------------------------------------
// The host

namespace {

using internal::UnixNanos;

struct Running {
  std::uint64_t trial = 0;
  std::uint32_t attempt = 0;
  ControlContext context;
  std::unique_ptr<Controller> controller;
  bool failed = false;  // the factory refused this trial: ignore it
  // The last sample answered and the answer: a lockstep cell re-publishes a
  // sample it has no answer to (best-effort may lose either message), and the
  // same answer goes out again without asking the law twice.
  std::optional<std::uint32_t> answered;
  msg::PusherCommand last;
};

}  // namespace

ControllerCounters RunController(const ControllerHostOptions& o, const ControllerFactory& factory,
                                 const std::atomic<bool>* stop) {
  if (o.name.empty() || o.name.size() > 64)
    throw std::invalid_argument("--name: must be 1..64 characters");
  for (char ch : o.name) {
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-' || ch == '.'))
      throw std::invalid_argument("--name: only letters, digits, '_', '-' and '.' are allowed");
  }
  dds::ParticipantOptions po;
  po.domain_id = o.domain_id;
  po.name = dds::ControllerParticipantName(o.name);
  po.network = o.network;
  po.lease_s = o.participant_lease_s;
  dds::Participant participant(po);
  dds::Reader<msg::LiveState> live(participant, dds::ReaderOptions{false});
  // Commands go on this name's own topic, which cells running its scenes
  // read; under DDS-Security only an identity issued for this name may
  // publish there (a SecurityError naming the binding otherwise).
  dds::WriterOptions wo;
  wo.controller = o.name;
  { dds::Writer<msg::PusherCommand> allowed(participant, wo); }  // refused at once if not
  // One controller per name: a second one would answer the same samples
  // with another law. The name is claimed before the writer cells wait for
  // exists, so no trial starts on a controller that is still claiming it.
  if (const auto holder = participant.WaitForNamesake(
          std::chrono::duration_cast<dds::Millis>(std::chrono::duration<double>(o.claim_wait_s)))) {
    throw ControllerNameConflict(
        "--name: controller '" + o.name + "' is registered already on domain " +
        std::to_string(o.domain_id) + " by another controller (" + po.name + ", " + *holder +
        "); stop that one or choose another name");
  }
  dds::Writer<msg::PusherCommand> commands(participant, wo);
  spdlog::info("controller {}: up on domain {}", o.name, o.domain_id);

  ControllerCounters counters;
  std::map<std::string, Running> cells;  // per cell: the trial attempt in progress
  while (stop == nullptr || !stop->load()) {
    auto state = live.Take(dds::Millis(100));
    if (!state || !state->closed_loop() || state->controller() != o.name) continue;
    // A new trial attempt on this cell gets a fresh Running (built in place).
    auto found = cells.find(state->cell_id());
    if (found != cells.end() &&
        (found->second.trial != state->trial_id() || found->second.attempt != state->attempt())) {
      cells.erase(found);
      found = cells.end();
    }
    const bool fresh = found == cells.end();
    Running& run = cells[state->cell_id()];
    if (fresh) {
      run.trial = state->trial_id();
      run.attempt = state->attempt();
      try {
        run.context = ControlContextFromJson(state->controller_params());
        run.controller = factory(run.context);
      } catch (const std::exception& e) {
        spdlog::error("controller {}: trial {} on {}: {}", o.name, run.trial, state->cell_id(),
                      e.what());
      }
      run.failed = run.controller == nullptr;
      if (!run.failed) ++counters.trials;
    }
    if (run.failed) continue;
    if (run.answered && *run.answered == state->sample()) {
      run.last.sent_unix_ns(UnixNanos());
      commands.Write(run.last);
      continue;
    }
    mechanics::TrajectorySample truth;
    dds::Observation observed;
    if (!dds::CheckSample(state->state()).empty()) continue;  // malformed: no answer
    truth = dds::DecodeSample(state->state(), nullptr, &observed);
    ControlInput in;
    in.trial_id = state->trial_id();
    in.attempt = state->attempt();
    in.sample = state->sample();
    in.t = truth.t;
    in.truth = truth;
    in.observed_valid = observed.valid;
    in.observed_t = observed.t;
    in.observed_position = observed.position;
    in.observed_orientation = observed.orientation;
    in.context = &run.context;
    const mechanics::PusherMotion m = run.controller->Command(in);
    msg::PusherCommand c;
    c.cell_id(state->cell_id());
    c.trial_id(state->trial_id());
    c.attempt(state->attempt());
    c.answers_sample(state->sample());
    c.controller(o.name);
    c.velocity() = {m.velocity.x(), m.velocity.y(), m.velocity.z()};
    c.angular_velocity() = {m.angular_velocity.x(), m.angular_velocity.y(), m.angular_velocity.z()};
    c.done(run.controller->Done());
    c.state_sent_unix_ns(state->sent_unix_ns());
    c.sent_unix_ns(UnixNanos());
    commands.Write(c);
    run.answered = state->sample();
    run.last = c;
    ++counters.samples;
  }
  counters.live = live.counters();
  return counters;
}

}  // namespace arena::executors
