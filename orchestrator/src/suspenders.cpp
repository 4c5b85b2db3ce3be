// The suspenders at run time; the contract is in suspenders.hpp, the rules in
// suspender_policy.hpp.
#include "arena/orchestrator/suspenders.hpp"

#include <algorithm>
#include <cmath>

namespace arena::orchestrator {

namespace {
// A window never holds more than this many observations (memory stays flat
// whatever a campaign's window asks for; windows are at most 10000).
constexpr std::size_t kMaxWindow = 10000;
}  // namespace

Suspenders::Suspenders(SuspenderConfig config, std::function<double()> now_s)
    : config_(std::move(config)), now_(std::move(now_s)) {}

Suspenders::Key Suspenders::KeyOf(Condition c, const std::string& cell, std::int64_t campaign) {
  switch (ScopeOf(c)) {
    case Scope::kCell:
      return {c, cell, 0};
    case Scope::kCampaign:
      return {c, "", campaign};
    case Scope::kService:
      break;
  }
  return {c, "", 0};
}

void Suspenders::Push(std::deque<Observation>& window, Observation o) {
  window.push_back(o);
  while (window.size() > kMaxWindow) window.pop_front();
}

void Suspenders::OnReset(const std::string& cell_id, std::int64_t, bool ok, bool pose_observed,
                         double position_error_m) {
  Push(resets_[cell_id], {seq_++, ok ? 0.0 : 1.0, 1.0});
  SlotOf(KeyOf(Condition::kResetFailureRate, cell_id, 0));  // known from now on
  if (ok && pose_observed && std::isfinite(position_error_m)) {
    Push(drift_[cell_id], {seq_++, position_error_m, 1.0});
    SlotOf(KeyOf(Condition::kStartPoseDrift, cell_id, 0));
  }
}

void Suspenders::OnStream(const std::string& cell_id, std::int64_t, std::int64_t samples,
                          std::int64_t dropped) {
  if (samples <= 0) return;
  Push(streams_[cell_id], {seq_++, static_cast<double>(dropped), static_cast<double>(samples)});
  SlotOf(KeyOf(Condition::kSampleDropRate, cell_id, 0));
}

void Suspenders::OnClosedLoop(const std::string&, std::int64_t campaign_id, std::int64_t samples,
                              std::int64_t held) {
  if (samples <= 0 || campaign_id <= 0) return;
  Push(loops_[campaign_id], {seq_++, static_cast<double>(held), static_cast<double>(samples)});
  SlotOf(KeyOf(Condition::kDeadlineMisses, "", campaign_id));
}

void Suspenders::OnCellAlive(const std::string& cell_id, bool alive) {
  auto [it, inserted] = cells_.try_emplace(cell_id);
  if (inserted || it->second.alive != alive) {
    it->second.alive = alive;
    it->second.since = now_();
  }
  SlotOf(KeyOf(Condition::kCellSilence, cell_id, 0));
}

const char* Suspenders::DispatchGate(const std::string& cell_id) {
  // A cell whose condition was set aside is quarantined in the store; until
  // the service learns it there, the gate holds it back itself.
  for (const auto& [key, slot] : slots_)
    if (slot.state.set_aside && ScopeOf(std::get<0>(key)) == Scope::kCell &&
        std::get<1>(key) == cell_id)
      return "gate.cell_set_aside";
  return orchestrator::DispatchGate(Active(), cell_id);
}

std::vector<ActiveSuspension> Suspenders::Active() const {
  std::vector<ActiveSuspension> out;
  for (const auto& [key, slot] : slots_)
    if (slot.state.suspended) out.push_back({std::get<0>(key), std::get<1>(key), std::get<2>(key)});
  return out;
}

Reading Suspenders::Read(Condition c, const std::string& cell, std::int64_t campaign,
                         std::uint64_t from, std::optional<double> free_bytes) const {
  Reading r;
  const SuspenderLimits& l = config_[c];
  auto rate = [&](const std::deque<Observation>* w, bool mean_of_a) {
    if (!w) return;
    double a = 0, b = 0;
    int n = 0;
    for (auto it = w->rbegin(); it != w->rend() && n < l.window; ++it) {
      if (it->seq < from) break;
      a += it->a;
      b += it->b;
      ++n;
    }
    r.evidence = n;
    r.known = n > 0 && b > 0;
    if (r.known) r.value = mean_of_a ? a / n : a / b;
  };
  auto find = [](const auto& m, const auto& k) -> const std::deque<Observation>* {
    auto it = m.find(k);
    return it == m.end() ? nullptr : &it->second;
  };
  switch (c) {
    case Condition::kResetFailureRate:
      rate(find(resets_, cell), false);
      break;
    case Condition::kStartPoseDrift:
      rate(find(drift_, cell), true);
      break;
    case Condition::kSampleDropRate:
      rate(find(streams_, cell), false);
      break;
    case Condition::kDeadlineMisses:
      rate(find(loops_, campaign), false);
      break;
    case Condition::kCellSilence: {
      auto it = cells_.find(cell);
      if (it == cells_.end()) break;
      r.known = true;
      r.evidence = 1;
      r.value = it->second.alive ? 0.0 : now_() - it->second.since;
      break;
    }
    case Condition::kStoreFreeSpace:
      if (free_bytes) {
        r.known = true;
        r.evidence = 1;
        r.value = *free_bytes;
      }
      break;
  }
  return r;
}

std::vector<Suspenders::Action> Suspenders::Evaluate(std::optional<double> free_bytes) const {
  const double t = now_();
  std::vector<Action> out;
  auto judge = [&](const Key& key, const Slot& slot) {
    const auto& [c, cell, campaign] = key;
    const Reading r = Read(c, cell, campaign, slot.measured_from, free_bytes);
    SuspenderDecision d = DecideSuspender(c, config_[c], slot.state, r, t);
    const bool changed = d.step != SuspenderStep::kNone && d.step != SuspenderStep::kHold;
    const bool state_moved =
        d.next.clear_since != slot.state.clear_since || d.next.fires != slot.state.fires;
    if (changed || state_moved)
      out.push_back({c, cell, campaign, std::move(d), slot.suspension_id});
  };
  for (const auto& [key, slot] : slots_) judge(key, slot);
  const Key service = KeyOf(Condition::kStoreFreeSpace, "", 0);
  if (!slots_.count(service)) judge(service, Slot{});
  return out;
}

void Suspenders::Commit(const Action& a, std::int64_t suspension_id) {
  Slot& slot = SlotOf(KeyOf(a.condition, a.cell_id, a.campaign_id));
  slot.state = a.decision.next;
  switch (a.decision.step) {
    case SuspenderStep::kFire:
      slot.suspension_id = suspension_id;
      slot.measured_from = seq_;  // the window starts empty after the hold
      break;
    case SuspenderStep::kLift:
      slot.suspension_id = 0;
      break;
    default:
      break;
  }
}

void Suspenders::Adopt(const db::Suspension& s) {
  const auto c = ParseCondition(s.condition);
  if (!c) return;
  Slot& slot = SlotOf(KeyOf(*c, s.cell_id, s.campaign_id));
  if (slot.state.suspended) return;
  slot.state.suspended = true;
  slot.state.fired_at = now_();
  slot.state.fires = std::max(slot.state.fires, 1);
  slot.suspension_id = s.id;
  slot.measured_from = seq_;
}

void Suspenders::CellReleased(const std::string& cell_id) {
  for (auto& [key, slot] : slots_)
    if (slot.state.set_aside && ScopeOf(std::get<0>(key)) == Scope::kCell &&
        std::get<1>(key) == cell_id) {
      slot.state = SuspenderState{};
      slot.measured_from = seq_;
    }
}

std::vector<Suspenders::Action> Suspenders::Reconcile(const std::vector<db::Suspension>& active) {
  std::vector<Action> lifted;
  for (auto& [key, slot] : slots_) {
    if (!slot.state.suspended || slot.suspension_id == 0) continue;
    const bool still = std::any_of(active.begin(), active.end(), [&](const db::Suspension& s) {
      return s.id == slot.suspension_id;
    });
    if (still) continue;
    Action a{std::get<0>(key), std::get<1>(key), std::get<2>(key), {}, slot.suspension_id};
    a.decision.step = SuspenderStep::kLift;
    a.decision.rule = kLiftedByOperator;
    slot.state = ResumedByOperator();
    slot.suspension_id = 0;
    slot.measured_from = seq_;
    lifted.push_back(std::move(a));
  }
  return lifted;
}

}  // namespace arena::orchestrator
