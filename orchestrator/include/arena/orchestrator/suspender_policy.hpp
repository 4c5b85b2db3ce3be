// Suspenders (issue 29): conditions that pause dispatch by themselves and
// resume it when the condition clears, as pure functions of typed inputs in
// the style of trial_policy.hpp. Each decision carries the NAME of its rule;
// the name goes to the store's suspension row (suspensions.rule, lifted_by),
// so "why did cell c2 stop taking trials at 03:12?" is answered by one row
// and one row of the table test (tests/orchestrator/suspender_policy_test.cpp).
//
// ## The conditions
//
//   condition            scope     measure (a reading)                 fires when
//   reset_failure_rate   cell      failed / all resets, last `window`  > threshold
//   start_pose_drift     cell      mean |observed - target| of the     > threshold (m)
//                                  observed resets, last `window`
//   sample_drop_rate     cell      dropped / all samples of the last   > threshold
//                                  `window` streams (sensor dropouts)
//   cell_silence         cell      seconds since the cell was alive    > threshold (s)
//   store_free_space     service   free bytes in the store's folder    < threshold (bytes)
//                                  (statvfs)
//   deadline_misses      campaign  held / all samples of the last      > threshold
//                                  `window` closed-loop streams
//
// A rate needs `min_evidence` trials in its window before it may fire.
//
// ## One suspender's life (DecideSuspender)
//
//   watching ──fires──▶ suspended ──hold elapsed, clear──▶ watching (lifted)
//      │                    │
//      │ fired `budget`     └── `arena resume` lifts it at once and resets its hold
//      ▼   times without a clean window between
//   set aside (never again): a cell condition quarantines the cell; a
//   campaign condition ends the campaign's planned trials `failed` with the
//   reason; the rest goes on.
//
// Hold time: an outcome condition (a rate over trials) cannot clear while
// nothing runs, so it lifts once `hold_s` has passed since it fired and its
// window starts empty (the next trials measure again: a probe). A signal
// condition (silence, free space) lifts only after its reading has been clear
// for `hold_s` without a break (a flapping cell or a disk at the edge does not
// flap the campaign).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

namespace arena::orchestrator {

enum class Condition {
  kResetFailureRate,
  kStartPoseDrift,
  kSampleDropRate,
  kCellSilence,
  kStoreFreeSpace,
  kDeadlineMisses,
};
inline constexpr std::array<Condition, 6> kConditions = {
    Condition::kResetFailureRate, Condition::kStartPoseDrift, Condition::kSampleDropRate,
    Condition::kCellSilence,      Condition::kStoreFreeSpace, Condition::kDeadlineMisses};

enum class Scope { kCell, kCampaign, kService };
Scope ScopeOf(Condition c);
// A signal condition is read from the world (the clock, statvfs); an outcome
// condition from the trials that ran.
bool IsSignal(Condition c);
const char* ToString(Condition c);  // "reset_failure_rate", ...
const char* ToString(Scope s);      // "cell", "campaign", "service"
std::optional<Condition> ParseCondition(const std::string& name);

struct SuspenderLimits {
  bool enabled = true;
  double threshold = 0;  // a rate in [0, 1], metres, seconds or bytes (see the table above)
  int window = 10;       // trials the measure covers (outcome conditions)
  int min_evidence = 3;  // trials needed in the window before it may fire
  double hold_s = 60;    // see "Hold time"
  int budget = 3;        // fires before it is set aside; 0: never set aside
};

// Every condition's limits; the defaults are docs/operations.md's table.
struct SuspenderConfig {
  std::array<SuspenderLimits, kConditions.size()> limits;
  SuspenderConfig();  // the defaults
  const SuspenderLimits& operator[](Condition c) const { return limits[static_cast<int>(c)]; }
  SuspenderLimits& operator[](Condition c) { return limits[static_cast<int>(c)]; }
};

// A `suspenders` JSON object over the defaults:
//   {"reset_failure_rate": {"threshold": 0.5, "window": 10, "min_evidence": 4,
//                           "hold_s": 60, "budget": 3, "enabled": true}, ...}
// Fields left out keep their default. @throws std::invalid_argument naming the
// field ("suspenders.cell_silence.hold_s: must be a number of seconds in [0, 86400]").
SuspenderConfig ParseSuspenders(const nlohmann::json& j);
nlohmann::json ToJson(const SuspenderConfig& c);

// What one suspender (one condition on one cell, campaign or the service) knows.
struct SuspenderState {
  bool suspended = false;
  bool set_aside = false;
  double fired_at = 0;      // s (the caller's clock), when suspended
  double clear_since = -1;  // s, a signal's reading clear without a break since (-1: not clear)
  int fires = 0;            // since the last clean window
};

// The measure now. `known` false: nothing to judge yet (no trial, no probe).
struct Reading {
  bool known = false;
  double value = 0;
  int evidence = 0;  // trials in the window (outcome conditions)
};

enum class SuspenderStep {
  kNone,      // nothing changes
  kFire,      // suspend dispatch in the scope; record it (why, evidence, when)
  kHold,      // stays suspended
  kLift,      // resume dispatch; record when and by which rule
  kSetAside,  // fired too often: set aside (see the diagram), never fires again
};

struct SuspenderDecision {
  SuspenderStep step = SuspenderStep::kNone;
  const char* rule = "";  // "reset_failure_rate.fired", ...
  SuspenderState next;    // the state after the step
  // For a fire or a set aside: the reading against its limit, for the record
  // ("0.6 > 0.5 over 5 resets").
  std::string evidence;
};

// Whether `value` is past the threshold (free space: below it; others: above).
bool Exceeds(Condition c, double value, double threshold);

// One suspender's decision at `now_s`.
SuspenderDecision DecideSuspender(Condition c, const SuspenderLimits& limits,
                                  const SuspenderState& state, const Reading& reading,
                                  double now_s);

// `arena resume`: the suspension is lifted and its hold reset (the operator
// takes it on himself: the budget starts over too).
SuspenderState ResumedByOperator();
inline constexpr const char* kLiftedByOperator = "arena resume";

// ---- the dispatch gate: may a cell take a trial now?
struct ActiveSuspension {
  Condition condition = Condition::kResetFailureRate;
  std::string cell_id;  // cell scope: the cell
  std::int64_t campaign_id = 0;
};
// nullptr: it may; otherwise the rule that holds it back ("gate.cell_suspended",
// "gate.service_suspended"). A campaign's own suspension is its store state
// (paused, "suspended: ..."): the claim skips it, every other campaign goes on.
const char* DispatchGate(const std::vector<ActiveSuspension>& active, const std::string& cell_id);

}  // namespace arena::orchestrator
