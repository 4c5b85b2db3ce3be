// The claim gate's store side (issue 26, migration 18): what active
// campaigns' planned trials need of a cell, and the campaigns that wait
// because no live cell can host them. Tables: db/README.md (campaign_waits).
#include <sqlite3.h>

#include <string>

#include "arena/db/store.hpp"
#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db {

using detail::Tx;

std::vector<PlannedNeed> Store::PlannedNeeds(std::size_t limit) const {
  // Grouped per campaign; each campaign's groups are capped by the row
  // number (a million planned trials of one campaign are few groups).
  auto s = impl_->Prepare(
      "SELECT campaign_id, contact_mask, x, y, z, speed, defects_json, n FROM ("
      " SELECT t.campaign_id, t.contact_mask, t.nominal_x AS x, t.nominal_y AS y,"
      " t.nominal_z AS z, coalesce(t.pusher_speed, 0) AS speed, t.defects_json, count(*) AS n,"
      " row_number() OVER (PARTITION BY t.campaign_id ORDER BY min(t.idx)) AS k"
      " FROM trials t JOIN campaigns c ON c.id = t.campaign_id"
      " WHERE c.state = 'active' AND t.state = 'planned'"
      " GROUP BY t.campaign_id, t.contact_mask, x, y, z, speed, t.defects_json)"
      " WHERE k <= ? ORDER BY campaign_id, k");
  s->Bind(1, static_cast<std::int64_t>(limit));
  std::vector<PlannedNeed> out;
  while (s->Step()) {
    PlannedNeed n;
    n.campaign_id = s->Int(0);
    n.contact_mask = static_cast<int>(s->Int(1));
    for (int k = 0; k < 3; ++k) n.position[k] = s->Real(2 + k);
    n.pusher_speed = s->Real(5);
    n.defects_json = s->Text(6);
    n.trials = s->Int(7);
    out.push_back(std::move(n));
  }
  return out;
}

void Store::SetCampaignWait(std::int64_t campaign_id, const std::string& kind,
                            const std::string& reason, const std::string& rule) {
  impl_->RequireWritable("SetCampaignWait");
  if (kind != "defects" && kind != "contact_types" && kind != "workspace" && kind != "pusher_speed")
    throw StoreError(StoreError::Kind::kBadInput,
                     "SetCampaignWait: kind '" + kind +
                         "' is not defects, contact_types, workspace or pusher_speed");
  if (reason.empty())
    throw StoreError(StoreError::Kind::kBadInput, "SetCampaignWait: reason is empty");
  Tx tx(impl_->db, true);
  auto c = impl_->Prepare("SELECT 1 FROM campaigns WHERE id = ?");
  c->Bind(1, campaign_id);
  if (!c->Step())
    throw StoreError(StoreError::Kind::kNotFound,
                     "SetCampaignWait: no campaign " + std::to_string(campaign_id));
  // The same wait keeps its `since` (the gate re-decides every few seconds).
  auto s = impl_->Prepare(
      "INSERT INTO campaign_waits(campaign_id, kind, reason, rule, since) VALUES(?,?,?,?,?)"
      " ON CONFLICT(campaign_id) DO UPDATE SET kind = excluded.kind, reason = excluded.reason,"
      " rule = excluded.rule, since = CASE WHEN kind = excluded.kind AND reason = excluded.reason"
      " THEN since ELSE excluded.since END");
  s->Bind(1, campaign_id).Bind(2, kind).Bind(3, reason).Bind(4, rule).Bind(5, impl_->Now()).Run();
  tx.Commit();
}

bool Store::ClearCampaignWait(std::int64_t campaign_id) {
  impl_->RequireWritable("ClearCampaignWait");
  Tx tx(impl_->db, true);
  auto s = impl_->Prepare("DELETE FROM campaign_waits WHERE campaign_id = ?");
  s->Bind(1, campaign_id).Run();
  const bool cleared = sqlite3_changes(impl_->db) > 0;
  tx.Commit();
  return cleared;
}

std::vector<CampaignWait> Store::ListCampaignWaits() const {
  auto s = impl_->Prepare(
      "SELECT campaign_id, kind, reason, rule, since FROM campaign_waits ORDER BY campaign_id");
  std::vector<CampaignWait> out;
  while (s->Step()) {
    CampaignWait w;
    w.campaign_id = s->Int(0);
    w.kind = s->Text(1);
    w.reason = s->Text(2);
    w.rule = s->Text(3);
    w.since = s->Real(4);
    out.push_back(std::move(w));
  }
  return out;
}

void Store::RestrictClaimsTo(std::optional<std::vector<std::int64_t>> campaigns) {
  if (!campaigns) {
    impl_->claimable.reset();
    return;
  }
  impl_->claimable.emplace(campaigns->begin(), campaigns->end());
}

std::vector<std::int64_t> Store::ActiveCampaignIds() const {
  auto s = impl_->Prepare("SELECT id FROM campaigns WHERE state = 'active' ORDER BY id");
  std::vector<std::int64_t> out;
  while (s->Step()) out.push_back(s->Int(0));
  return out;
}

}  // namespace arena::db
