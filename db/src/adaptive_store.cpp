// Adaptive samplers' rounds and decisions, and calibrations (migration 7;
// db/README.md, "sampler_decisions", "calibrations").
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db {
namespace {

using detail::Tx;

using detail::BadInput;

void RequireObject(const std::string& text, const std::string& what) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const std::exception& e) {
    BadInput(what + " is not valid JSON: " + e.what());
  }
  if (!j.is_object()) BadInput(what + " must be a JSON object");
}

void RequireFiniteNonNegative(double v, const std::string& what) {
  if (!std::isfinite(v) || v < 0)
    BadInput(what + " must be finite and >= 0, got " + std::to_string(v));
}

constexpr const char* kCalibrationCols =
    "SELECT id, campaign_id, created_at, params_json, settings_json, heldout_error_before,"
    " heldout_error_after, applied, report_json FROM calibrations";

Calibration ReadCalibration(const detail::Stmt& s) {
  Calibration c;
  c.id = s.Int(0);
  c.campaign_id = s.Int(1);
  c.created_at = s.Real(2);
  c.params_json = s.Text(3);
  c.settings_json = s.Text(4);
  c.heldout_error_before = s.Real(5);
  c.heldout_error_after = s.Real(6);
  c.applied = s.Int(7) != 0;
  c.report_json = s.Text(8);
  return c;
}

}  // namespace

namespace {

// @throws kBadInput for a round whose fields do not fit together.
void CheckRound(const AdaptiveRound& round, const char* fn) {
  if (round.round < 0) BadInput(std::string(fn) + ": round must be >= 0");
  if (round.reasons.size() != round.trials.size() || round.bases_json.size() != round.trials.size())
    BadInput(std::string(fn) + ": one reason and one basis per trial are required");
  for (std::size_t i = 0; i < round.trials.size(); ++i) {
    if (round.reasons[i].empty())
      BadInput(std::string(fn) + ": trial " + std::to_string(i) + ": reason is empty");
    RequireObject(round.bases_json[i],
                  std::string(fn) + ": trial " + std::to_string(i) + ": basis");
  }
  RequireObject(round.sampler_state_json, std::string(fn) + ": sampler_state_json");
  if (!round.open && round.stop_reason.empty())
    BadInput(std::string(fn) + ": a round that closes the sampler needs a stop_reason");
}

// The round's trials, one decision each (and a stop row when it closes the
// sampler), the sampler's state; inside the caller's write transaction.
void WriteRound(const Store::Impl& impl, std::int64_t campaign_id, const AdaptiveRound& round,
                const char* fn) {
  auto n = impl.Prepare("SELECT IFNULL(MAX(idx) + 1, 0) FROM trials WHERE campaign_id = ?");
  n->Bind(1, campaign_id);
  n->Step();
  const int first = static_cast<int>(n->Int(0));
  const std::vector<std::int64_t> ids =
      internal::InsertPlannedTrials(impl, campaign_id, first, round.trials, fn);
  const double now = impl.Now();
  auto ins = impl.Prepare(
      "INSERT INTO sampler_decisions(campaign_id, round, trial_id, reason, basis_json, created_at)"
      " VALUES(?,?,?,?,?,?)");
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ins->Bind(1, campaign_id)
        .Bind(2, round.round)
        .Bind(3, ids[i])
        .Bind(4, round.reasons[i])
        .Bind(5, round.bases_json[i])
        .Bind(6, now)
        .Run();
    ins->Reset();
  }
  if (!round.open) {
    ins->Bind(1, campaign_id)
        .Bind(2, round.round)
        .BindNull(3)
        .Bind(4, round.stop_reason)
        .Bind(5, std::string("{}"))
        .Bind(6, now)
        .Run();
    ins->Reset();
  }
  auto u = impl.Prepare(
      "UPDATE campaigns SET sampler_state_json = ?, sampler_open = ?, updated_at = ? WHERE id = ?");
  u->Bind(1, round.sampler_state_json)
      .Bind(2, round.open ? 1 : 0)
      .Bind(3, now)
      .Bind(4, campaign_id)
      .Run();
}

}  // namespace

bool Store::PlanAdaptiveRound(std::int64_t campaign_id, const std::string& expected_state_json,
                              const AdaptiveRound& round) {
  constexpr const char* kFn = "PlanAdaptiveRound";
  impl_->RequireWritable(kFn);
  CheckRound(round, kFn);

  Tx tx(impl_->db, true);
  const Campaign c = GetCampaign(campaign_id);
  if (c.state != CampaignState::kActive || !c.sampler_open ||
      c.sampler_state_json != expected_state_json)
    return false;
  // The trials of the rounds the decision was based on (a trial without a
  // decision counts as round 0).
  auto busy = impl_->Prepare(
      "SELECT 1 FROM trials t LEFT JOIN sampler_decisions d ON d.trial_id = t.id"
      " WHERE t.campaign_id = ? AND t.state NOT IN ('done','failed','cancelled')"
      " AND IFNULL(d.round, 0) <= ? LIMIT 1");
  busy->Bind(1, campaign_id)
      .Bind(2, static_cast<std::int64_t>(
                   round.known_through_round.value_or(std::numeric_limits<int>::max())));
  if (busy->Step()) return false;
  WriteRound(*impl_, campaign_id, round, kFn);
  internal::RegisterParameters(*impl_, campaign_id);  // a later round may bring a new name
  tx.Commit();
  return true;
}

std::int64_t Store::CreateAdaptiveCampaign(
    const NewCampaign& campaign,
    const std::function<AdaptiveRound(std::int64_t campaign_id)>& plan_first) {
  constexpr const char* kFn = "CreateAdaptiveCampaign";
  impl_->RequireWritable(kFn);
  if (!campaign.sampler_open)
    BadInput(std::string(kFn) + ": an adaptive campaign's sampler is open");
  Tx tx(impl_->db, true);  // rolled back by any exception: nothing of the campaign stays
  const std::int64_t id = internal::InsertCampaignRow(*impl_, campaign, kFn);
  const AdaptiveRound round = plan_first(id);
  CheckRound(round, kFn);
  WriteRound(*impl_, id, round, kFn);
  internal::RegisterParameters(*impl_, id);
  tx.Commit();
  return id;
}

std::vector<SamplerDecision> Store::ListDecisions(std::int64_t campaign_id) const {
  auto s = impl_->Prepare(
      "SELECT id, campaign_id, round, trial_id, reason, basis_json, created_at"
      " FROM sampler_decisions WHERE campaign_id = ? ORDER BY id");
  s->Bind(1, campaign_id);
  std::vector<SamplerDecision> out;
  while (s->Step()) {
    SamplerDecision d;
    d.id = s->Int(0);
    d.campaign_id = s->Int(1);
    d.round = static_cast<int>(s->Int(2));
    if (!s->IsNull(3)) d.trial_id = s->Int(3);
    d.reason = s->Text(4);
    d.basis_json = s->Text(5);
    d.created_at = s->Real(6);
    out.push_back(std::move(d));
  }
  return out;
}

std::int64_t Store::RecordCalibration(const Calibration& c) {
  constexpr const char* kFn = "RecordCalibration";
  impl_->RequireWritable(kFn);
  RequireObject(c.params_json, std::string(kFn) + ": params_json");
  RequireObject(c.settings_json, std::string(kFn) + ": settings_json");
  RequireObject(c.report_json, std::string(kFn) + ": report_json");
  RequireFiniteNonNegative(c.heldout_error_before, std::string(kFn) + ": heldout_error_before");
  RequireFiniteNonNegative(c.heldout_error_after, std::string(kFn) + ": heldout_error_after");
  Tx tx(impl_->db, true);
  GetCampaign(c.campaign_id);  // kNotFound
  auto s = impl_->Prepare(
      "INSERT INTO calibrations(campaign_id, created_at, params_json, settings_json,"
      " heldout_error_before, heldout_error_after, applied, report_json) VALUES(?,?,?,?,?,?,?,?)");
  s->Bind(1, c.campaign_id)
      .Bind(2, impl_->Now())
      .Bind(3, c.params_json)
      .Bind(4, c.settings_json)
      .Bind(5, c.heldout_error_before)
      .Bind(6, c.heldout_error_after)
      .Bind(7, c.applied ? 1 : 0)
      .Bind(8, c.report_json)
      .Run();
  const auto id = static_cast<std::int64_t>(sqlite3_last_insert_rowid(impl_->db));
  tx.Commit();
  return id;
}

Calibration Store::GetCalibration(std::int64_t calibration_id) const {
  auto s = impl_->Prepare(std::string(kCalibrationCols) + " WHERE id = ?");
  s->Bind(1, calibration_id);
  if (!s->Step()) {
    throw StoreError(StoreError::Kind::kNotFound,
                     "GetCalibration: no calibration " + std::to_string(calibration_id) +
                         " (see 'arena query \"SELECT * FROM calibrations\"')");
  }
  return ReadCalibration(*s);
}

std::vector<Calibration> Store::ListCalibrations(std::int64_t campaign_id) const {
  auto s = impl_->Prepare(std::string(kCalibrationCols) + " WHERE campaign_id = ? ORDER BY id");
  s->Bind(1, campaign_id);
  std::vector<Calibration> out;
  while (s->Step()) out.push_back(ReadCalibration(*s));
  return out;
}

}  // namespace arena::db
