// Closed-loop tests (issue 19): a pivot scene whose pusher a controller
// drives, real `arena cell` and `arena controller` processes, a driver that
// plays the service and watches the live topic.
#pragma once

#include <memory>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "test_support.hpp"

namespace arena::test {

// A box held by two patch fingers on the x axis (it pivots about it against
// their torsional friction, so it stops when the pusher stops);
// the pusher on the -y face, 4 cm below the axis, pushes along +y and turns
// the box about +x. pivot_to_angle drives that angle to `target` (rad).
inline std::string PivotScene(double duration_s, double target, double gain, double hold_s) {
  std::ostringstream s;
  s << R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2},
  "gravity": [0, 0, -9.81], "duration": )"
    << duration_s << R"(, "grip_force": 10.0,
  "fingers": [
    {"name": "left",  "type": "patch", "radius": 0.005, "position": [-0.025, 0, 0], "normal": [1, 0, 0], "mu": 0.5},
    {"name": "right", "type": "patch", "radius": 0.005, "position": [0.025, 0, 0], "normal": [-1, 0, 0], "mu": 0.5}],
  "pusher": {"type": "point", "position": [0, -0.015, -0.04], "normal": [0, 1, 0], "mu": 0.3,
             "motion": {"controller": "pivot_to_angle", "target": )"
    << target << R"(, "gain": )" << gain << R"(, "tolerance": 0.02, "hold_s": )" << hold_s << R"(}},
  "model": {"facets": 8, "points": 3, "dt": 0.004, "reduce": "auto"}})";
  return s.str();
}

inline std::unique_ptr<Child> StartProcess(const std::string& what,
                                           const std::vector<std::string>& args) {
  std::vector<std::string> argv = {ARENA_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  const std::string log =
      ::testing::TempDir() + "closed_loop_" + what + "_" + std::to_string(getpid()) + ".log";
  return std::make_unique<Child>(argv, log);
}

inline std::unique_ptr<Child> StartController(int domain, const std::string& name) {
  return StartProcess("controller_" + name,
                      {"controller", "--name", name, "--domain", std::to_string(domain)});
}

inline std::unique_ptr<Child> StartCell(int domain, const std::string& id, double speed,
                                        const std::string& defects = "",
                                        const std::string& backend = "model") {
  std::vector<std::string> args = {
      "cell",      "--id", id, "--domain", std::to_string(domain), "--speed", std::to_string(speed),
      "--backend", backend};
  if (!defects.empty()) {
    const std::string path =
        ::testing::TempDir() + "closed_loop_defects_" + std::to_string(getpid()) + ".json";
    std::ofstream(path) << defects;
    args.push_back("--defects");
    args.push_back(path);
  }
  return StartProcess("cell_" + id, args);
}

// One cell ("c1") and the pivot_to_angle controller as real processes on a
// test domain, with a driver playing the service and a reader of the live
// topic. Ready() waits (bounded) until all of them have found each other.
struct LoopRig {
  LoopRig(int domain, double speed, const std::string& defects = "",
          const std::string& backend = "model")
      : cell(StartCell(domain, "c1", speed, defects, backend)),
        controller(StartController(domain, "pivot_to_angle")),
        driver(domain),
        live(driver.participant, dds::ReaderOptions{false}) {}
  bool Ready() {
    using namespace std::chrono_literals;
    return driver.WaitForCells({"c1"}, 15s) && driver.commands.WaitForMatched(1, 10s) &&
           driver.participant.WaitForPeer("arena.controller.pivot_to_angle", 15s);
  }
  std::unique_ptr<Child> cell, controller;
  Driver driver;
  dds::Reader<msg::LiveState> live;
};

// The closed_loop section of an EXECUTE status's detail.
inline nlohmann::json ClosedLoopDetail(const msg::TrialStatus& s) {
  const auto j = nlohmann::json::parse(s.detail_json(), nullptr, false);
  if (!j.is_object() || !j.contains("closed_loop")) return nlohmann::json();
  return j["closed_loop"];
}

}  // namespace arena::test
