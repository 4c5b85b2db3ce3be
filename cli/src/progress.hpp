// A live progress line for long jobs: a bar on a terminal, silent when
// stderr is not a TTY (CI logs, pipes), so logs stay readable.
#pragma once

#include <chrono>
#include <string>

namespace arena::cli {

class ProgressLine {
 public:
  // total: the number of units expected (trials); label: what is counted.
  ProgressLine(long total, std::string label);
  ~ProgressLine();  // finishes the line if one was drawn
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  // done/failed units so far; extra: free text appended (e.g. "2 cells").
  // Redraws at most 10 times a second.
  void Update(long done, long failed, const std::string& extra = "");
  void Finish();
  bool enabled() const { return enabled_; }

 private:
  long total_;
  std::string label_;
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_{};
};

// "1h02m", "3m05s", "12s": for ETAs and elapsed times.
std::string FormatDuration(double seconds);

// "2026-11-28T00:44:06Z" (UTC); "-" for no time (0 or less).
std::string IsoTime(double unix_s);

}  // namespace arena::cli
