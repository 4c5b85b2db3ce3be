#include "store_steps.hpp"

#include <algorithm>

#include <spdlog/spdlog.h>

namespace arena::orchestrator {

StoreVerdict Judge(const db::StoreError& e) {
  using K = db::StoreError::Kind;
  switch (e.kind()) {
    case K::kBusy:
      return StoreVerdict::kRetry;
    case K::kFull:
    case K::kIo:
    case K::kCorrupt:
    case K::kReadOnly:
    case K::kTooNew:
      return StoreVerdict::kStop;
    default:
      return StoreVerdict::kMoot;
  }
}

StoreSteps::StoreSteps(std::function<Clock::time_point()> now,
                       std::function<void(const std::string&, int)> on_wait)
    : now_(std::move(now)), on_wait_(std::move(on_wait)) {}

bool StoreSteps::Step(const std::string& what, const std::string& cell_id, const Run& run,
                      const OnMoot& on_moot, double backoff_s) {
  try {
    run();
    return true;
  } catch (const db::StoreError& e) {
    switch (Judge(e)) {
      case StoreVerdict::kStop:
        throw;
      case StoreVerdict::kRetry: {
        spdlog::warn("{}: store busy ({}); retrying in {:.2f} s", what, e.what(), backoff_s);
        if (!cell_id.empty()) on_wait_(cell_id, +1);
        const auto due = now_() + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(backoff_s));
        pending_.push_back({what, cell_id, run, on_moot, due, backoff_s});
        return false;
      }
      case StoreVerdict::kMoot:
        if (on_moot)
          on_moot(e);
        else
          spdlog::error("{}: {}", what, e.what());
        return false;
    }
  }
  return false;
}

void StoreSteps::Attempt(const std::string& what, const Run& run) {
  try {
    run();
  } catch (const db::StoreError& e) {
    if (Judge(e) == StoreVerdict::kStop) throw;
    spdlog::warn("{}: {}", what, e.what());
  }
}

void StoreSteps::RunDue() {
  const auto t = now_();
  for (std::size_t n = pending_.size(); n > 0 && !pending_.empty(); --n) {
    if (pending_.front().due > t) {  // FIFO per due time is enough: keep order, rotate
      pending_.push_back(std::move(pending_.front()));
      pending_.pop_front();
      continue;
    }
    Pending p = std::move(pending_.front());
    pending_.pop_front();
    if (!p.cell_id.empty()) on_wait_(p.cell_id, -1);
    Step(p.what, p.cell_id, p.run, p.on_moot, std::min(p.backoff_s * 2, kMaxBackoff_s));
  }
}

}  // namespace arena::orchestrator
