// Suspensions and service events (issue 29): what paused dispatch, when it
// was lifted and by whom, and every event the service told the operator.
// Tables: db/README.md (suspensions, service_events).
#include <sqlite3.h>

#include <string>

#include "arena/db/store.hpp"
#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db {

using detail::Tx;

namespace {
constexpr const char* kSuspensionCols =
    "SELECT id, condition, scope, campaign_id, cell_id, rule, evidence, fired_at, lifted_at,"
    " lifted_by, lift_reason FROM suspensions";

Suspension ReadSuspension(const detail::Stmt& s) {
  Suspension r;
  r.id = s.Int(0);
  r.condition = s.Text(1);
  r.scope = s.Text(2);
  r.campaign_id = s.IsNull(3) ? 0 : s.Int(3);
  r.cell_id = s.IsNull(4) ? "" : s.Text(4);
  r.rule = s.Text(5);
  r.evidence = s.Text(6);
  r.fired_at = s.Real(7);
  r.lifted_at = s.OptReal(8);
  r.lifted_by = s.IsNull(9) ? "" : s.Text(9);
  r.lift_reason = s.IsNull(10) ? "" : s.Text(10);
  return r;
}

constexpr const char* kSuspendedPrefix = "suspended: ";

// Inside a write transaction: a campaign paused by its suspensions resumes
// when none of them holds any more (an operator's pause is left alone).
void ResumeIfNoneHolds(const Store::Impl& impl, std::int64_t campaign_id) {
  auto n = impl.Prepare(
      "SELECT count(*) FROM suspensions WHERE scope = 'campaign' AND campaign_id = ?"
      " AND lifted_at IS NULL");
  n->Bind(1, campaign_id);
  n->Step();
  if (n->Int(0) > 0) return;
  auto u = impl.Prepare(
      "UPDATE campaigns SET state = 'active', state_reason = '', updated_at = ?"
      " WHERE id = ? AND state = 'paused' AND state_reason LIKE 'suspended: %'");
  u->Bind(1, impl.Now()).Bind(2, campaign_id).Run();
}

void Lift(const Store::Impl& impl, const Suspension& s, const std::string& by,
          const std::string& reason) {
  auto u = impl.Prepare(
      "UPDATE suspensions SET lifted_at = ?, lifted_by = ?, lift_reason = ?"
      " WHERE id = ? AND lifted_at IS NULL");
  u->Bind(1, impl.Now()).Bind(2, by).Bind(3, reason).Bind(4, s.id).Run();
  if (s.scope == "campaign") ResumeIfNoneHolds(impl, s.campaign_id);
}

Suspension LoadSuspension(const Store::Impl& impl, std::int64_t id, const char* function) {
  auto s = impl.Prepare(std::string(kSuspensionCols) + " WHERE id = ?");
  s->Bind(1, id);
  if (!s->Step())
    throw StoreError(StoreError::Kind::kNotFound,
                     std::string(function) + ": no suspension " + std::to_string(id));
  return ReadSuspension(*s);
}
}  // namespace

std::int64_t Store::RecordSuspension(const Suspension& in) {
  impl_->RequireWritable("RecordSuspension");
  const char* f = "RecordSuspension";
  if (in.condition.empty())
    throw StoreError(StoreError::Kind::kBadInput, std::string(f) + ": condition is empty");
  if (in.scope == "cell" && in.cell_id.empty())
    throw StoreError(StoreError::Kind::kBadInput, std::string(f) + ": a cell scope needs cell_id");
  if (in.scope == "campaign" && in.campaign_id <= 0)
    throw StoreError(StoreError::Kind::kBadInput,
                     std::string(f) + ": a campaign scope needs campaign_id");
  if (in.scope != "cell" && in.scope != "campaign" && in.scope != "service")
    throw StoreError(
        StoreError::Kind::kBadInput,
        std::string(f) + ": scope must be cell, campaign or service, got '" + in.scope + "'");
  Tx tx(impl_->db, true);
  const double now = impl_->Now();
  if (in.scope == "campaign") {
    auto c = impl_->Prepare("SELECT state FROM campaigns WHERE id = ?");
    c->Bind(1, in.campaign_id);
    if (!c->Step())
      throw StoreError(StoreError::Kind::kNotFound,
                       std::string(f) + ": no campaign " + std::to_string(in.campaign_id));
    auto u = impl_->Prepare(
        "UPDATE campaigns SET state = 'paused', state_reason = ?, updated_at = ?"
        " WHERE id = ? AND state = 'active'");
    u->Bind(1, std::string(kSuspendedPrefix) + in.condition + ": " + in.evidence)
        .Bind(2, now)
        .Bind(3, in.campaign_id)
        .Run();
  }
  auto s = impl_->Prepare(
      "INSERT INTO suspensions(condition, scope, campaign_id, cell_id, rule, evidence, fired_at)"
      " VALUES(?,?,?,?,?,?,?)");
  s->Bind(1, in.condition).Bind(2, in.scope);
  if (in.scope == "campaign")
    s->Bind(3, in.campaign_id);
  else
    s->BindNull(3);
  if (in.scope == "cell")
    s->Bind(4, in.cell_id);
  else
    s->BindNull(4);
  s->Bind(5, in.rule).Bind(6, in.evidence).Bind(7, now).Run();
  const std::int64_t id = sqlite3_last_insert_rowid(impl_->db);
  tx.Commit();
  return id;
}

bool Store::LiftSuspension(std::int64_t id, const std::string& by, const std::string& reason) {
  impl_->RequireWritable("LiftSuspension");
  Tx tx(impl_->db, true);
  const Suspension s = LoadSuspension(*impl_, id, "LiftSuspension");
  if (s.lifted_at) return false;
  Lift(*impl_, s, by, reason);
  tx.Commit();
  return true;
}

std::vector<Suspension> Store::ResumeSuspended(std::int64_t campaign_id,
                                               const std::optional<std::string>& cell_id) {
  impl_->RequireWritable("ResumeSuspended");
  Tx tx(impl_->db, true);
  auto c = impl_->Prepare("SELECT state FROM campaigns WHERE id = ?");
  c->Bind(1, campaign_id);
  if (!c->Step())
    throw StoreError(StoreError::Kind::kNotFound,
                     "ResumeSuspended: no campaign " + std::to_string(campaign_id));
  const std::string state = c->Text(0);
  if (state == "done" || state == "cancelled")
    throw StoreError(StoreError::Kind::kIllegalTransition,
                     "ResumeSuspended: campaign " + std::to_string(campaign_id) + " is " + state +
                         ", nothing to resume");
  auto q =
      impl_->Prepare(std::string(kSuspensionCols) +
                     " WHERE lifted_at IS NULL AND ((scope = 'campaign' AND campaign_id = ?1)"
                     " OR scope = 'service' OR (scope = 'cell' AND cell_id = ?2)) ORDER BY id");
  q->Bind(1, campaign_id);
  if (cell_id)
    q->Bind(2, *cell_id);
  else
    q->BindNull(2);
  std::vector<Suspension> lifted;
  while (q->Step()) lifted.push_back(ReadSuspension(*q));
  for (auto& s : lifted) {
    Lift(*impl_, s, "arena resume", "lifted by the operator");
    s.lifted_by = "arena resume";
  }
  auto u = impl_->Prepare(
      "UPDATE campaigns SET state = 'active', state_reason = '', updated_at = ?"
      " WHERE id = ? AND state = 'paused'");
  u->Bind(1, impl_->Now()).Bind(2, campaign_id).Run();
  tx.Commit();
  return lifted;
}

std::vector<Suspension> Store::ListSuspensions(bool active_only, std::size_t limit) const {
  auto s =
      impl_->Prepare(std::string(kSuspensionCols) +
                     (active_only ? " WHERE lifted_at IS NULL" : "") + " ORDER BY id DESC LIMIT ?");
  s->Bind(1, static_cast<std::int64_t>(limit));
  std::vector<Suspension> out;
  while (s->Step()) out.push_back(ReadSuspension(*s));
  return out;
}

int Store::SetAsideTrials(std::int64_t campaign_id, const std::string& reason,
                          const std::string& rule) {
  impl_->RequireWritable("SetAsideTrials");
  Tx tx(impl_->db, true);
  auto q = impl_->Prepare(
      "SELECT id, attempt FROM trials WHERE campaign_id = ? AND state = 'planned' ORDER BY id");
  q->Bind(1, campaign_id);
  std::vector<std::pair<std::int64_t, int>> planned;
  while (q->Step()) planned.emplace_back(q->Int(0), static_cast<int>(q->Int(1)));
  for (auto [tid, attempt] : planned) {
    internal::WriteTransition(*impl_, tid, attempt, TrialState::kPlanned, TrialState::kFailed, "",
                              reason, rule, "SetAsideTrials");
    auto o = impl_->Prepare("UPDATE trials SET outcome = 'failed' WHERE id = ?");
    o->Bind(1, tid).Run();
  }
  tx.Commit();
  return static_cast<int>(planned.size());
}

std::int64_t Store::RecordEvent(const EventRecord& e) {
  impl_->RequireWritable("RecordEvent");
  if (e.kind.empty()) throw StoreError(StoreError::Kind::kBadInput, "RecordEvent: kind is empty");
  Tx tx(impl_->db, true);
  auto s = impl_->Prepare(
      "INSERT INTO service_events(at, kind, campaign_id, cell_id, message, event_json)"
      " VALUES(?,?,?,?,?,?)");
  s->Bind(1, e.at > 0 ? e.at : impl_->Now()).Bind(2, e.kind);
  if (e.campaign_id > 0)
    s->Bind(3, e.campaign_id);
  else
    s->BindNull(3);
  if (!e.cell_id.empty())
    s->Bind(4, e.cell_id);
  else
    s->BindNull(4);
  s->Bind(5, e.message).Bind(6, e.event_json).Run();
  const std::int64_t id = sqlite3_last_insert_rowid(impl_->db);
  tx.Commit();
  return id;
}

std::vector<EventRecord> Store::ListEvents(std::int64_t after_id, std::size_t limit) const {
  auto s = impl_->Prepare(
      "SELECT id, at, kind, campaign_id, cell_id, message, event_json FROM service_events"
      " WHERE id > ? ORDER BY id LIMIT ?");
  s->Bind(1, after_id).Bind(2, static_cast<std::int64_t>(limit));
  std::vector<EventRecord> out;
  while (s->Step()) {
    EventRecord e;
    e.id = s->Int(0);
    e.at = s->Real(1);
    e.kind = s->Text(2);
    e.campaign_id = s->IsNull(3) ? 0 : s->Int(3);
    e.cell_id = s->IsNull(4) ? "" : s->Text(4);
    e.message = s->Text(5);
    e.event_json = s->Text(6);
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace arena::db
