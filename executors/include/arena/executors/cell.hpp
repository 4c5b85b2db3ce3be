// The arena cell: a DDS server that announces itself, executes TrialCommands
// on its backend (backend.hpp: model, mujoco, exec:COMMAND, replay:DATASET),
// wrapped in the defect layer (defect_layer.hpp), and streams ground truth.
//
//   commands (TrialCommand, cell_id == ours)
//        |
//   listener queue --> worker thread: one command at a time
//        EXECUTE: parse scene -> defect layer + backend Prepare (REFUSED + reason)
//                 -> ACCEPTED -> perturb (friction, actuation) -> backend Execute:
//                    each true sample as it arrives -> checked -> observed
//                    (noise, latency, drops) -> LiveState and GroundTruth
//                    batches, paced by speed -> EXECUTED (or FAILED + reason)
//        RESET:   the backend's own reset (a robot), or else: plan from the
//                 observed end pose to the next scene's start -> simulated
//                 execution with retries -> RESET_DONE / FAILED
//   A command whose (trial, attempt, phase) already finished is answered by
//   re-sending the final status; it never runs twice (idempotency).
//
// Thread safety: Stop() may be called from any thread; everything else runs
// on the cell's own worker thread (started in the constructor, joined in the
// destructor).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "arena/executors/backend.hpp"
#include "arena/executors/defects.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/schemas/dds.hpp"

namespace arena::executors {

// The high-fidelity model settings a cell simulates with; a scene asking for
// more (more facets, a smaller step) keeps its own.
struct Fidelity {
  int facets = 16;    // edges of the friction cone
  int points = 5;     // constituent points per line/patch
  double dt = 0.002;  // s
};

struct CellOptions {
  std::string id;  // [A-Za-z0-9_.-]+, unique per deployment
  int domain_id = 0;
  dds::NetworkOptions network;
  DefectProfile defects;
  double speed = 1.0;      // wall s per simulated s: 0 = as fast as possible, 1 = real time
  int batch_samples = 25;  // samples per GroundTruth message, 1..256 (25 = 10 Hz at 250 Hz)
  Fidelity fidelity;
  double participant_lease_s = 2.5;
};

// @throws std::invalid_argument naming the option ("--speed: ...").
void ValidateCellOptions(const CellOptions& options);

// The mechanics a simulated cell runs on. DefaultMechanics() is the real
// library (ParseScene, Simulate); tests may supply closed-form stand-ins.
struct MechanicsBackend {
  std::function<mechanics::Scene(std::string_view)> parse;  // throws mechanics::SceneError
  std::function<mechanics::SimulationResult(const mechanics::Scene&)> simulate;
  // Closed-loop trials (pusher.controller set); empty: the cell refuses them.
  std::function<mechanics::SimulationResult(const mechanics::Scene&,
                                            const mechanics::PusherCommandSource&)>
      simulate_closed_loop;
};
MechanicsBackend DefaultMechanics();
// A MechanicsBackend as a cell Backend (`model`, at least the given fidelity).
std::unique_ptr<Backend> MakeMechanicsStandIn(const MechanicsBackend& mechanics,
                                              const Fidelity& fidelity);

struct CellCounters {
  std::uint64_t executed = 0;
  std::uint64_t resets = 0;
  std::uint64_t refused = 0;
  std::uint64_t failed = 0;
  std::uint64_t duplicates = 0;  // commands answered from the finished table
  std::uint64_t samples = 0;     // ground-truth samples sent
};

class Cell {
 public:
  // Joins the domain, announces the cell and starts the worker.
  // @throws std::invalid_argument for bad options, dds::DdsError when DDS refuses.
  // The `model` backend on these mechanics (tests bring closed-form stand-ins).
  Cell(const CellOptions& options, MechanicsBackend mechanics);
  // Any backend (backend.hpp), wrapped in the defect layer with options.defects.
  // @throws std::invalid_argument also when the backend cannot emulate the
  // profile's defects.
  Cell(const CellOptions& options, std::unique_ptr<Backend> backend);
  Cell(const CellOptions& options, std::unique_ptr<Backend> backend,
       std::function<mechanics::Scene(std::string_view)> parse);
  ~Cell();
  Cell(const Cell&) = delete;
  Cell& operator=(const Cell&) = delete;

  // Asks the worker to stop (a phase in progress ends FAILED "cell shutting
  // down"); returns at once.
  void Stop();
  // Blocks until Stop() was called and the worker finished.
  void Wait();
  CellCounters counters() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arena::executors
