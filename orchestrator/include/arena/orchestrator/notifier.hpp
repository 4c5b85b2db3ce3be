// `arena serve --notify COMMAND` (issue 29): each event (a campaign done, a
// cell gone or quarantined, a suspension fired or lifted, a failure rate
// above its threshold, a condition set aside) is handed to COMMAND as one
// JSON object on its stdin; a lab wires it to mail or chat.
//
// The command never stalls the service: Post() only appends to a bounded
// queue (full: the event is dropped, counted and logged; it is still in the
// store's service_events table and the log). One worker thread runs the
// commands one at a time, each `/bin/sh -c COMMAND` in its own process group;
// one that outlives `timeout_s` gets SIGTERM, then SIGKILL 1 s later, to its
// whole group. A non-zero exit is logged and counted, never retried.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

namespace arena::orchestrator {

struct NotifierCounters {
  std::int64_t posted = 0;     // accepted into the queue
  std::int64_t delivered = 0;  // the command exited 0
  std::int64_t failed = 0;     // it exited non-zero, was killed by a signal, or did not start
  std::int64_t timed_out = 0;  // killed after timeout_s
  std::int64_t dropped = 0;    // the queue was full
};

class Notifier {
 public:
  // @throws std::invalid_argument for an empty command, timeout_s outside
  //   (0, 3600] or a capacity outside 1..100000.
  Notifier(std::string command, double timeout_s = 10.0, std::size_t capacity = 256);
  // Waits for the command running now (at most its timeout), drops the rest.
  ~Notifier();
  Notifier(const Notifier&) = delete;
  Notifier& operator=(const Notifier&) = delete;

  // Never blocks on the command. @returns false when the queue was full.
  bool Post(std::string event_json);
  NotifierCounters counters() const;
  // Blocks until the queue is empty and no command runs (or `timeout_s`
  // passes); @returns whether it emptied. For tests and a clean stop.
  bool Drain(double timeout_s);

 private:
  void Work();
  // Runs the command once with `input` on its stdin. @returns the outcome.
  enum class Outcome { kOk, kFailed, kTimedOut };
  Outcome RunOnce(const std::string& input);

  std::string command_;
  double timeout_s_;
  std::size_t capacity_;
  mutable std::mutex mu_;
  std::condition_variable cv_, idle_cv_;
  std::deque<std::string> queue_;
  bool busy_ = false;
  bool stop_ = false;
  NotifierCounters counters_;
  std::thread worker_;
};

}  // namespace arena::orchestrator
