// The one rule that decides whether an ended attempt is run again or the
// trial fails for good. Store::RetryTrial applies it inside its transaction
// (it needs the trial's service_restarts); the service's trial policy
// (orchestrator/trial_policy.hpp) names it, and every test fake of the store
// calls it, so nobody keeps a second copy that could drift.
#pragma once

namespace arena::db {

struct RetryVerdict {
  bool give_up = false;   // true: -> failed (outcome "failed"); false: -> planned, attempt + 1
  int counted = 0;        // attempts that count against max_attempts
  const char* rule = "";  // the rule's name, written to trial_transitions.rule
};

// Attempts a service restart cut short (RecoverAfterRestart) are nobody's
// fault and do not count. max_attempts >= 1 (the store refuses less).
constexpr RetryVerdict DecideRetry(int attempt, int service_restarts, int max_attempts) {
  const int counted = attempt - service_restarts;
  if (counted >= max_attempts) return {true, counted, "retry.attempts_exhausted"};
  return {false, counted, "retry.attempts_left"};
}

}  // namespace arena::db
