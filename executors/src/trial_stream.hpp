// How a trial's samples leave a cell: the reliable GroundTruth log, and the
// LiveState topic beside it (issue 19).
//
// A TrialStream is fed sample by sample as the backend produces them (Push)
// and ended by End. The log takes samples in batches of --batch: a full batch
// leaves when the next sample arrives, a partial one when the backend goes
// quiet (Flush, from TrialContext::idle) or at the end, flagged last. The
// live topic gets every sample when it is due; its `last` sample is sent
// again at the end, when the backend said the trial is over.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/schemas/arena.h"
#include "arena/schemas/dds.hpp"
#include "arena/schemas/ground_truth.hpp"

namespace arena::executors {

using StreamClock = std::chrono::steady_clock;

// The cell's side of a stream: who it is, its writers, and how to wait.
struct StreamPort {
  std::string cell_id;
  int batch_samples = 25;
  double speed = 1.0;          // wall s per simulated s (0: unpaced)
  std::string corrupt_stream;  // fault injection (defects.hpp): "", "gap" or "nan"
  dds::Writer<msg::GroundTruth>* log = nullptr;
  dds::Writer<msg::LiveState>* live = nullptr;
  std::function<bool()> stopping;
  // Sleeps until the time point or the cell stops; false when stopping.
  std::function<bool(StreamClock::time_point)> sleep_until;
  // Whether the cell still serves this service session (a superseded
  // session's trial must not reach the log).
  std::function<bool(std::uint64_t)> serves;
  std::function<void(std::size_t)> count_samples;  // samples now in the log
};

// How a trial's samples go out.
enum class Pacing {
  kLive,     // samples leave when due (speed > 0), each on the live topic too
  kFlatOut,  // as fast as the log takes them, log only (closed loop: already live)
};

// One sample on the live topic: best-effort, keep-last 1, never waits.
// `controller` and its `params` are set for a closed-loop trial's samples.
void PublishLive(const StreamPort& port, const msg::TrialCommand& c, std::uint32_t index, bool last,
                 const msg::GroundTruthSample& sample, const std::string& controller = "",
                 const std::string& params = "");

class TrialStream {
 public:
  TrialStream(const StreamPort& port, const msg::TrialCommand& command,
              StreamClock::time_point deadline, Pacing pacing);

  // Takes one sample: paces it, publishes it live, queues it for the log.
  // @returns false when the stream stopped (failure() says why).
  bool Push(const mechanics::Scene& actual, const mechanics::TrajectorySample& truth,
            const dds::Observation& observed);
  // The same with the pusher's state given (a closed loop's changes with
  // every command; `actual`'s constant motion would give the last one).
  bool Push(const mechanics::TrajectorySample& truth, const dds::PusherState& pusher,
            const dds::Observation& observed);
  // What the log queue holds leaves now (a backend waiting on its hardware).
  void Flush();
  // The backend finished: the rest of the log, flagged last; the live
  // topic's final sample again, flagged last.
  void End();

  const std::string& failure() const { return failure_; }          // "" while going
  msg::FailureKind failure_kind() const { return failure_kind_; }  // typed: deadline, interrupted
  std::size_t sent() const { return sent_; }                       // samples in the log
  std::uint32_t batches() const { return batches_; }               // batches in the log

 private:
  bool Paced() const { return pacing_ == Pacing::kLive && port_.speed > 0; }
  bool LiveDue() const;
  // The queued samples into the log as one batch (nothing queued: nothing
  // sent, unless it is the last one). @returns false when the stream stopped.
  bool SendBatch(bool last);
  void Fail(msg::FailureKind kind, std::string reason);

  const StreamPort& port_;
  const msg::TrialCommand& c_;
  StreamClock::time_point deadline_;
  Pacing pacing_;
  bool live_on_;                     // a reader was matched at the start (unpaced)
  StreamClock::time_point start_{};  // when sample 0 arrived: the pacing's origin
  msg::GroundTruth batch_;           // the samples not yet in the log
  std::size_t sent_ = 0;
  std::size_t pushed_ = 0;
  std::uint32_t batches_ = 0;
  msg::GroundTruthSample newest_;  // the latest sample, for the live topic's last
  std::string failure_;
  msg::FailureKind failure_kind_ = msg::FAILURE_NONE;
};

struct StreamOutcome {
  std::string failure;  // "" when the whole trial was sent
  msg::FailureKind kind = msg::FAILURE_NONE;
  std::uint32_t batches = 0;
};

// A whole trial's samples, known in advance (closed loop: the loop ran live,
// and `pushers` holds the pusher's state at each sample).
StreamOutcome StreamLog(const StreamPort& port, const msg::TrialCommand& c,
                        const std::vector<mechanics::TrajectorySample>& truth,
                        const std::vector<dds::PusherState>& pushers,
                        const std::vector<dds::Observation>& observed,
                        StreamClock::time_point deadline, Pacing pacing);

}  // namespace arena::executors
