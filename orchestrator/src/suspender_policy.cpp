// The suspenders' rules; the contract is in suspender_policy.hpp.
#include "arena/orchestrator/suspender_policy.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>

#include <nlohmann/json.hpp>

namespace arena::orchestrator {

namespace {
struct Names {
  const char* name;
  const char* fired;
  const char* set_aside;
  const char* holding;
  const char* still;
  const char* lifted;
  const char* clean;
};
const Names& NamesOf(Condition c) {
  static const Names kNames[] = {
      {"reset_failure_rate", "reset_failure_rate.fired", "reset_failure_rate.set_aside",
       "reset_failure_rate.holding", "reset_failure_rate.still_past",
       "reset_failure_rate.hold_elapsed", "reset_failure_rate.clean_window"},
      {"start_pose_drift", "start_pose_drift.fired", "start_pose_drift.set_aside",
       "start_pose_drift.holding", "start_pose_drift.still_past", "start_pose_drift.hold_elapsed",
       "start_pose_drift.clean_window"},
      {"sample_drop_rate", "sample_drop_rate.fired", "sample_drop_rate.set_aside",
       "sample_drop_rate.holding", "sample_drop_rate.still_past", "sample_drop_rate.hold_elapsed",
       "sample_drop_rate.clean_window"},
      {"cell_silence", "cell_silence.fired", "cell_silence.set_aside", "cell_silence.holding",
       "cell_silence.still_past", "cell_silence.cleared", "cell_silence.clean_window"},
      {"store_free_space", "store_free_space.fired", "store_free_space.set_aside",
       "store_free_space.holding", "store_free_space.still_past", "store_free_space.cleared",
       "store_free_space.clean_window"},
      {"deadline_misses", "deadline_misses.fired", "deadline_misses.set_aside",
       "deadline_misses.holding", "deadline_misses.still_past", "deadline_misses.hold_elapsed",
       "deadline_misses.clean_window"},
  };
  return kNames[static_cast<int>(c)];
}

std::string FourDigits(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

const char* Unit(Condition c) {
  switch (c) {
    case Condition::kStartPoseDrift:
      return " m";
    case Condition::kCellSilence:
      return " s";
    default:
      return "";
  }
}

// Bytes as a person reads them: MiB from 1 MiB on.
std::string Bytes(double b) {
  if (b < 1024.0 * 1024) return FourDigits(b) + " bytes";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f MiB", b / (1024.0 * 1024));
  return buf;
}

std::string Evidence(Condition c, const SuspenderLimits& l, const Reading& r) {
  std::string e = c == Condition::kStoreFreeSpace
                      ? Bytes(r.value) + " < " + Bytes(l.threshold)
                      : FourDigits(r.value) + Unit(c) + " > " + FourDigits(l.threshold) + Unit(c);
  switch (c) {
    case Condition::kResetFailureRate:
      return e + " failed over the last " + std::to_string(r.evidence) + " resets";
    case Condition::kStartPoseDrift:
      return e + " mean start-pose error over the last " + std::to_string(r.evidence) + " resets";
    case Condition::kSampleDropRate:
      return e + " samples dropped over the last " + std::to_string(r.evidence) + " streams";
    case Condition::kDeadlineMisses:
      return e + " samples held (deadline missed) over the last " + std::to_string(r.evidence) +
             " closed-loop streams";
    case Condition::kCellSilence:
      return e + " without a sign of life";
    case Condition::kStoreFreeSpace:
      return e + " free in the store's folder";
  }
  return e;
}
}  // namespace

Scope ScopeOf(Condition c) {
  switch (c) {
    case Condition::kStoreFreeSpace:
      return Scope::kService;
    case Condition::kDeadlineMisses:
      return Scope::kCampaign;
    default:
      return Scope::kCell;
  }
}

bool IsSignal(Condition c) {
  return c == Condition::kCellSilence || c == Condition::kStoreFreeSpace;
}

const char* ToString(Condition c) { return NamesOf(c).name; }

const char* ToString(Scope s) {
  switch (s) {
    case Scope::kCell:
      return "cell";
    case Scope::kCampaign:
      return "campaign";
    case Scope::kService:
      break;
  }
  return "service";
}

std::optional<Condition> ParseCondition(const std::string& name) {
  for (Condition c : kConditions)
    if (name == ToString(c)) return c;
  return std::nullopt;
}

SuspenderConfig::SuspenderConfig() {
  // threshold, window, min_evidence, hold_s, budget
  (*this)[Condition::kResetFailureRate] = {true, 0.5, 10, 4, 60, 3};
  (*this)[Condition::kStartPoseDrift] = {true, 0.005, 10, 3, 60, 3};
  (*this)[Condition::kSampleDropRate] = {true, 0.2, 5, 3, 60, 3};
  (*this)[Condition::kCellSilence] = {true, 30, 10, 1, 30, 5};
  (*this)[Condition::kStoreFreeSpace] = {true, 512.0 * 1024 * 1024, 10, 1, 60, 0};
  (*this)[Condition::kDeadlineMisses] = {true, 0.2, 10, 3, 60, 3};
}

namespace {
void Bad(const std::string& field, const std::string& why) {
  throw std::invalid_argument("suspenders." + field + ": " + why);
}
double Number(const nlohmann::json& j, const std::string& field, double min, double max,
              const char* what) {
  if (!j.is_number()) Bad(field, std::string("must be ") + what + ", got " + j.dump());
  const double v = j.get<double>();
  if (!std::isfinite(v) || v < min || v > max)
    Bad(field, std::string("must be ") + what + " in [" + FourDigits(min) + ", " + FourDigits(max) +
                   "], got " + j.dump());
  return v;
}
int Integer(const nlohmann::json& j, const std::string& field, int min, int max) {
  if (!j.is_number_integer())
    Bad(field, "must be an integer in [" + std::to_string(min) + ", " + std::to_string(max) +
                   "], got " + j.dump());
  const auto v = j.get<long long>();
  if (v < min || v > max)
    Bad(field, "must be an integer in [" + std::to_string(min) + ", " + std::to_string(max) +
                   "], got " + j.dump());
  return static_cast<int>(v);
}
double MaxThreshold(Condition c) {
  switch (c) {
    case Condition::kStartPoseDrift:
      return 1.0;  // m
    case Condition::kCellSilence:
      return 7 * 86400.0;
    case Condition::kStoreFreeSpace:
      return 1e15;
    default:
      return 1.0;  // a rate
  }
}
}  // namespace

SuspenderConfig ParseSuspenders(const nlohmann::json& j) {
  SuspenderConfig config;
  if (j.is_null()) return config;
  if (!j.is_object()) throw std::invalid_argument("suspenders: must be a JSON object");
  for (const auto& [name, body] : j.items()) {
    const auto c = ParseCondition(name);
    if (!c) {
      std::string known;
      for (Condition k : kConditions) known += std::string(known.empty() ? "" : ", ") + ToString(k);
      Bad(name, "unknown condition (known: " + known + ")");
    }
    if (!body.is_object()) Bad(name, "must be an object of limits");
    SuspenderLimits& l = config[*c];
    for (const auto& [key, v] : body.items()) {
      const std::string field = name + "." + key;
      if (key == "enabled") {
        if (!v.is_boolean()) Bad(field, "must be true or false");
        l.enabled = v.get<bool>();
      } else if (key == "threshold") {
        l.threshold = Number(v, field, 0, MaxThreshold(*c), "a number");
      } else if (key == "window") {
        l.window = Integer(v, field, 1, 10000);
      } else if (key == "min_evidence") {
        l.min_evidence = Integer(v, field, 1, 10000);
      } else if (key == "hold_s") {
        l.hold_s = Number(v, field, 0, 86400, "a number of seconds");
      } else if (key == "budget") {
        l.budget = Integer(v, field, 0, 1000000);
      } else {
        Bad(field, "unknown field (enabled, threshold, window, min_evidence, hold_s, budget)");
      }
    }
    if (l.min_evidence > l.window)
      Bad(name + ".min_evidence", "must be <= window (" + std::to_string(l.window) + ")");
    if (*c == Condition::kStoreFreeSpace && l.budget != 0)
      Bad(name + ".budget",
          "must be 0: a store short of space cannot be set aside, dispatch waits for space");
  }
  return config;
}

nlohmann::json ToJson(const SuspenderConfig& config) {
  nlohmann::json j = nlohmann::json::object();
  for (Condition c : kConditions) {
    const SuspenderLimits& l = config[c];
    j[ToString(c)] = {{"enabled", l.enabled}, {"threshold", l.threshold},
                      {"window", l.window},   {"min_evidence", l.min_evidence},
                      {"hold_s", l.hold_s},   {"budget", l.budget}};
  }
  return j;
}

bool Exceeds(Condition c, double value, double threshold) {
  return c == Condition::kStoreFreeSpace ? value < threshold : value > threshold;
}

namespace {

SuspenderDecision Decided(SuspenderDecision d, SuspenderStep step, const char* rule) {
  d.step = step;
  d.rule = rule;
  if (step == SuspenderStep::kLift) d.next.suspended = false;
  return d;
}

// While suspended: a signal lifts once clear for hold_s without a break; an
// outcome holds (nothing runs) for hold_s, then the next trials probe.
SuspenderDecision DecideWhileSuspended(Condition c, const SuspenderLimits& l, const Reading& r,
                                       double now_s, bool past, SuspenderDecision d) {
  const Names& n = NamesOf(c);
  const bool hold_over = now_s - d.next.fired_at >= l.hold_s;
  if (!IsSignal(c))
    return hold_over ? Decided(std::move(d), SuspenderStep::kLift, n.lifted)
                     : Decided(std::move(d), SuspenderStep::kHold, n.holding);
  if (!r.known || past) {
    d.next.clear_since = -1;
    return Decided(std::move(d), SuspenderStep::kHold, past ? n.still : n.holding);
  }
  if (d.next.clear_since < 0) d.next.clear_since = now_s;
  if (now_s - d.next.clear_since >= l.hold_s && hold_over)
    return Decided(std::move(d), SuspenderStep::kLift, n.lifted);
  return Decided(std::move(d), SuspenderStep::kHold, n.holding);
}

}  // namespace

SuspenderDecision DecideSuspender(Condition c, const SuspenderLimits& l, const SuspenderState& s,
                                  const Reading& r, double now_s) {
  const Names& n = NamesOf(c);
  SuspenderDecision d;
  d.next = s;
  if (s.set_aside) {
    d.rule = "suspender.set_aside";
    return d;
  }
  if (!l.enabled) {
    // A suspender switched off while suspended lifts (nothing holds it).
    if (s.suspended) {
      d.step = SuspenderStep::kLift;
      d.rule = "suspender.disabled";
      d.next = SuspenderState{};
    } else {
      d.rule = "suspender.disabled";
    }
    return d;
  }
  const bool judged = r.known && (IsSignal(c) || r.evidence >= l.min_evidence);
  const bool past = judged && Exceeds(c, r.value, l.threshold);
  if (s.suspended) return DecideWhileSuspended(c, l, r, now_s, past, std::move(d));
  if (past) {
    d.evidence = Evidence(c, l, r);
    d.next.clear_since = -1;
    if (l.budget > 0 && s.fires >= l.budget) {
      d.step = SuspenderStep::kSetAside;
      d.rule = n.set_aside;
      d.next.set_aside = true;
      d.evidence += " (fired " + std::to_string(s.fires + 1) + " times, budget " +
                    std::to_string(l.budget) + ")";
      return d;
    }
    d.step = SuspenderStep::kFire;
    d.rule = n.fired;
    d.next.suspended = true;
    d.next.fired_at = now_s;
    d.next.fires = s.fires + 1;
    return d;
  }
  // Clear. A clean window gives the budget back: a full window of trials
  // within the limit, or a signal clear for `window` hold times.
  d.rule = "suspender.clear";
  if (IsSignal(c)) {
    if (r.known) {
      if (d.next.clear_since < 0) d.next.clear_since = now_s;
      if (s.fires > 0 && now_s - d.next.clear_since >= l.window * std::max(l.hold_s, 1.0)) {
        d.next.fires = 0;
        d.rule = n.clean;
      }
    }
  } else if (judged && r.evidence >= l.window && s.fires > 0) {
    d.next.fires = 0;
    d.rule = n.clean;
  }
  return d;
}

SuspenderState ResumedByOperator() { return SuspenderState{}; }

const char* DispatchGate(const std::vector<ActiveSuspension>& active, const std::string& cell_id) {
  for (const auto& a : active)
    if (ScopeOf(a.condition) == Scope::kService) return "gate.service_suspended";
  for (const auto& a : active)
    if (ScopeOf(a.condition) == Scope::kCell && a.cell_id == cell_id) return "gate.cell_suspended";
  return nullptr;
}

}  // namespace arena::orchestrator
