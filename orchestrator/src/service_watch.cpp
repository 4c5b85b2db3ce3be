// The service's watch; the contract is in service_watch.hpp.
#include "service_watch.hpp"

#include <sys/statvfs.h>

#include <filesystem>

#include <spdlog/spdlog.h>

namespace arena::orchestrator {

namespace {
bool Fatal(const db::StoreError& e) {
  using K = db::StoreError::Kind;
  return e.kind() == K::kFull || e.kind() == K::kIo || e.kind() == K::kReadOnly ||
         e.kind() == K::kTooNew || e.kind() == K::kCorrupt;
}
}  // namespace

ServiceWatch::ServiceWatch(db::Store& store, const ServiceOptions& options, Suspenders& suspenders,
                           Notifier* notifier)
    : store_(store), opt_(options), suspenders_(suspenders), notifier_(notifier) {
  std::filesystem::path p = std::filesystem::absolute(options.db_path).parent_path();
  folder_ = p.empty() ? "." : p.string();
}

std::optional<double> ServiceWatch::FreeBytes() const {
  struct statvfs v {};
  if (::statvfs(folder_.c_str(), &v) != 0) return std::nullopt;
  return static_cast<double>(v.f_bavail) * static_cast<double>(v.f_frsize);
}

void ServiceWatch::Start() {
  for (const auto& s : store_.ListSuspensions(true)) suspenders_.Adopt(s);
  for (const auto& c : store_.ListCells()) cells_[c.id] = c.state;
  for (const auto& c : store_.ListCampaigns()) campaigns_[c.id] = c.state;
  started_ = true;
}

void ServiceWatch::Poll() {
  try {
    if (!started_) Start();
    Pass();
  } catch (const db::StoreError& e) {
    if (Fatal(e)) throw;
    if (e.kind() == db::StoreError::Kind::kBusy)
      spdlog::debug("watch: store busy ({}); next pass", e.what());
    else
      spdlog::error("watch: {}", e.what());
  }
}

void ServiceWatch::Emit(const std::string& kind, std::int64_t campaign_id,
                        const std::string& cell_id, const std::string& message,
                        nlohmann::json detail) {
  db::EventRecord e;
  e.at = store_.Now();
  e.kind = kind;
  e.campaign_id = campaign_id;
  e.cell_id = cell_id;
  e.message = message;
  nlohmann::json j = {{"event", kind}, {"at", e.at}, {"store", opt_.db_path}, {"message", message}};
  if (campaign_id > 0) j["campaign"] = campaign_id;
  if (!cell_id.empty()) j["cell"] = cell_id;
  if (!detail.empty()) j["detail"] = std::move(detail);
  e.event_json = j.dump();
  spdlog::warn("event {}: {}", kind, message);
  unsent_.push_back(std::move(e));
  Flush();
}

// First the store, then the command: an event a command never took is
// still in service_events. A busy store keeps them for the next pass.
void ServiceWatch::Flush() {
  while (!unsent_.empty()) {
    db::EventRecord& e = unsent_.front();
    try {
      e.id = store_.RecordEvent(e);
    } catch (const db::StoreError& err) {
      if (err.kind() == db::StoreError::Kind::kBusy || Fatal(err)) throw;
      spdlog::error("event {} not stored: {}", e.kind, err.what());  // not retried for ever
      unsent_.pop_front();
      continue;
    }
    if (notifier_) {
      auto j = nlohmann::json::parse(e.event_json);
      j["id"] = e.id;
      notifier_->Post(j.dump());
    }
    unsent_.pop_front();
  }
}

void ServiceWatch::Carry(const Suspenders::Action& a) {
  const SuspenderDecision& d = a.decision;
  const Scope scope = ScopeOf(a.condition);
  const std::string where = scope == Scope::kCell ? "cell " + a.cell_id
                            : scope == Scope::kCampaign
                                ? "campaign " + std::to_string(a.campaign_id)
                                : "every campaign";
  nlohmann::json detail = {
      {"condition", ToString(a.condition)}, {"scope", ToString(scope)}, {"rule", d.rule}};
  switch (d.step) {
    case SuspenderStep::kFire: {
      db::Suspension s;
      s.condition = ToString(a.condition);
      s.scope = ToString(scope);
      s.campaign_id = a.campaign_id;
      s.cell_id = a.cell_id;
      s.rule = d.rule;
      s.evidence = d.evidence;
      const std::int64_t id = store_.RecordSuspension(s);
      suspenders_.Commit(a, id);
      detail["evidence"] = d.evidence;
      detail["suspension"] = id;
      Emit("suspension_fired", a.campaign_id, a.cell_id,
           std::string(ToString(a.condition)) + ": dispatch to " + where +
               " suspended: " + d.evidence,
           detail);
      return;
    }
    case SuspenderStep::kLift: {
      if (a.suspension_id > 0) store_.LiftSuspension(a.suspension_id, d.rule, "condition cleared");
      suspenders_.Commit(a);
      detail["suspension"] = a.suspension_id;
      Emit("suspension_lifted", a.campaign_id, a.cell_id,
           std::string(ToString(a.condition)) + ": dispatch to " + where + " resumed (" + d.rule +
               ")",
           detail);
      return;
    }
    case SuspenderStep::kSetAside: {
      const std::string why =
          std::string("set aside: ") + ToString(a.condition) + ": " + d.evidence;
      detail["evidence"] = d.evidence;
      if (scope == Scope::kCell) {
        store_.QuarantineCell(a.cell_id, why);
        detail["action"] = "cell quarantined";
      } else if (scope == Scope::kCampaign) {
        const int n = store_.SetAsideTrials(a.campaign_id, why, d.rule);
        detail["action"] = "planned trials failed";
        detail["trials"] = n;
      }
      suspenders_.Commit(a);
      Emit("condition_set_aside", a.campaign_id, a.cell_id, where + ": " + why, detail);
      return;
    }
    default:
      suspenders_.Commit(a);  // a clear reading's bookkeeping (budget, clear since)
      return;
  }
}

void ServiceWatch::Pass() {
  ++passes_;
  Flush();
  // `arena resume` lifted some of ours: their hold and budget start over.
  for (const auto& a : suspenders_.Reconcile(store_.ListSuspensions(true))) {
    const std::string where = ScopeOf(a.condition) == Scope::kCell ? "cell " + a.cell_id
                              : ScopeOf(a.condition) == Scope::kCampaign
                                  ? "campaign " + std::to_string(a.campaign_id)
                                  : "every campaign";
    Emit("suspension_lifted", a.campaign_id, a.cell_id,
         std::string(ToString(a.condition)) + ": dispatch to " + where +
             " resumed by `arena resume`",
         {{"condition", ToString(a.condition)},
          {"rule", kLiftedByOperator},
          {"suspension", a.suspension_id}});
  }
  for (const auto& a : suspenders_.Evaluate(FreeBytes())) Carry(a);

  for (const auto& c : store_.ListCells()) {
    auto [it, inserted] = cells_.try_emplace(c.id, c.state);
    if (!inserted && it->second != c.state) {
      if (c.state == db::CellState::kGone)
        Emit("cell_gone", 0, c.id, "cell " + c.id + " is gone: " + c.quarantine_reason);
      else if (c.state == db::CellState::kQuarantined)
        Emit("cell_quarantined", 0, c.id, "cell " + c.id + " quarantined: " + c.quarantine_reason);
      else if (it->second == db::CellState::kGone)
        Emit("cell_back", 0, c.id, "cell " + c.id + " is back");
      if (it->second == db::CellState::kQuarantined && c.state == db::CellState::kHealthy)
        suspenders_.CellReleased(c.id);  // `arena cells release`
    }
    it->second = c.state;
  }
  for (const auto& c : store_.ListCampaigns()) {
    auto [it, inserted] = campaigns_.try_emplace(c.id, c.state);
    if (!inserted && it->second != c.state && c.state == db::CampaignState::kDone)
      Emit("campaign_done", c.id, "",
           "campaign " + std::to_string(c.id) + " '" + c.name + "' done");
    it->second = c.state;
  }
  // The failure rate per campaign: told once when it passes the threshold
  // (at least 10 finished trials), again only after it fell back below.
  if (passes_ % 5 != 1) return;  // a heavier query: every fifth pass
  for (const auto& c : store_.Status().campaigns) {
    const std::int64_t finished = c.done + c.failed;
    if (finished < 10) continue;
    const double rate = static_cast<double>(c.failed) / static_cast<double>(finished);
    bool& high = failure_rate_high_[c.id];
    if (!high && rate > opt_.notify_failure_rate) {
      high = true;
      Emit("failure_rate_high", c.id, "",
           "campaign " + std::to_string(c.id) + ": " + std::to_string(c.failed) + " of " +
               std::to_string(finished) + " finished trials failed",
           {{"failed", c.failed}, {"finished", finished}, {"threshold", opt_.notify_failure_rate}});
    } else if (high && rate <= opt_.notify_failure_rate) {
      high = false;
    }
  }
}

}  // namespace arena::orchestrator
