// SIGINT/SIGTERM as an ordinary callback. The constructor blocks both signals
// (call it before any thread starts, so DDS threads inherit the mask); a
// watcher thread waits for them with sigtimedwait and calls on_signal, so no
// code runs inside a signal handler.
#pragma once

#include <atomic>
#include <functional>
#include <thread>

namespace arena::cli {

class SignalWatcher {
 public:
  explicit SignalWatcher(std::function<void(int signal)> on_signal);
  ~SignalWatcher();  // stops watching (signals stay blocked until exit)
  SignalWatcher(const SignalWatcher&) = delete;
  SignalWatcher& operator=(const SignalWatcher&) = delete;
  int received() const { return received_; }  // the last signal seen, 0 if none

 private:
  std::atomic<bool> done_{false};
  std::atomic<int> received_{0};
  std::thread thread_;
};

// A process started by `arena run` (a cell, a controller) must not outlive
// it, even when it is SIGKILLed: the kernel sends SIGTERM when the parent
// dies. @returns false when the parent (parent_pid > 0) is already gone, so
// the caller exits at once; true when there is none to follow.
bool FollowParent(int parent_pid);

}  // namespace arena::cli
