#include "trial_stream.hpp"

#include <limits>

#include <spdlog/spdlog.h>

#include "arena/executors/defects.hpp"
#include "clock.hpp"

namespace arena::executors {
namespace {

using internal::UnixNanos;

}  // namespace

void PublishLive(const StreamPort& port, const msg::TrialCommand& c, std::uint32_t index, bool last,
                 const msg::GroundTruthSample& sample, const std::string& controller,
                 const std::string& params) {
  msg::LiveState s;
  s.cell_id(port.cell_id);
  s.trial_id(c.trial_id());
  s.attempt(c.attempt());
  s.sample(index);
  s.last(last);
  s.closed_loop(!controller.empty());
  s.controller(controller);
  s.controller_params(params);
  s.state(sample);
  s.sent_unix_ns(UnixNanos());
  port.live->Write(s);
}

TrialStream::TrialStream(const StreamPort& port, const msg::TrialCommand& command,
                         StreamClock::time_point deadline, Pacing pacing)
    : port_(port),
      c_(command),
      deadline_(deadline),
      pacing_(pacing),
      live_on_(pacing == Pacing::kLive && port.live->Matched() > 0) {}

// Paced, a sample goes live only when someone listens now; unpaced, when
// someone listened at the start (a matched count per sample costs more than
// a simulator's step).
bool TrialStream::LiveDue() const { return Paced() ? port_.live->Matched() > 0 : live_on_; }

bool TrialStream::Push(const mechanics::Scene& actual, const mechanics::TrajectorySample& truth,
                       const dds::Observation& observed) {
  return Push(truth, PusherAt(actual, truth), observed);
}

bool TrialStream::Push(const mechanics::TrajectorySample& truth, const dds::PusherState& pusher,
                       const dds::Observation& observed) {
  if (!failure_.empty()) return false;
  if (pushed_ == 0) start_ = StreamClock::now();
  if (batch_.samples().size() >= static_cast<std::size_t>(port_.batch_samples) && !SendBatch(false))
    return false;
  if (Paced()) {
    const auto due = start_ + std::chrono::duration_cast<StreamClock::duration>(
                                  std::chrono::duration<double>(truth.t * port_.speed));
    if (due > deadline_) {
      port_.sleep_until(deadline_);
      Fail(msg::FAILURE_DEADLINE, "deadline: " + std::to_string(c_.deadline_s()) +
                                      " s exceeded after " + std::to_string(sent_) + " samples");
      return false;
    }
    if (!port_.sleep_until(due)) {
      Fail(msg::FAILURE_INTERRUPTED, "interrupted: cell shutting down");
      return false;
    }
  }
  msg::GroundTruthSample encoded;
  dds::EncodeSample(truth, pusher, observed, &encoded);
  if (LiveDue()) PublishLive(port_, c_, static_cast<std::uint32_t>(pushed_), false, encoded);
  newest_ = encoded;
  batch_.samples().push_back(std::move(encoded));
  ++pushed_;
  return true;
}

void TrialStream::Fail(msg::FailureKind kind, std::string reason) {
  failure_ = std::move(reason);
  failure_kind_ = kind;
}

void TrialStream::Flush() {
  if (failure_.empty()) SendBatch(false);
}

void TrialStream::End() {
  if (!SendBatch(true) || pushed_ == 0) return;
  if (LiveDue()) PublishLive(port_, c_, static_cast<std::uint32_t>(pushed_ - 1), true, newest_);
}

bool TrialStream::SendBatch(bool last) {
  if (!failure_.empty()) return false;
  if (batch_.samples().empty() && !last) return true;
  const std::size_t count = batch_.samples().size();
  batch_.trial_id(c_.trial_id());
  batch_.attempt(c_.attempt());
  batch_.cell_id(port_.cell_id);
  batch_.service_session(c_.service_session());
  batch_.batch(batches_);
  batch_.first_sample(static_cast<std::uint32_t>(sent_));
  batch_.last(last);
  // Fault injection (defects.hpp): a malformed sample, or a missing batch.
  if (port_.corrupt_stream == "gap" && batches_ == 0)
    batch_.first_sample(static_cast<std::uint32_t>(sent_ + 1));
  if (port_.corrupt_stream == "nan" && batches_ == 0 && count > 0)
    batch_.samples()[0].object_pose()[0] = std::numeric_limits<double>::quiet_NaN();
  if (!port_.serves(c_.service_session())) {
    Fail(msg::FAILURE_INTERRUPTED, "interrupted: the cell now serves another service");
    return false;
  }
  batch_.sent_unix_ns(UnixNanos());
  // Ground truth is a log: a full history throttles us, it never drops.
  while (!port_.log->Write(batch_)) {
    if (port_.stopping()) {
      Fail(msg::FAILURE_INTERRUPTED, "interrupted: cell shutting down");
      return false;
    }
    if (StreamClock::now() > deadline_) break;
    spdlog::warn("cell {}: ground-truth history full (a slow reader?), retrying", port_.cell_id);
  }
  if (StreamClock::now() > deadline_) {
    Fail(msg::FAILURE_DEADLINE, "deadline: " + std::to_string(c_.deadline_s()) +
                                    " s exceeded after " + std::to_string(sent_ + count) +
                                    " samples");
    return false;
  }
  sent_ += count;
  ++batches_;
  batch_.samples().clear();
  port_.count_samples(count);
  return true;
}

StreamOutcome StreamLog(const StreamPort& port, const msg::TrialCommand& c,
                        const std::vector<mechanics::TrajectorySample>& truth,
                        const std::vector<dds::PusherState>& pushers,
                        const std::vector<dds::Observation>& observed,
                        StreamClock::time_point deadline, Pacing pacing) {
  TrialStream out(port, c, deadline, pacing);
  std::string stopped;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (!out.Push(truth[i], pushers[i], observed[i])) break;
    if (port.stopping() && i + 1 < truth.size()) {
      stopped = "interrupted: cell shutting down";
      break;
    }
  }
  if (out.failure().empty() && stopped.empty()) out.End();
  if (!out.failure().empty()) return {out.failure(), out.failure_kind(), out.batches()};
  return {stopped, stopped.empty() ? msg::FAILURE_NONE : msg::FAILURE_INTERRUPTED, out.batches()};
}

}  // namespace arena::executors
