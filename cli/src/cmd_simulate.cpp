// arena simulate SCENE.json [--facets G --points K --dt S --reduce MODE]
//                           [--contacts tracked|fixed] [--trajectory FILE.csv]
// The contract is docs/scene.md: one JSON object on stdout; ok=false and a
// non-zero exit on any error.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <optional>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/mechanics/frames.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "commands.hpp"
#include "output_guard.hpp"

namespace arena::cli {
namespace {

using mechanics::ContactMode;
using nlohmann::json;

struct SimulateOptions {
  std::string scene_path;
  std::optional<int> facets;
  std::optional<int> points;
  std::optional<double> dt;
  std::optional<std::string> reduce;
  std::optional<std::string> contacts;
  std::string trajectory_path;
};

json Vec(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// Roll-pitch-yaw about fixed x, y, z (R = Rz(yaw) Ry(pitch) Rx(roll)).
Eigen::Vector3d Rpy(const Eigen::Quaterniond& q) {
  return mechanics::RpyFromRotation(q.normalized().toRotationMatrix());
}

int PrintError(const std::string& error, int exit_code) {
  std::printf("%s\n", json({{"ok", false}, {"error", error}}).dump().c_str());
  return exit_code;
}

void WriteTrajectory(const std::string& path, const mechanics::Scene& scene,
                     const mechanics::SimulationResult& result) {
  std::ofstream out(path);
  // An output that cannot be written is a failed command (README: exit 1), not bad input.
  if (!out)
    throw CommandError(kExitFailure, "--trajectory: cannot write '" + path +
                                         "': " + std::strerror(errno) +
                                         " (does its directory exist and is it writable?)");
  out << "t,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz,pusher_fx,pusher_fy,pusher_fz";
  std::vector<std::string> names;
  for (const auto& f : scene.fingers) names.push_back(f.name);
  if (scene.pusher) names.push_back("pusher");
  for (const auto& n : names) out << ',' << n << "_fn," << n << "_ft," << n << "_mode";
  // Appended (docs/scene.md): per contact whether it touches and where, in
  // the object frame.
  for (const auto& n : names) {
    out << ',' << n << "_touching," << n << "_px," << n << "_py," << n << "_pz";
  }
  // Appended (issue 26): each contact's force and torque on the object in G
  // under the names `arena export` gives them (<name>_fx..fz, <name>_tx..tz);
  // the pusher's force is the pusher_fx..fz above, so only its torque is new.
  for (const auto& n : names) {
    if (n != "pusher") out << ',' << n << "_fx," << n << "_fy," << n << "_fz";
    out << ',' << n << "_tx," << n << "_ty," << n << "_tz";
  }
  const auto normals = [&] {
    std::vector<Eigen::Vector3d> v;
    for (const auto& f : scene.fingers) v.push_back(f.normal.normalized());
    if (scene.pusher) v.push_back(scene.pusher->normal.normalized());
    return v;
  }();
  out << '\n' << std::setprecision(10);
  for (const auto& s : result.samples) {
    const auto& q = s.orientation;
    out << s.t << ',' << s.position.x() << ',' << s.position.y() << ',' << s.position.z() << ','
        << q.w() << ',' << q.x() << ',' << q.y() << ',' << q.z() << ',' << s.velocity.x() << ','
        << s.velocity.y() << ',' << s.velocity.z() << ',' << s.angular_velocity.x() << ','
        << s.angular_velocity.y() << ',' << s.angular_velocity.z() << ',' << s.pusher_force.x()
        << ',' << s.pusher_force.y() << ',' << s.pusher_force.z();
    for (const auto& c : s.contacts) {
      out << ',' << c.normal_force << ',' << c.tangential_force.norm() << ','
          << mechanics::ToString(c.mode);
    }
    for (const auto& c : s.contacts) {
      out << ',' << (c.touching ? 1 : 0) << ',' << c.point.x() << ',' << c.point.y() << ','
          << c.point.z();
    }
    for (std::size_t i = 0; i < s.contacts.size() && i < names.size(); ++i) {
      const auto& c = s.contacts[i];
      if (names[i] != "pusher") {
        const Eigen::Vector3d f = c.normal_force * normals[i] + c.tangential_force;
        out << ',' << f.x() << ',' << f.y() << ',' << f.z();
      }
      out << ',' << c.torque.x() << ',' << c.torque.y() << ',' << c.torque.z();
    }
    out << '\n';
  }
  if (!out) throw CommandError(kExitFailure, "--trajectory: write to '" + path + "' failed");
}

int RunSimulate(const SimulateOptions& opt) {
  mechanics::Scene scene;
  try {
    scene = mechanics::LoadSceneFile(opt.scene_path);  // refuses > 1 MiB before reading
    if (opt.facets) scene.model.facets = *opt.facets;
    if (opt.points) scene.model.points = *opt.points;
    if (opt.dt) scene.model.dt = *opt.dt;
    if (opt.reduce) {
      if (*opt.reduce == "auto")
        scene.model.reduce = mechanics::Reduce::kAuto;
      else if (*opt.reduce == "full")
        scene.model.reduce = mechanics::Reduce::kFull;
      else if (*opt.reduce == "planar")
        scene.model.reduce = mechanics::Reduce::kPlanar;
      else
        throw mechanics::SceneError("--reduce",
                                    "must be auto, full or planar, got '" + *opt.reduce + "'");
    }
    if (opt.contacts) {
      const auto parsed = mechanics::ContactTrackingFromString(*opt.contacts);
      if (!parsed) {
        throw mechanics::SceneError("--contacts",
                                    "must be tracked or fixed, got '" + *opt.contacts + "'");
      }
      scene.model.contacts = *parsed;
    }
    mechanics::ValidateScene(scene);  // the overrides too
  } catch (const mechanics::SceneError& e) {
    return PrintError(e.what(), kExitBadInput);
  } catch (const CommandError& e) {
    return PrintError(e.what(), e.exit_code());
  }

  if (!opt.trajectory_path.empty()) {
    try {
      RefuseToOverwriteStore(opt.trajectory_path, "--trajectory");
    } catch (const CommandError& e) {
      return PrintError(e.what(), e.exit_code());
    }
  }
  const mechanics::SimulationResult result = mechanics::Simulate(scene);
  if (result.status != mechanics::SimulationStatus::kOk) {
    return PrintError(result.error, result.status == mechanics::SimulationStatus::kInvalidScene
                                        ? kExitBadInput
                                        : kExitFailure);
  }
  if (!opt.trajectory_path.empty()) {
    try {
      WriteTrajectory(opt.trajectory_path, scene, result);
    } catch (const CommandError& e) {
      return PrintError(e.what(), e.exit_code());
    }
  }

  const auto& last = result.samples.back();
  json contacts = json::array();
  for (size_t i = 0; i < last.contacts.size(); ++i) {
    const auto& c = last.contacts[i];
    const std::string name = i < scene.fingers.size() ? scene.fingers[i].name : "pusher";
    contacts.push_back({{"name", name},
                        {"mode", mechanics::ToString(c.mode)},
                        {"normal_force", c.normal_force},
                        {"tangential_force", Vec(c.tangential_force)},
                        {"touching", c.touching},
                        {"point", Vec(c.point)}});
  }
  Eigen::Vector3d mean_pusher = Eigen::Vector3d::Zero();
  double max_pusher = 0;
  for (const auto& s : result.samples) {
    mean_pusher += s.pusher_force;
    max_pusher = std::max(max_pusher, s.pusher_force.norm());
  }
  mean_pusher /= static_cast<double>(result.samples.size());

  json out = {{"ok", true},
              {"model",
               {{"dof", result.model.dof},
                {"facets", result.model.facets},
                {"points", result.model.points},
                {"dt", result.model.dt},
                {"unknowns", result.model.unknowns},
                {"contacts", mechanics::ToString(scene.model.contacts)},
                {"inertia", mechanics::ToString(result.model.inertia)}}},
              {"final",
               {{"position", Vec(last.position)},
                {"rpy", Vec(Rpy(last.orientation))},
                {"velocity", json::array({last.velocity.x(), last.velocity.y(), last.velocity.z(),
                                          last.angular_velocity.x(), last.angular_velocity.y(),
                                          last.angular_velocity.z()})}}},
              {"pusher_force", {{"mean", Vec(mean_pusher)}, {"max_norm", max_pusher}}},
              {"contacts", contacts},
              {"residuals",
               {{"force_balance", result.residuals.force_balance},
                {"complementarity", result.residuals.complementarity},
                {"cone", result.residuals.cone}}},
              {"solver", json::parse(mechanics::SolverStatisticsJson(result.solver))},
              {"grasp",
               {{"status", mechanics::ToString(result.grasp)},
                {"changed_t", result.grasp_changed_t},
                {"note", result.grasp_note}}},
              {"oscillation", json::parse(mechanics::OscillationJson(result.oscillation))},
              {"impact", json::parse(mechanics::ImpactJson(result.impact))},
              {"steered_slip", json::parse(mechanics::SteeredSlipJson(result.steered_slip))},
              {"wall_s", result.wall_s}};
  std::printf("%s\n", out.dump().c_str());
  return kExitOk;
}

}  // namespace

void AddSimulateCommand(CLI::App& app, Action* action) {
  auto opt = std::make_shared<SimulateOptions>();
  CLI::App* cmd = app.add_subcommand("simulate", "Simulate one scene with the contact model");
  cmd->footer(
      "Example:\n  arena simulate examples/scenes/canonical.json --facets 16 --trajectory out.csv\n"
      "Prints one JSON object (docs/scene.md); exit 0 on success, 2 on a bad scene, 1 on a solver "
      "failure.");
  cmd->add_option("scene", opt->scene_path, "Scene JSON file (docs/scene.md)")->required();
  cmd->add_option("--facets", opt->facets,
                  "Edges of the polyhedral friction cone (overrides model.facets)");
  cmd->add_option("--points", opt->points,
                  "Constituent points per line/patch (overrides model.points)");
  cmd->add_option("--dt", opt->dt, "Time step in s (overrides model.dt)");
  cmd->add_option("--reduce", opt->reduce, "auto, full or planar (overrides model.reduce)");
  cmd->add_option("--contacts", opt->contacts,
                  "tracked or fixed: contact geometry follows the object, or stays frozen "
                  "(overrides model.contacts)");
  cmd->add_option("--trajectory", opt->trajectory_path, "Write the 250 Hz trajectory as CSV");
  cmd->callback([opt, action] { *action = [opt] { return RunSimulate(*opt); }; });
}

}  // namespace arena::cli
