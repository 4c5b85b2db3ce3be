#include "signals.hpp"

#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <ctime>

namespace arena::cli {

SignalWatcher::SignalWatcher(std::function<void(int)> on_signal) {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  thread_ = std::thread([this, set, on_signal = std::move(on_signal)] {
    const timespec tick{0, 100'000'000};  // 100 ms: how soon the destructor is noticed
    while (!done_) {
      const int sig = sigtimedwait(&set, nullptr, &tick);
      if (sig > 0) {
        received_ = sig;
        on_signal(sig);
      }
    }
  });
}

SignalWatcher::~SignalWatcher() {
  done_ = true;
  thread_.join();
}

bool FollowParent(int parent_pid) {
  if (parent_pid <= 0) return true;
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  // A parent that died before the line above is caught by its pid.
  return getppid() == parent_pid;
}

}  // namespace arena::cli
