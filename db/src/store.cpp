// Campaigns, the trial state machine, cells and the status summary.
// The state machine's diagram and its transition table are in store.hpp.
#include "arena/db/store.hpp"

#include "arena/db/prediction_status.hpp"
#include "arena/db/retry_rule.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db {

using detail::StmtRef;
using detail::Tx;
using nlohmann::json;

// ---------------------------------------------------------------- enums

const char* ToString(TrialState s) {
  switch (s) {
    case TrialState::kPlanned:
      return "planned";
    case TrialState::kDispatched:
      return "dispatched";
    case TrialState::kExecuted:
      return "executed";
    case TrialState::kResetting:
      return "resetting";
    case TrialState::kResetDone:
      return "reset_done";
    case TrialState::kResetFailed:
      return "reset_failed";
    case TrialState::kPredicted:
      return "predicted";
    case TrialState::kDone:
      return "done";
    case TrialState::kFailed:
      return "failed";
    case TrialState::kCancelled:
      return "cancelled";
  }
  return "?";
}

std::optional<TrialState> ParseTrialState(const std::string& text) {
  for (int i = 0; i <= static_cast<int>(TrialState::kCancelled); ++i) {
    const auto s = static_cast<TrialState>(i);
    if (text == ToString(s)) return s;
  }
  return std::nullopt;
}

bool IsTerminal(TrialState s) {
  return s == TrialState::kDone || s == TrialState::kFailed || s == TrialState::kCancelled;
}

bool IsLegalTransition(TrialState from, TrialState to) {
  using S = TrialState;
  if (to == S::kFailed) return !IsTerminal(from);
  switch (from) {
    case S::kPlanned:
      return to == S::kDispatched || to == S::kCancelled;
    case S::kDispatched:
      return to == S::kExecuted || to == S::kPlanned;
    case S::kExecuted:
      return to == S::kResetting;
    case S::kResetting:
      return to == S::kResetDone || to == S::kResetFailed;
    case S::kResetDone:
      return to == S::kPredicted;
    case S::kResetFailed:
      return to == S::kResetting || to == S::kPredicted;
    case S::kPredicted:
      return to == S::kDone;
    default:
      return false;
  }
}

const char* ToString(CampaignState s) {
  switch (s) {
    case CampaignState::kActive:
      return "active";
    case CampaignState::kPaused:
      return "paused";
    case CampaignState::kCancelled:
      return "cancelled";
    case CampaignState::kDone:
      return "done";
  }
  return "?";
}

const char* ToString(CellState s) {
  switch (s) {
    case CellState::kHealthy:
      return "healthy";
    case CellState::kQuarantined:
      return "quarantined";
    case CellState::kGone:
      return "gone";
  }
  return "?";
}

const char* ToString(PredictionStatus s) {
  switch (s) {
    case PredictionStatus::kOk:
      return "ok";
    case PredictionStatus::kSolverFailure:
      return "solver_failure";
    case PredictionStatus::kInvalidScene:
      return "invalid_scene";
    case PredictionStatus::kError:
      return "error";
    case PredictionStatus::kDiverged:
      return "diverged";
  }
  return "?";
}

std::optional<PredictionStatus> ParsePredictionStatus(const std::string& text) {
  for (auto s :
       {PredictionStatus::kOk, PredictionStatus::kSolverFailure, PredictionStatus::kInvalidScene,
        PredictionStatus::kError, PredictionStatus::kDiverged})
    if (text == ToString(s)) return s;
  return std::nullopt;
}

const char* ToString(TrialEnd o) {
  switch (o) {
    case TrialEnd::kNone:
      return "";
    case TrialEnd::kOk:
      return "ok";
    case TrialEnd::kSolverFailure:
      return "solver_failure";
    case TrialEnd::kInvalidScene:
      return "invalid_scene";
    case TrialEnd::kRefused:
      return "refused";
    case TrialEnd::kFailed:
      return "failed";
    case TrialEnd::kCancelled:
      return "cancelled";
  }
  return "?";
}

std::optional<TrialEnd> ParseTrialEnd(const std::string& text) {
  for (auto o : {TrialEnd::kNone, TrialEnd::kOk, TrialEnd::kSolverFailure, TrialEnd::kInvalidScene,
                 TrialEnd::kRefused, TrialEnd::kFailed, TrialEnd::kCancelled})
    if (text == ToString(o)) return o;
  return std::nullopt;
}

PredictionStatus StoredPredictionStatus(const std::string& text) {
  if (text == "left_geometry") return PredictionStatus::kDiverged;
  return ParsePredictionStatus(text).value_or(PredictionStatus::kError);
}

namespace {

CampaignState ParseCampaignState(const std::string& t) {
  for (auto s : {CampaignState::kActive, CampaignState::kPaused, CampaignState::kCancelled,
                 CampaignState::kDone}) {
    if (t == ToString(s)) return s;
  }
  throw StoreError(StoreError::Kind::kCorrupt, "campaigns.state has unknown value '" + t + "'");
}

CellState ParseCellState(const std::string& t) {
  for (auto s : {CellState::kHealthy, CellState::kQuarantined, CellState::kGone}) {
    if (t == ToString(s)) return s;
  }
  throw StoreError(StoreError::Kind::kCorrupt, "cells.state has unknown value '" + t + "'");
}

TrialState MustParseTrialState(const std::string& t) {
  auto s = ParseTrialState(t);
  if (!s)
    throw StoreError(StoreError::Kind::kCorrupt, "trials.state has unknown value '" + t + "'");
  return *s;
}

using detail::BadInput;

// Seeds are uint64; SQLite integers are int64: stored bit for bit.
std::int64_t SeedToDb(std::uint64_t v) {
  std::int64_t out;
  std::memcpy(&out, &v, 8);
  return out;
}
std::uint64_t SeedFromDb(std::int64_t v) {
  std::uint64_t out;
  std::memcpy(&out, &v, 8);
  return out;
}

json ParseObject(const std::string& text, const std::string& what) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::out_of_range& e) {  // 1e999: valid JSON, no double holds it
    BadInput(what + " holds a number out of range (beyond a double): " + e.what());
  } catch (const json::exception& e) {
    BadInput(what + " is not valid JSON: " + e.what());
  }
  if (!j.is_object()) BadInput(what + " must be a JSON object");
  return j;
}

void RequireFinite(double v, const std::string& what) {
  if (!std::isfinite(v)) BadInput(what + " is " + (std::isnan(v) ? "NaN" : "infinite"));
}

int TypeBit(const std::string& t, const std::string& where) {
  if (t == "point") return kPointBit;
  if (t == "line") return kLineBit;
  if (t == "patch") return kPatchBit;
  BadInput(where + " is '" + t + "'; expected point, line or patch");
}

// The caller's facts of a scene (scene_facts.hpp), checked before they are
// stored: no NaN, no unknown contact type, at least one contact.
void CheckSceneFacts(const SceneFacts& f, const std::string& where) {
  for (auto [name, v] :
       {std::pair{"object_mass", f.object_mass}, std::pair{"grip_force", f.grip_force},
        std::pair{"finger_mu", f.finger_mu}, std::pair{"pusher_mu", f.pusher_mu},
        std::pair{"pusher_speed", f.pusher_speed},
        std::pair{"pusher_angular_speed", f.pusher_angular_speed},
        std::pair{"duration", f.duration}}) {
    if (v) RequireFinite(*v, where + "." + name);
  }
  for (std::size_t i = 0; i < f.nominal.size(); ++i)
    RequireFinite(f.nominal[i], where + ".nominal[" + std::to_string(i) + "]");
  if (f.finger_type && *f.finger_type != "mixed") TypeBit(*f.finger_type, where + ".finger_type");
  if (f.pusher_type) TypeBit(*f.pusher_type, where + ".pusher_type");
  if (f.finger_count < 0) BadInput(where + ".finger_count must be >= 0");
  if (f.contact_mask < 0 || f.contact_mask > (kPointBit | kLineBit | kPatchBit))
    BadInput(where + ".contact_mask " + std::to_string(f.contact_mask) + " is not a set of types");
}

}  // namespace

namespace internal {

TrialRow LoadTrialRow(const Store::Impl& impl, std::int64_t trial_id, const char* function) {
  auto s = impl.Prepare(
      "SELECT state, attempt, IFNULL(cell_id,''), campaign_id, gt_stream_id FROM trials WHERE id = "
      "?");
  s->Bind(1, trial_id);
  if (!s->Step()) {
    throw StoreError(StoreError::Kind::kNotFound,
                     std::string(function) + ": no trial " + std::to_string(trial_id));
  }
  TrialRow r;
  r.state = MustParseTrialState(s->Text(0));
  r.attempt = static_cast<int>(s->Int(1));
  r.cell_id = s->Text(2);
  r.campaign_id = s->Int(3);
  if (!s->IsNull(4)) r.gt_stream_id = s->Int(4);
  return r;
}

void CheckAttempt(const TrialRow& row, std::int64_t trial_id, int attempt, const char* function) {
  if (row.attempt != attempt) {
    throw StoreError(StoreError::Kind::kStaleAttempt,
                     std::string(function) + ": trial " + std::to_string(trial_id) +
                         " is at attempt " + std::to_string(row.attempt) + ", not " +
                         std::to_string(attempt) + " (a late message from an earlier attempt?)");
  }
}

void CheckEdge(TrialState from, TrialState to, std::int64_t trial_id, const char* function) {
  if (!IsLegalTransition(from, to)) {
    throw StoreError(StoreError::Kind::kIllegalTransition,
                     std::string(function) + ": trial " + std::to_string(trial_id) + " cannot go " +
                         ToString(from) + " -> " + ToString(to));
  }
}

void WriteTransition(const Store::Impl& impl, std::int64_t trial_id, int attempt, TrialState from,
                     TrialState to, const std::string& cell_id, const std::string& reason,
                     std::string_view rule, const char* function) {
  CheckEdge(from, to, trial_id, function);
  const double now = impl.Now();
  {
    auto u = impl.Prepare(
        "UPDATE trials SET state = ?, updated_at = ?,"
        " finished_at = CASE WHEN ? THEN ? ELSE finished_at END WHERE id = ?");
    u->Bind(1, ToString(to))
        .Bind(2, now)
        .Bind(3, IsTerminal(to) ? 1 : 0)
        .Bind(4, now)
        .Bind(5, trial_id);
    u->Run();
  }
  auto a = impl.Prepare(
      "INSERT INTO trial_transitions(trial_id, attempt, from_state, to_state, at, cell_id, reason,"
      " rule) VALUES(?,?,?,?,?,?,?,?)");
  a->Bind(1, trial_id)
      .Bind(2, attempt)
      .Bind(3, ToString(from))
      .Bind(4, ToString(to))
      .Bind(5, now)
      .Bind(6, cell_id)
      .Bind(7, reason)
      .Bind(8, std::string(rule));
  a->Run();
}

}  // namespace internal

using internal::CheckAttempt;
using internal::LoadTrialRow;
using internal::QuatAngle;
using internal::WriteTransition;

int ContactTypeMask(const std::vector<std::string>& types) {
  int mask = 0;
  for (const auto& t : types) mask |= TypeBit(t, "ContactTypeMask: contact type");
  return mask;
}

// ---------------------------------------------------------------- campaigns

namespace internal {

std::int64_t InsertCampaignRow(const Store::Impl& impl, const NewCampaign& campaign,
                               const char* function) {
  if (campaign.name.empty()) BadInput(std::string(function) + ": name is empty");
  ParseObject(campaign.spec_json, std::string(function) + ": spec_json");
  ParseObject(campaign.sampler_state_json, std::string(function) + ": sampler_state_json");
  const double now = impl.Now();
  auto s = impl.Prepare(
      "INSERT INTO campaigns(name, spec_json, state, priority, seed, sampler_state_json, "
      "created_at, updated_at, sampler_open) VALUES(?,?,'active',?,?,?,?,?,?)");
  s->Bind(1, campaign.name)
      .Bind(2, campaign.spec_json)
      .Bind(3, campaign.priority)
      .Bind(4, SeedToDb(campaign.seed))
      .Bind(5, campaign.sampler_state_json)
      .Bind(6, now)
      .Bind(7, now)
      .Bind(8, campaign.sampler_open ? 1 : 0);
  s->Run();
  return static_cast<std::int64_t>(sqlite3_last_insert_rowid(impl.db));
}

std::vector<std::int64_t> InsertPlannedTrials(const Store::Impl& impl, std::int64_t campaign_id,
                                              int first_index,
                                              const std::vector<PlannedTrial>& trials,
                                              const char* function) {
  std::vector<std::int64_t> ids;
  const double now = impl.Now();
  auto ins = impl.Prepare(
      "INSERT INTO trials(campaign_id, idx, condition, replicate, seed, state, attempt,"
      " object_shape, object_mass, grip_force, finger_type, finger_count, finger_mu, pusher_type,"
      " pusher_mu, pusher_speed, pusher_angular_speed, duration, contact_mask,"
      " nominal_x, nominal_y, nominal_z, nominal_qw, nominal_qx, nominal_qy, nominal_qz,"
      " scene_json, params_json, defects_json, created_at, updated_at)"
      " VALUES(?,?,?,?,?,'planned',1,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
  auto audit = impl.Prepare(
      "INSERT INTO trial_transitions(trial_id, attempt, from_state, to_state, at, reason, rule)"
      " VALUES(?,1,'','planned',?,'sampled','sampler.planned')");
  for (std::size_t i = 0; i < trials.size(); ++i) {
    const auto& t = trials[i];
    const std::string where = std::string(function) + ": trial " + std::to_string(i);
    if (t.condition < 0) BadInput(where + ": condition must be >= 0");
    if (t.replicate < 0) BadInput(where + ": replicate must be >= 0");
    const SceneFacts& c = t.facts;
    ParseObject(t.scene_json, where + ": scene");
    CheckSceneFacts(c, where + ": scene facts");
    ParseObject(t.params_json, where + ": params_json");
    ParseObject(t.defects_json, where + ": defects_json");
    if (c.contact_mask == 0) BadInput(where + ": scene has no fingers or pusher");
    auto& s = *ins;
    detail::Binder b(s);
    b << campaign_id << first_index + static_cast<int>(i) << t.condition << t.replicate
      << SeedToDb(t.seed) << c.object_shape << c.object_mass << c.grip_force << c.finger_type
      << c.finger_count << c.finger_mu << c.pusher_type << c.pusher_mu << c.pusher_speed
      << c.pusher_angular_speed << c.duration << c.contact_mask;
    for (double v : c.nominal) b << v;
    b << t.scene_json << t.params_json << t.defects_json << now << now;
    s.Run();
    s.Reset();
    ids.push_back(static_cast<std::int64_t>(sqlite3_last_insert_rowid(impl.db)));
    audit->Bind(1, ids.back()).Bind(2, now).Run();
    audit->Reset();
  }
  return ids;
}

}  // namespace internal

namespace {
using internal::InsertPlannedTrials;

Campaign ReadCampaign(const detail::Stmt& s) {
  Campaign c;
  c.id = s.Int(0);
  c.name = s.Text(1);
  c.spec_json = s.Text(2);
  c.state = ParseCampaignState(s.Text(3));
  c.priority = static_cast<int>(s.Int(4));
  c.seed = SeedFromDb(s.Int(5));
  c.sampler_state_json = s.Text(6);
  c.created_at = s.Real(7);
  c.updated_at = s.Real(8);
  c.state_reason = s.Text(9);
  c.sampler_open = s.Int(10) != 0;
  return c;
}

constexpr const char* kCampaignCols =
    "SELECT id, name, spec_json, state, priority, seed, sampler_state_json, created_at, updated_at,"
    " state_reason, sampler_open FROM campaigns";

}  // namespace

std::int64_t Store::CreateCampaign(const NewCampaign& campaign,
                                   const std::vector<PlannedTrial>& trials) {
  impl_->RequireWritable("CreateCampaign");
  if (campaign.name.empty()) BadInput("CreateCampaign: name is empty");
  ParseObject(campaign.spec_json, "CreateCampaign: spec_json");
  ParseObject(campaign.sampler_state_json, "CreateCampaign: sampler_state_json");
  Tx tx(impl_->db, true);
  const std::int64_t id = internal::InsertCampaignRow(*impl_, campaign, "CreateCampaign");
  InsertPlannedTrials(*impl_, id, 0, trials, "CreateCampaign");
  internal::RegisterParameters(*impl_, id);
  tx.Commit();
  return id;
}

std::int64_t Store::CreateCampaign(const NewCampaign& campaign,
                                   const std::function<std::vector<PlannedTrial>()>& next_chunk) {
  impl_->RequireWritable("CreateCampaign");
  if (campaign.name.empty()) BadInput("CreateCampaign: name is empty");
  ParseObject(campaign.spec_json, "CreateCampaign: spec_json");
  ParseObject(campaign.sampler_state_json, "CreateCampaign: sampler_state_json");
  Tx tx(impl_->db, true);  // rolled back by any exception: nothing of the campaign stays
  const std::int64_t id = internal::InsertCampaignRow(*impl_, campaign, "CreateCampaign");
  int first = 0;
  for (;;) {
    const std::vector<PlannedTrial> chunk = next_chunk();
    if (chunk.empty()) break;
    InsertPlannedTrials(*impl_, id, first, chunk, "CreateCampaign");
    first += static_cast<int>(chunk.size());
  }
  internal::RegisterParameters(*impl_, id);
  tx.Commit();
  return id;
}

void Store::AppendPlannedTrials(std::int64_t campaign_id, const std::vector<PlannedTrial>& trials,
                                const std::string& sampler_state_json) {
  impl_->RequireWritable("AppendPlannedTrials");
  ParseObject(sampler_state_json, "AppendPlannedTrials: sampler_state_json");
  Tx tx(impl_->db, true);
  const Campaign c = GetCampaign(campaign_id);
  if (c.state == CampaignState::kCancelled || c.state == CampaignState::kDone) {
    BadInput("AppendPlannedTrials: campaign " + std::to_string(campaign_id) + " is " +
             ToString(c.state));
  }
  auto n = impl_->Prepare("SELECT IFNULL(MAX(idx) + 1, 0) FROM trials WHERE campaign_id = ?");
  n->Bind(1, campaign_id);
  n->Step();
  const int first = static_cast<int>(n->Int(0));
  InsertPlannedTrials(*impl_, campaign_id, first, trials, "AppendPlannedTrials");
  internal::RegisterParameters(*impl_, campaign_id);
  auto u =
      impl_->Prepare("UPDATE campaigns SET sampler_state_json = ?, updated_at = ? WHERE id = ?");
  u->Bind(1, sampler_state_json).Bind(2, impl_->Now()).Bind(3, campaign_id).Run();
  tx.Commit();
}

Campaign Store::GetCampaign(std::int64_t campaign_id) const {
  auto s = impl_->Prepare(std::string(kCampaignCols) + " WHERE id = ?");
  s->Bind(1, campaign_id);
  if (!s->Step()) {
    throw StoreError(
        StoreError::Kind::kNotFound,
        "GetCampaign: no campaign " + std::to_string(campaign_id) + " (see 'arena list')");
  }
  return ReadCampaign(*s);
}

std::vector<Campaign> Store::ListCampaigns() const {
  auto s = impl_->Prepare(std::string(kCampaignCols) + " ORDER BY id");
  std::vector<Campaign> out;
  while (s->Step()) out.push_back(ReadCampaign(*s));
  return out;
}

namespace {

void SetCampaignState(Store::Impl& impl, std::int64_t id, const char* function,
                      std::initializer_list<CampaignState> from, CampaignState to,
                      const std::string& reason) {
  impl.RequireWritable(function);
  Tx tx(impl.db, true);
  auto s = impl.Prepare("SELECT state FROM campaigns WHERE id = ?");
  s->Bind(1, id);
  if (!s->Step()) {
    throw StoreError(StoreError::Kind::kNotFound,
                     std::string(function) + ": no campaign " + std::to_string(id));
  }
  const CampaignState cur = ParseCampaignState(s->Text(0));
  if (cur == to) return;  // idempotent: pausing a paused campaign is a no-op
  if (std::find(from.begin(), from.end(), cur) == from.end()) {
    throw StoreError(StoreError::Kind::kIllegalTransition,
                     std::string(function) + ": campaign " + std::to_string(id) + " is " +
                         ToString(cur) + ", cannot become " + ToString(to));
  }
  auto u =
      impl.Prepare("UPDATE campaigns SET state = ?, state_reason = ?, updated_at = ? WHERE id = ?");
  u->Bind(1, ToString(to)).Bind(2, reason).Bind(3, impl.Now()).Bind(4, id).Run();
  if (to == CampaignState::kCancelled) {
    auto q =
        impl.Prepare("SELECT id, attempt FROM trials WHERE campaign_id = ? AND state = 'planned'");
    q->Bind(1, id);
    std::vector<std::pair<std::int64_t, int>> planned;
    while (q->Step()) planned.emplace_back(q->Int(0), static_cast<int>(q->Int(1)));
    for (auto [tid, attempt] : planned) {
      WriteTransition(impl, tid, attempt, TrialState::kPlanned, TrialState::kCancelled, "",
                      "campaign cancelled: " + reason, "operator.cancel_campaign", function);
      auto o = impl.Prepare("UPDATE trials SET outcome = 'cancelled' WHERE id = ?");
      o->Bind(1, tid).Run();
    }
  }
  tx.Commit();
}

}  // namespace

void Store::PauseCampaign(std::int64_t id, const std::string& reason) {
  SetCampaignState(*impl_, id, "PauseCampaign", {CampaignState::kActive}, CampaignState::kPaused,
                   reason);
}
void Store::ResumeCampaign(std::int64_t id) {
  SetCampaignState(*impl_, id, "ResumeCampaign", {CampaignState::kPaused}, CampaignState::kActive,
                   "");
}
void Store::CancelCampaign(std::int64_t id, const std::string& reason) {
  SetCampaignState(*impl_, id, "CancelCampaign", {CampaignState::kActive, CampaignState::kPaused},
                   CampaignState::kCancelled, reason);
}

std::vector<std::int64_t> Store::CompleteFinishedCampaigns() {
  impl_->RequireWritable("CompleteFinishedCampaigns");
  Tx tx(impl_->db, true);
  auto s = impl_->Prepare(
      "SELECT c.id FROM campaigns c WHERE c.state = 'active' AND c.sampler_open = 0"
      " AND NOT EXISTS ("
      " SELECT 1 FROM trials t WHERE t.campaign_id = c.id"
      " AND t.state NOT IN ('done','failed','cancelled'))");
  std::vector<std::int64_t> ids;
  while (s->Step()) ids.push_back(s->Int(0));
  for (auto id : ids) {
    auto u = impl_->Prepare("UPDATE campaigns SET state = 'done', updated_at = ? WHERE id = ?");
    u->Bind(1, impl_->Now()).Bind(2, id).Run();
  }
  tx.Commit();
  return ids;
}

// ---------------------------------------------------------------- state machine

namespace {

// Campaigns in scheduling order, then the first eligible planned trial of
// each: both walk an index, so a claim costs the same with 10 or 10^6
// planned trials (one ORDER BY over all planned trials would not).
constexpr const char* kActiveCampaignsSql =
    "SELECT id FROM campaigns WHERE state = 'active'"
    " AND id NOT IN (SELECT campaign_id FROM campaign_waits)"  // the claim gate (issue 26)
    " ORDER BY priority DESC, id";
constexpr const char* kNextTrialSql =
    "SELECT id, campaign_id, attempt, seed, scene_json, defects_json, idx FROM trials"
    " WHERE state = 'planned' AND campaign_id = ? AND not_before <= ? AND (contact_mask & ~?) = 0"
    " ORDER BY idx LIMIT ?";

// The first `limit` claimable trials of the first campaign (by priority) that
// has any; empty when the cell is not healthy or nothing is claimable.
std::vector<ClaimedTrial> FindWindow(const Store::Impl& impl, const std::string& cell_id, int limit,
                                     const char* function) {
  auto cell = impl.Prepare("SELECT state, contact_mask FROM cells WHERE id = ?");
  cell->Bind(1, cell_id);
  if (!cell->Step()) {
    throw StoreError(StoreError::Kind::kNotFound,
                     std::string(function) + ": unknown cell '" + cell_id + "' (UpsertCell first)");
  }
  std::vector<ClaimedTrial> out;
  if (cell->Text(0) != "healthy") return out;
  const std::int64_t mask = cell->Int(1);
  std::vector<std::int64_t> campaigns;
  {
    auto c = impl.Prepare(kActiveCampaignsSql);
    while (c->Step()) campaigns.push_back(c->Int(0));
  }
  const double now = impl.Now();
  for (const auto campaign : campaigns) {
    if (impl.claimable && !impl.claimable->count(campaign)) continue;  // RestrictClaimsTo
    auto s = impl.Prepare(kNextTrialSql);
    s->Bind(1, campaign).Bind(2, now).Bind(3, mask).Bind(4, static_cast<std::int64_t>(limit));
    while (s->Step()) {
      ClaimedTrial t;
      t.trial_id = s->Int(0);
      t.campaign_id = s->Int(1);
      t.attempt = static_cast<int>(s->Int(2));
      t.seed = SeedFromDb(s->Int(3));
      t.scene_json = s->Text(4);
      t.defects_json = s->Text(5);
      t.index = s->Int(6);
      out.push_back(std::move(t));
    }
    if (!out.empty()) return out;
  }
  return out;
}

std::optional<ClaimedTrial> FindNext(const Store::Impl& impl, const std::string& cell_id,
                                     const char* function) {
  auto w = FindWindow(impl, cell_id, 1, function);
  if (w.empty()) return std::nullopt;
  return w.front();
}

// Moves the found trial to dispatched on the cell (ClaimNextTrial's contract);
// the caller holds the write transaction.
// `reason`: "claimed", or with the chooser's rule ("claimed by claim.least_change").
void ClaimFound(const Store::Impl& impl, const ClaimedTrial& t, const std::string& cell_id,
                const std::string& reason, const char* function);

}  // namespace

std::vector<ClaimedTrial> Store::ClaimWindow(const std::string& cell_id, int limit) const {
  if (limit < 1 || limit > 1000) BadInput("ClaimWindow: limit must be 1..1000");
  Tx tx(impl_->db, false);
  auto w = FindWindow(*impl_, cell_id, limit, "ClaimWindow");
  tx.Commit();
  return w;
}

std::optional<ClaimedTrial> Store::ClaimTrial(const std::string& cell_id, std::int64_t trial_id,
                                              std::string_view rule) {
  impl_->RequireWritable("ClaimTrial");
  Tx tx(impl_->db, true);  // find + update: one atomic step, as ClaimNextTrial
  // Still claimable: the window's filters, this trial only.
  auto cell = impl_->Prepare("SELECT state, contact_mask FROM cells WHERE id = ?");
  cell->Bind(1, cell_id);
  if (!cell->Step()) {
    throw StoreError(StoreError::Kind::kNotFound,
                     "ClaimTrial: unknown cell '" + cell_id + "' (UpsertCell first)");
  }
  if (cell->Text(0) != "healthy") return std::nullopt;
  auto s = impl_->Prepare(
      "SELECT t.id, t.campaign_id, t.attempt, t.seed, t.scene_json, t.defects_json, t.idx"
      " FROM trials AS t JOIN campaigns AS c ON c.id = t.campaign_id"
      " WHERE t.id = ? AND t.state = 'planned' AND c.state = 'active' AND t.not_before <= ?"
      " AND (t.contact_mask & ~?) = 0");
  s->Bind(1, trial_id).Bind(2, impl_->Now()).Bind(3, cell->Int(1));
  if (!s->Step()) return std::nullopt;
  if (impl_->claimable && !impl_->claimable->count(s->Int(1))) return std::nullopt;
  ClaimedTrial t;
  t.trial_id = s->Int(0);
  t.campaign_id = s->Int(1);
  t.attempt = static_cast<int>(s->Int(2));
  t.seed = SeedFromDb(s->Int(3));
  t.scene_json = s->Text(4);
  t.defects_json = s->Text(5);
  t.index = s->Int(6);
  ClaimFound(*impl_, t, cell_id, "claimed by " + std::string(rule), "ClaimTrial");
  tx.Commit();
  return t;
}

void Store::RecordFixtureChanges(const std::vector<FixtureChangeRecord>& changes) {
  impl_->RequireWritable("RecordFixtureChanges");
  for (const auto& c : changes) {
    if (c.phase != "reset" && c.phase != "execute")
      BadInput("RecordFixtureChanges: phase must be reset or execute, got '" + c.phase + "'");
    if (c.what != "finger" && c.what != "pusher" && c.what != "object")
      BadInput("RecordFixtureChanges: what must be finger, pusher or object, got '" + c.what + "'");
    RequireFinite(c.seconds, "RecordFixtureChanges: seconds");
    if (c.seconds < 0) BadInput("RecordFixtureChanges: seconds must be >= 0");
  }
  Tx tx(impl_->db, true);
  const double now = impl_->Now();
  for (const auto& c : changes) {
    auto t = impl_->Prepare("SELECT 1 FROM trials WHERE id = ?");
    t->Bind(1, c.trial_id);
    if (!t->Step())
      throw StoreError(StoreError::Kind::kNotFound,
                       "RecordFixtureChanges: no trial " + std::to_string(c.trial_id));
    auto k = impl_->Prepare("SELECT 1 FROM cells WHERE id = ?");
    k->Bind(1, c.cell_id);
    if (!k->Step())
      throw StoreError(StoreError::Kind::kNotFound,
                       "RecordFixtureChanges: unknown cell '" + c.cell_id + "'");
    auto i = impl_->Prepare(
        "INSERT INTO fixture_changes(trial_id, attempt, cell_id, phase, what, from_key, to_key,"
        " seconds, at) VALUES(?,?,?,?,?,?,?,?,?)");
    i->Bind(1, c.trial_id)
        .Bind(2, c.attempt)
        .Bind(3, c.cell_id)
        .Bind(4, c.phase)
        .Bind(5, c.what)
        .Bind(6, c.from_key)
        .Bind(7, c.to_key)
        .Bind(8, c.seconds)
        .Bind(9, now);
    i->Run();
  }
  tx.Commit();
}

std::vector<FixtureChangeRecord> Store::ListFixtureChanges(std::int64_t campaign_id) const {
  Tx tx(impl_->db, false);
  auto s = impl_->Prepare(
      "SELECT f.trial_id, f.attempt, f.cell_id, f.phase, f.what, f.from_key, f.to_key, f.seconds,"
      " f.at FROM fixture_changes AS f JOIN trials AS t ON t.id = f.trial_id"
      " WHERE ?1 = 0 OR t.campaign_id = ?1 ORDER BY f.id");
  s->Bind(1, campaign_id);
  std::vector<FixtureChangeRecord> out;
  while (s->Step()) {
    FixtureChangeRecord r;
    r.trial_id = s->Int(0);
    r.attempt = static_cast<int>(s->Int(1));
    r.cell_id = s->Text(2);
    r.phase = s->Text(3);
    r.what = s->Text(4);
    r.from_key = s->Text(5);
    r.to_key = s->Text(6);
    r.seconds = s->Real(7);
    r.at = s->Real(8);
    out.push_back(std::move(r));
  }
  tx.Commit();
  return out;
}

std::optional<ClaimedTrial> Store::PeekNextTrial(const std::string& cell_id) const {
  Tx tx(impl_->db, false);
  auto t = FindNext(*impl_, cell_id, "PeekNextTrial");
  tx.Commit();
  return t;
}

std::optional<ClaimedTrial> Store::ClaimNextTrial(const std::string& cell_id) {
  impl_->RequireWritable("ClaimNextTrial");
  Tx tx(impl_->db, true);  // the write lock makes find + update one atomic step
  auto t = FindNext(*impl_, cell_id, "ClaimNextTrial");
  if (!t) return std::nullopt;
  ClaimFound(*impl_, *t, cell_id, "claimed", "ClaimNextTrial");
  tx.Commit();
  return t;
}

namespace {

void ClaimFound(const Store::Impl& impl, const ClaimedTrial& t, const std::string& cell_id,
                const std::string& reason, const char* function) {
  const double now = impl.Now();
  WriteTransition(impl, t.trial_id, t.attempt, TrialState::kPlanned, TrialState::kDispatched,
                  cell_id, reason, "dispatch.claimed", function);
  // The start state this trial begins from: the cell's last observed reset
  // result, if that reset was aimed at this trial (or its aim is not known).
  auto u = impl.Prepare(
      "UPDATE trials SET cell_id = ?1, dispatched_at = ?2,"
      " cell_defects_json = (SELECT defects_json FROM cells WHERE id = ?1),"
      " start_x = c.start_x, start_y = c.start_y, start_z = c.start_z, start_qw = c.start_qw,"
      " start_qx = c.start_qx, start_qy = c.start_qy, start_qz = c.start_qz"
      " FROM (SELECT 1) LEFT JOIN cells AS c ON c.id = ?1"
      "  AND (c.start_for_trial IS NULL OR c.start_for_trial = ?3) WHERE trials.id = ?3");
  u->Bind(1, cell_id).Bind(2, now).Bind(3, t.trial_id).Run();
  // The trial will move the object: the cell's start state is consumed.
  auto clear = impl.Prepare(
      "UPDATE cells SET start_x = NULL, start_y = NULL, start_z = NULL, start_qw = NULL,"
      " start_qx = NULL, start_qy = NULL, start_qz = NULL, start_observed_at = NULL,"
      " start_for_trial = NULL WHERE id = ?");
  clear->Bind(1, cell_id).Run();
  auto r = impl.Prepare(
      "SELECT start_x, start_y, start_z, start_qw, start_qx, start_qy, start_qz,"
      " nominal_x, nominal_y, nominal_z, nominal_qw, nominal_qx, nominal_qy, nominal_qz"
      " FROM trials WHERE id = ?");
  r->Bind(1, t.trial_id);
  r->Step();
  if (!r->IsNull(0)) {
    double v[14];
    for (int i = 0; i < 14; ++i) v[i] = r->Real(i);
    const double dp = std::sqrt((v[0] - v[7]) * (v[0] - v[7]) + (v[1] - v[8]) * (v[1] - v[8]) +
                                (v[2] - v[9]) * (v[2] - v[9]));
    const double da = QuatAngle(v + 3, v + 10);
    auto e = impl.Prepare(
        "UPDATE trials SET start_position_error = ?, start_angle_error = ? WHERE id = ?");
    e->Bind(1, dp).Bind(2, da).Bind(3, t.trial_id).Run();
  } else {
    // No observed start for this attempt: an earlier attempt's errors must not stay.
    auto e = impl.Prepare(
        "UPDATE trials SET start_position_error = NULL, start_angle_error = NULL WHERE id = ?");
    e->Bind(1, t.trial_id).Run();
  }
}

}  // namespace

TrialState Store::RetryTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                             int max_attempts, double backoff_s, std::string_view rule) {
  impl_->RequireWritable("RetryTrial");
  RequireFinite(backoff_s, "RetryTrial: backoff_s");
  if (backoff_s < 0) BadInput("RetryTrial: backoff_s must be >= 0");
  if (max_attempts < 1) BadInput("RetryTrial: max_attempts must be >= 1");
  Tx tx(impl_->db, true);
  const auto row = LoadTrialRow(*impl_, trial_id, "RetryTrial");
  CheckAttempt(row, trial_id, attempt, "RetryTrial");
  if (row.state != TrialState::kDispatched) {
    internal::CheckEdge(row.state, TrialState::kPlanned, trial_id, "RetryTrial");
  }
  auto r = impl_->Prepare("SELECT service_restarts FROM trials WHERE id = ?");
  r->Bind(1, trial_id);
  r->Step();
  const int restarts = static_cast<int>(r->Int(0));
  // The one retry rule (retry_rule.hpp); the audit row names the caller's
  // rule (why the attempt ended) and the retry rule's verdict.
  const RetryVerdict verdict = DecideRetry(attempt, restarts, max_attempts);
  const std::string rules =
      rule.empty() ? std::string(verdict.rule) : std::string(rule) + " " + verdict.rule;
  TrialState to;
  if (verdict.give_up) {
    to = TrialState::kFailed;
    WriteTransition(*impl_, trial_id, attempt, row.state, to, row.cell_id,
                    reason + " (attempt " + std::to_string(verdict.counted) + " of " +
                        std::to_string(max_attempts) +
                        (restarts != 0 ? " not counting " + std::to_string(restarts) +
                                             " cut short by service restarts or released"
                                       : std::string()) +
                        ": giving up)",
                    rules, "RetryTrial");
    auto o = impl_->Prepare("UPDATE trials SET outcome = 'failed' WHERE id = ?");
    o->Bind(1, trial_id).Run();
  } else {
    to = TrialState::kPlanned;
    WriteTransition(*impl_, trial_id, attempt, row.state, to, row.cell_id, reason, rules,
                    "RetryTrial");
    auto u = impl_->Prepare("UPDATE trials SET attempt = attempt + 1, not_before = ? WHERE id = ?");
    u->Bind(1, impl_->Now() + backoff_s).Bind(2, trial_id).Run();
  }
  tx.Commit();
  return to;
}

void Store::ReleaseTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                         std::string_view rule) {
  impl_->RequireWritable("ReleaseTrial");
  if (rule.empty()) BadInput("ReleaseTrial: rule is empty");
  Tx tx(impl_->db, true);
  const auto row = LoadTrialRow(*impl_, trial_id, "ReleaseTrial");
  CheckAttempt(row, trial_id, attempt, "ReleaseTrial");
  if (row.state != TrialState::kDispatched) {
    throw StoreError(StoreError::Kind::kIllegalTransition,
                     "ReleaseTrial: trial " + std::to_string(trial_id) + " is " +
                         ToString(row.state) + "; only a dispatched trial is released");
  }
  WriteTransition(*impl_, trial_id, attempt, row.state, TrialState::kPlanned, row.cell_id,
                  reason + " (not counted: re-run as attempt " + std::to_string(attempt + 1) + ")",
                  rule, "ReleaseTrial");
  auto u = impl_->Prepare(
      "UPDATE trials SET attempt = attempt + 1, not_before = 0,"
      " service_restarts = service_restarts + 1 WHERE id = ?");
  u->Bind(1, trial_id).Run();
  tx.Commit();
}

void Store::FailTrial(std::int64_t trial_id, int attempt, const std::string& reason,
                      TrialEnd outcome, std::string_view rule) {
  impl_->RequireWritable("FailTrial");
  if (outcome == TrialEnd::kNone) BadInput("FailTrial: outcome is not set");
  Tx tx(impl_->db, true);
  const auto row = LoadTrialRow(*impl_, trial_id, "FailTrial");
  CheckAttempt(row, trial_id, attempt, "FailTrial");
  WriteTransition(*impl_, trial_id, attempt, row.state, TrialState::kFailed, row.cell_id, reason,
                  rule.empty() ? std::string_view("fail.unnamed") : rule, "FailTrial");
  auto o = impl_->Prepare("UPDATE trials SET outcome = ? WHERE id = ?");
  o->Bind(1, ToString(outcome)).Bind(2, trial_id).Run();
  tx.Commit();
}

void internal::WriteBeginReset(const Store::Impl& impl, std::int64_t trial_id, int attempt,
                               std::string_view rule, const char* function) {
  const auto row = LoadTrialRow(impl, trial_id, function);
  CheckAttempt(row, trial_id, attempt, function);
  WriteTransition(impl, trial_id, attempt, row.state, TrialState::kResetting, row.cell_id,
                  row.state == TrialState::kResetFailed ? "reset retried" : "reset sent",
                  rule.empty() ? std::string_view("reset.unnamed") : rule, function);
}

void Store::BeginReset(std::int64_t trial_id, int attempt, std::string_view rule) {
  impl_->RequireWritable("BeginReset");
  Tx tx(impl_->db, true);
  internal::WriteBeginReset(*impl_, trial_id, attempt, rule, "BeginReset");
  tx.Commit();
}

void Store::CompleteReset(std::int64_t trial_id, int attempt, const ResetReport& report,
                          std::string_view rule) {
  impl_->RequireWritable("CompleteReset");
  for (int i = 0; i < 7; ++i) {
    RequireFinite(report.observed_pose[i],
                  "CompleteReset: observed_pose[" + std::to_string(i) + "]");
  }
  RequireFinite(report.position_error, "CompleteReset: position_error");
  RequireFinite(report.angle_error, "CompleteReset: angle_error");
  Tx tx(impl_->db, true);
  const auto row = LoadTrialRow(*impl_, trial_id, "CompleteReset");
  CheckAttempt(row, trial_id, attempt, "CompleteReset");
  const TrialState to = report.ok ? TrialState::kResetDone : TrialState::kResetFailed;
  WriteTransition(*impl_, trial_id, attempt, row.state, to, row.cell_id,
                  report.ok ? "reset verified" : report.reason,
                  !rule.empty() ? rule
                  : report.ok   ? std::string_view("reset.verified")
                                : std::string_view("reset.failed"),
                  "CompleteReset");
  auto u = impl_->Prepare(
      "UPDATE trials SET reset_ok = ?, reset_position_error = ?, reset_angle_error = ?,"
      " reset_attempts = ?, reset_reason = ? WHERE id = ?");
  u->Bind(1, report.ok ? 1 : 0)
      .Bind(2, report.position_error)
      .Bind(3, report.angle_error)
      .Bind(4, report.reset_attempts)
      .Bind(5, report.reason)
      .Bind(6, trial_id)
      .Run();
  if (!row.cell_id.empty()) {
    // The pose the cell observed is where the next trial on this cell starts,
    // ok or not; without an observation that start is unknown (NULL).
    auto c = impl_->Prepare(
        "UPDATE cells SET start_x = ?, start_y = ?, start_z = ?, start_qw = ?, start_qx = ?,"
        " start_qy = ?, start_qz = ?, start_observed_at = ?, start_for_trial = ?, updated_at = ?"
        " WHERE id = ?");
    detail::Binder b(*c);
    const double now = impl_->Now();
    for (double v : report.observed_pose) {
      if (report.pose_observed)
        b << v;
      else
        b << std::nullopt;
    }
    if (report.pose_observed)
      b << now;
    else
      b << std::nullopt;
    b << report.aimed_at_trial << now << row.cell_id;
    c->Run();
  }
  tx.Commit();
}

namespace {

// @throws kBadInput naming the field (prefix: "Function: ...").
void CheckPrediction(const Prediction& p, const std::string& prefix) {
  if (p.model_key.empty()) BadInput(prefix + "model_key is empty");
  ParseObject(p.model_json, prefix + "model_json");
  ParseObject(p.detail_json, prefix + "detail_json");
  for (auto [v, name] :
       {std::pair{p.final_position_error, "final_position_error"},
        std::pair{p.final_angle_error, "final_angle_error"},
        std::pair{p.force_error, "force_error"}, std::pair{p.mode_agreement, "mode_agreement"}}) {
    if (v) RequireFinite(*v, prefix + name);
  }
  RequireFinite(p.wall_s, prefix + "wall_s");
  if (p.wall_s < 0) BadInput(prefix + "wall_s must be >= 0");
  if (p.mode_agreement && (*p.mode_agreement < 0 || *p.mode_agreement > 1)) {
    BadInput(prefix + "mode_agreement must be in [0, 1]");
  }
}

}  // namespace

namespace {

// RecordPrediction's writes; the caller holds the write transaction.
void WritePrediction(const Store::Impl& impl, std::int64_t trial_id, int attempt,
                     const Prediction& p, const char* function) {
  const auto row = LoadTrialRow(impl, trial_id, function);
  CheckAttempt(row, trial_id, attempt, function);
  if (row.state != TrialState::kPredicted) {
    WriteTransition(impl, trial_id, attempt, row.state, TrialState::kPredicted, row.cell_id,
                    "predicted (" + p.model_key + ")", "predict.recorded", function);
  }
  auto s = impl.Prepare(
      "INSERT INTO predictions(trial_id, attempt, model_key, model_json, status, "
      "final_position_error,"
      " final_angle_error, force_error, mode_agreement, wall_s, detail_json, created_at)"
      " VALUES(?,?,?,?,?,?,?,?,?,?,?,?)"
      " ON CONFLICT(trial_id, attempt, model_key) DO UPDATE SET model_json = excluded.model_json,"
      " status = excluded.status, final_position_error = excluded.final_position_error,"
      " final_angle_error = excluded.final_angle_error, force_error = excluded.force_error,"
      " mode_agreement = excluded.mode_agreement, wall_s = excluded.wall_s,"
      " detail_json = excluded.detail_json, created_at = excluded.created_at");
  s->Bind(1, trial_id)
      .Bind(2, attempt)
      .Bind(3, p.model_key)
      .Bind(4, p.model_json)
      .Bind(5, ToString(p.status))
      .Bind(6, p.final_position_error)
      .Bind(7, p.final_angle_error)
      .Bind(8, p.force_error)
      .Bind(9, p.mode_agreement)
      .Bind(10, p.wall_s)
      .Bind(11, p.detail_json)
      .Bind(12, impl.Now());
  s->Run();
}

// FinishTrial's write (predicted -> done); the caller holds the write transaction.
void WriteFinish(const Store::Impl& impl, std::int64_t trial_id, int attempt,
                 const char* function) {
  const auto row = LoadTrialRow(impl, trial_id, function);
  CheckAttempt(row, trial_id, attempt, function);
  WriteTransition(impl, trial_id, attempt, row.state, TrialState::kDone, row.cell_id, "done",
                  "finish.predicted", function);
}

}  // namespace

void Store::RecordPrediction(std::int64_t trial_id, int attempt, const Prediction& p) {
  impl_->RequireWritable("RecordPrediction");
  CheckPrediction(p, "RecordPrediction: ");
  Tx tx(impl_->db, true);
  WritePrediction(*impl_, trial_id, attempt, p, "RecordPrediction");
  tx.Commit();
}

void Store::RecordPredictionAndFinish(std::int64_t trial_id, int attempt, const Prediction& p) {
  impl_->RequireWritable("RecordPredictionAndFinish");
  CheckPrediction(p, "RecordPredictionAndFinish: ");
  Tx tx(impl_->db, true);
  WritePrediction(*impl_, trial_id, attempt, p, "RecordPredictionAndFinish");
  WriteFinish(*impl_, trial_id, attempt, "RecordPredictionAndFinish");
  tx.Commit();
}

std::int64_t Store::RecordEvaluation(std::int64_t campaign_id, const std::string& settings_json,
                                     const std::string& report_json,
                                     const std::vector<EvaluationResult>& results) {
  impl_->RequireWritable("RecordEvaluation");
  ParseObject(settings_json, "RecordEvaluation: settings_json");
  ParseObject(report_json, "RecordEvaluation: report_json");
  for (std::size_t i = 0; i < results.size(); ++i) {
    CheckPrediction(results[i].prediction, "RecordEvaluation: results[" + std::to_string(i) + "].");
  }
  Tx tx(impl_->db, true);
  {
    auto c = impl_->Prepare("SELECT 1 FROM campaigns WHERE id = ?");
    c->Bind(1, campaign_id);
    if (!c->Step()) {
      throw StoreError(StoreError::Kind::kNotFound,
                       "RecordEvaluation: no campaign " + std::to_string(campaign_id));
    }
  }
  const double now = impl_->Now();
  auto e = impl_->Prepare(
      "INSERT INTO evaluations(campaign_id, created_at, settings_json, report_json) "
      "VALUES(?,?,?,?)");
  e->Bind(1, campaign_id).Bind(2, now).Bind(3, settings_json).Bind(4, report_json).Run();
  const std::int64_t id = sqlite3_last_insert_rowid(impl_->db);
  std::map<std::int64_t, bool> checked;
  std::set<std::pair<std::int64_t, std::string>> seen;
  auto ins = impl_->Prepare(
      "INSERT INTO evaluation_results(evaluation_id, trial_id, attempt, model_key, model_json, "
      "status,"
      " final_position_error, final_angle_error, force_error, mode_agreement, wall_s, detail_json)"
      " VALUES(?,?,?,?,?,?,?,?,?,?,?,?)");
  for (const auto& r : results) {
    const Prediction& p = r.prediction;
    if (!checked.count(r.trial_id)) {
      const auto row = LoadTrialRow(*impl_, r.trial_id, "RecordEvaluation");
      if (row.campaign_id != campaign_id) {
        BadInput("RecordEvaluation: trial " + std::to_string(r.trial_id) + " belongs to campaign " +
                 std::to_string(row.campaign_id) + ", not " + std::to_string(campaign_id));
      }
      CheckAttempt(row, r.trial_id, r.attempt, "RecordEvaluation");
      if (row.state != TrialState::kDone) {
        throw StoreError(StoreError::Kind::kIllegalTransition,
                         "RecordEvaluation: trial " + std::to_string(r.trial_id) + " is " +
                             ToString(row.state) + "; only done trials are evaluated");
      }
      checked[r.trial_id] = true;
    }
    if (!seen.emplace(r.trial_id, p.model_key).second) {
      BadInput("RecordEvaluation: trial " + std::to_string(r.trial_id) + " has two results for " +
               p.model_key);
    }
    ins->Reset();
    ins->Bind(1, id)
        .Bind(2, r.trial_id)
        .Bind(3, r.attempt)
        .Bind(4, p.model_key)
        .Bind(5, p.model_json)
        .Bind(6, ToString(p.status))
        .Bind(7, p.final_position_error)
        .Bind(8, p.final_angle_error)
        .Bind(9, p.force_error)
        .Bind(10, p.mode_agreement)
        .Bind(11, p.wall_s)
        .Bind(12, p.detail_json);
    ins->Run();
  }
  tx.Commit();
  return id;
}

namespace {

Evaluation ReadEvaluationRow(const detail::Stmt& s) {
  Evaluation e;
  e.id = s.Int(0);
  e.campaign_id = s.Int(1);
  e.created_at = s.Real(2);
  e.settings_json = s.Text(3);
  e.report_json = s.Text(4);
  return e;
}

}  // namespace

std::vector<Evaluation> Store::ListEvaluations(std::int64_t campaign_id) const {
  auto s = impl_->Prepare(
      "SELECT id, campaign_id, created_at, settings_json, report_json FROM evaluations"
      " WHERE campaign_id = ? ORDER BY id");
  s->Bind(1, campaign_id);
  std::vector<Evaluation> out;
  while (s->Step()) out.push_back(ReadEvaluationRow(*s));
  return out;
}

Evaluation Store::GetEvaluation(std::int64_t evaluation_id) const {
  auto s = impl_->Prepare(
      "SELECT id, campaign_id, created_at, settings_json, report_json FROM evaluations WHERE id = "
      "?");
  s->Bind(1, evaluation_id);
  if (!s->Step()) {
    throw StoreError(StoreError::Kind::kNotFound,
                     "GetEvaluation: no evaluation " + std::to_string(evaluation_id));
  }
  return ReadEvaluationRow(*s);
}

std::vector<EvaluationResult> Store::ListEvaluationResults(std::int64_t evaluation_id) const {
  auto s = impl_->Prepare(
      "SELECT trial_id, attempt, model_key, model_json, status, final_position_error, "
      "final_angle_error,"
      " force_error, mode_agreement, wall_s, detail_json FROM evaluation_results"
      " WHERE evaluation_id = ? ORDER BY trial_id, model_key");
  s->Bind(1, evaluation_id);
  std::vector<EvaluationResult> out;
  while (s->Step()) {
    EvaluationResult r;
    r.trial_id = s->Int(0);
    r.attempt = static_cast<int>(s->Int(1));
    Prediction& p = r.prediction;
    p.model_key = s->Text(2);
    p.model_json = s->Text(3);
    p.status = StoredPredictionStatus(s->Text(4));
    p.final_position_error = s->OptReal(5);
    p.final_angle_error = s->OptReal(6);
    p.force_error = s->OptReal(7);
    p.mode_agreement = s->OptReal(8);
    p.wall_s = s->Real(9);
    p.detail_json = s->Text(10);
    out.push_back(std::move(r));
  }
  return out;
}

void internal::WriteExecution(const Store::Impl& impl, std::int64_t trial_id, int attempt,
                              const ExecutionRecord& record, const char* function) {
  const auto row = LoadTrialRow(impl, trial_id, function);
  CheckAttempt(row, trial_id, attempt, function);
  auto u =
      impl.Prepare("UPDATE trials SET backend = ?, truth = ?, defects_applied = ? WHERE id = ?");
  u->Bind(1, record.backend)
      .Bind(2, record.truth)
      .Bind(3, record.defects_applied_json)
      .Bind(4, trial_id)
      .Run();
}

void Store::RecordExecution(std::int64_t trial_id, int attempt, const std::string& backend,
                            const std::string& truth, const std::string& defects_applied_json) {
  impl_->RequireWritable("RecordExecution");
  Tx tx(impl_->db, true);
  internal::WriteExecution(*impl_, trial_id, attempt, {backend, truth, defects_applied_json},
                           "RecordExecution");
  tx.Commit();
}

std::vector<Store::TruthCount> Store::CampaignTruths(std::int64_t campaign_id) const {
  Tx tx(impl_->db, false);
  auto s = impl_->Prepare(
      "SELECT IFNULL(truth, ''), IFNULL(backend, ''), COUNT(*) FROM trials"
      " WHERE campaign_id = ? AND gt_stream_id IS NOT NULL GROUP BY 1, 2 ORDER BY 3 DESC");
  s->Bind(1, campaign_id);
  std::vector<TruthCount> out;
  while (s->Step()) out.push_back({s->Text(0), s->Text(1), s->Int(2)});
  tx.Commit();
  return out;
}

void Store::FinishTrial(std::int64_t trial_id, int attempt) {
  impl_->RequireWritable("FinishTrial");
  Tx tx(impl_->db, true);
  WriteFinish(*impl_, trial_id, attempt, "FinishTrial");
  tx.Commit();
}

RecoveryReport Store::RecoverAfterRestart(const std::string& reason) {
  impl_->RequireWritable("RecoverAfterRestart");
  Tx tx(impl_->db, true);
  RecoveryReport report;
  std::vector<std::pair<std::int64_t, int>> dispatched, resetting;
  {
    auto s = impl_->Prepare(
        "SELECT id, attempt, state FROM trials WHERE state IN ('dispatched','resetting')");
    while (s->Step()) {
      (s->Text(2) == "dispatched" ? dispatched : resetting)
          .emplace_back(s->Int(0), static_cast<int>(s->Int(1)));
    }
  }
  for (auto [id, attempt] : dispatched) {
    const auto row = LoadTrialRow(*impl_, id, "RecoverAfterRestart");
    WriteTransition(
        *impl_, id, attempt, TrialState::kDispatched, TrialState::kPlanned, row.cell_id,
        reason + ": execute not confirmed, re-run as attempt " + std::to_string(attempt + 1),
        "recover.execute_unconfirmed", "RecoverAfterRestart");
    auto u = impl_->Prepare(
        "UPDATE trials SET attempt = attempt + 1, not_before = 0,"
        " service_restarts = service_restarts + 1 WHERE id = ?");
    u->Bind(1, id).Run();
    report.requeued.push_back(id);
  }
  for (auto [id, attempt] : resetting) {
    const auto row = LoadTrialRow(*impl_, id, "RecoverAfterRestart");
    WriteTransition(*impl_, id, attempt, TrialState::kResetting, TrialState::kResetFailed,
                    row.cell_id, reason + ": reset not confirmed", "recover.reset_unconfirmed",
                    "RecoverAfterRestart");
    auto u = impl_->Prepare("UPDATE trials SET reset_ok = 0, reset_reason = ? WHERE id = ?");
    u->Bind(1, reason + ": reset not confirmed").Bind(2, id).Run();
    // Where the interrupted reset left the object is unknown.
    auto c = impl_->Prepare(
        "UPDATE cells SET start_x = NULL, start_y = NULL, start_z = NULL, start_qw = NULL,"
        " start_qx = NULL, start_qy = NULL, start_qz = NULL, start_observed_at = NULL,"
        " start_for_trial = NULL WHERE id = ?");
    c->Bind(1, row.cell_id).Run();
    report.reset_failed.push_back(id);
  }
  // Streams never published (their ingest died with the service) hold partial data only.
  auto d = impl_->Prepare(
      "DELETE FROM gt_streams WHERE complete = 0"
      " AND id NOT IN (SELECT gt_stream_id FROM trials WHERE gt_stream_id IS NOT NULL)");
  d->Run();
  report.orphan_streams_deleted = sqlite3_changes(impl_->db);
  tx.Commit();
  return report;
}

// ---------------------------------------------------------------- reads

namespace {

constexpr const char* kTrialCols =
    "SELECT id, campaign_id, idx, condition, replicate, seed, state, attempt, IFNULL(cell_id,''),"
    " scene_json, params_json, defects_json, IFNULL(outcome,''), gt_stream_id, not_before,"
    " created_at, updated_at, dispatched_at, executed_at, finished_at FROM trials";

Trial ReadTrial(const detail::Stmt& s) {
  Trial t;
  t.id = s.Int(0);
  t.campaign_id = s.Int(1);
  t.index = static_cast<int>(s.Int(2));
  t.condition = static_cast<int>(s.Int(3));
  t.replicate = static_cast<int>(s.Int(4));
  t.seed = SeedFromDb(s.Int(5));
  t.state = MustParseTrialState(s.Text(6));
  t.attempt = static_cast<int>(s.Int(7));
  t.cell_id = s.Text(8);
  t.scene_json = s.Text(9);
  t.params_json = s.Text(10);
  t.defects_json = s.Text(11);
  const std::string outcome = s.Text(12);
  const auto parsed = ParseTrialEnd(outcome);
  if (!parsed)
    throw StoreError(StoreError::Kind::kCorrupt,
                     "trial " + std::to_string(t.id) + ": outcome '" + outcome + "' is unknown");
  t.outcome = *parsed;
  if (!s.IsNull(13)) t.gt_stream_id = s.Int(13);
  t.not_before = s.Real(14);
  t.created_at = s.Real(15);
  t.updated_at = s.Real(16);
  t.dispatched_at = s.OptReal(17);
  t.executed_at = s.OptReal(18);
  t.finished_at = s.OptReal(19);
  return t;
}

}  // namespace

Trial Store::GetTrial(std::int64_t trial_id) const {
  auto s = impl_->Prepare(std::string(kTrialCols) + " WHERE id = ?");
  s->Bind(1, trial_id);
  if (!s->Step()) {
    throw StoreError(StoreError::Kind::kNotFound, "GetTrial: no trial " + std::to_string(trial_id));
  }
  return ReadTrial(*s);
}

std::vector<Trial> Store::ListTrials(std::int64_t campaign_id) const {
  auto s = impl_->Prepare(std::string(kTrialCols) + " WHERE campaign_id = ? ORDER BY idx");
  s->Bind(1, campaign_id);
  std::vector<Trial> out;
  while (s->Step()) out.push_back(ReadTrial(*s));
  return out;
}

std::vector<Trial> Store::ListTrialsByState(const std::vector<TrialState>& states) const {
  std::string in;
  for (auto st : states) in += std::string(in.empty() ? "'" : ",'") + ToString(st) + "'";
  std::vector<Trial> out;
  if (in.empty()) return out;
  detail::Stmt s(impl_->db, std::string(kTrialCols) + " WHERE state IN (" + in + ") ORDER BY id");
  while (s.Step()) out.push_back(ReadTrial(s));
  return out;
}

std::vector<Transition> Store::ListTransitions(std::int64_t trial_id) const {
  auto s = impl_->Prepare(
      "SELECT trial_id, attempt, from_state, to_state, at, cell_id, reason, rule"
      " FROM trial_transitions WHERE trial_id = ? ORDER BY id");
  s->Bind(1, trial_id);
  std::vector<Transition> out;
  while (s->Step()) {
    out.push_back({s->Int(0), static_cast<int>(s->Int(1)), s->Text(2), s->Text(3), s->Real(4),
                   s->Text(5), s->Text(6), s->Text(7)});
  }
  return out;
}

std::vector<Prediction> Store::ListPredictions(std::int64_t trial_id) const {
  auto s = impl_->Prepare(
      "SELECT model_key, model_json, status, final_position_error, final_angle_error, force_error,"
      " mode_agreement, wall_s, detail_json FROM predictions WHERE trial_id = ? ORDER BY id");
  s->Bind(1, trial_id);
  std::vector<Prediction> out;
  while (s->Step()) {
    Prediction p;
    p.model_key = s->Text(0);
    p.model_json = s->Text(1);
    p.status = StoredPredictionStatus(s->Text(2));
    p.final_position_error = s->OptReal(3);
    p.final_angle_error = s->OptReal(4);
    p.force_error = s->OptReal(5);
    p.mode_agreement = s->OptReal(6);
    p.wall_s = s->Real(7);
    p.detail_json = s->Text(8);
    out.push_back(std::move(p));
  }
  return out;
}

std::vector<std::string> Store::CheckInvariants() const {
  std::vector<std::string> out;
  const std::pair<const char*, const char*> checks[] = {
      {"a trial at or past executed has a complete stream of its attempt",
       "SELECT t.id FROM trials t LEFT JOIN gt_streams g ON g.id = t.gt_stream_id"
       " WHERE t.state IN ('executed','resetting','reset_done','reset_failed','predicted','done')"
       " AND (g.id IS NULL OR g.complete = 0 OR g.attempt != t.attempt OR g.trial_id != t.id)"},
      {"a done trial has a prediction of its attempt",
       "SELECT t.id FROM trials t WHERE t.state = 'done' AND NOT EXISTS"
       " (SELECT 1 FROM predictions p WHERE p.trial_id = t.id AND p.attempt = t.attempt)"},
      {"the last audit row of a trial matches its state and attempt",
       "SELECT t.id FROM trials t JOIN trial_transitions a ON a.id ="
       " (SELECT MAX(id) FROM trial_transitions WHERE trial_id = t.id)"
       " WHERE a.to_state != t.state OR a.attempt > t.attempt"},
      {"every trial has an audit row",
       "SELECT t.id FROM trials t WHERE NOT EXISTS"
       " (SELECT 1 FROM trial_transitions a WHERE a.trial_id = t.id)"},
      {"a published stream's sample count equals its chunks'",
       "SELECT g.id FROM gt_streams g WHERE g.complete = 1 AND g.samples !="
       " (SELECT IFNULL(SUM(samples), 0) FROM gt_chunks c WHERE c.stream_id = g.id)"},
      {"a dispatched trial names its cell",
       "SELECT id FROM trials WHERE state = 'dispatched' AND cell_id IS NULL"},
  };
  Tx tx(impl_->db, false);
  for (const auto& [what, sql] : checks) {
    detail::Stmt s(impl_->db, sql);
    while (s.Step())
      out.push_back(std::string(what) + ": violated by id " + std::to_string(s.Int(0)));
  }
  tx.Commit();
  return out;
}

// ---------------------------------------------------------------- cells

void Store::UpsertCell(const std::string& cell_id, const std::vector<std::string>& contact_types,
                       const std::string& capabilities_json, const std::string& defects_json) {
  impl_->RequireWritable("UpsertCell");
  if (cell_id.empty()) BadInput("UpsertCell: cell_id is empty");
  const int mask = ContactTypeMask(contact_types);
  ParseObject(capabilities_json, "UpsertCell: capabilities_json");
  ParseObject(defects_json, "UpsertCell: defects_json");
  Tx tx(impl_->db, true);
  const double now = impl_->Now();
  auto s = impl_->Prepare(
      "INSERT INTO cells(id, state, contact_mask, capabilities_json, defects_json, last_seen,"
      " created_at, updated_at) VALUES(?1,'healthy',?2,?3,?4,?5,?5,?5)"
      " ON CONFLICT(id) DO UPDATE SET contact_mask = ?2, capabilities_json = ?3, defects_json = ?4,"
      " last_seen = ?5, updated_at = ?5,"
      " state = CASE WHEN state = 'gone' THEN 'healthy' ELSE state END,"
      " quarantine_reason = CASE WHEN state = 'gone' THEN '' ELSE quarantine_reason END");
  s->Bind(1, cell_id)
      .Bind(2, mask)
      .Bind(3, capabilities_json)
      .Bind(4, defects_json)
      .Bind(5, now)
      .Run();
  tx.Commit();
}

namespace {
void RequireCellChanged(sqlite3* db, const char* function, const std::string& cell_id) {
  if (sqlite3_changes(db) == 0) {
    throw StoreError(StoreError::Kind::kNotFound,
                     std::string(function) + ": unknown cell '" + cell_id + "'");
  }
}
}  // namespace

void Store::TouchCell(const std::string& cell_id) {
  impl_->RequireWritable("TouchCell");
  auto s = impl_->Prepare("UPDATE cells SET last_seen = ? WHERE id = ?");
  s->Bind(1, impl_->Now()).Bind(2, cell_id).Run();
  RequireCellChanged(impl_->db, "TouchCell", cell_id);
}

int Store::RecordCellResult(const std::string& cell_id, bool ok) {
  impl_->RequireWritable("RecordCellResult");
  Tx tx(impl_->db, true);
  auto s = impl_->Prepare(
      ok ? "UPDATE cells SET consecutive_failures = 0, last_seen = ?, updated_at = ? WHERE id = ?"
         : "UPDATE cells SET consecutive_failures = consecutive_failures + 1,"
           " total_failures = total_failures + 1, last_seen = ?, updated_at = ? WHERE id = ?");
  const double now = impl_->Now();
  s->Bind(1, now).Bind(2, now).Bind(3, cell_id).Run();
  RequireCellChanged(impl_->db, "RecordCellResult", cell_id);
  auto q = impl_->Prepare("SELECT consecutive_failures FROM cells WHERE id = ?");
  q->Bind(1, cell_id);
  q->Step();
  const int n = static_cast<int>(q->Int(0));
  tx.Commit();
  return n;
}

namespace {
void AddCellEvent(const Store::Impl& impl, const std::string& cell_id, const char* event,
                  const std::string& reason, const std::string& by_whom) {
  auto e = impl.Prepare(
      "INSERT INTO cell_events(cell_id, at, event, reason, by_whom) VALUES(?,?,?,?,?)");
  e->Bind(1, cell_id).Bind(2, impl.Now()).Bind(3, event).Bind(4, reason).Bind(5, by_whom).Run();
}
}  // namespace

void Store::QuarantineCell(const std::string& cell_id, const std::string& reason) {
  impl_->RequireWritable("QuarantineCell");
  Tx tx(impl_->db, true);
  auto s = impl_->Prepare(
      "UPDATE cells SET state = 'quarantined', quarantine_reason = ?, updated_at = ? WHERE id = ?");
  s->Bind(1, reason).Bind(2, impl_->Now()).Bind(3, cell_id).Run();
  RequireCellChanged(impl_->db, "QuarantineCell", cell_id);
  AddCellEvent(*impl_, cell_id, "quarantined", reason, "service");
  tx.Commit();
}

void Store::ReleaseCell(const std::string& cell_id, const std::string& reason,
                        const std::string& by_whom) {
  impl_->RequireWritable("ReleaseCell");
  Tx tx(impl_->db, true);
  auto s = impl_->Prepare(
      "UPDATE cells SET state = 'healthy', quarantine_reason = '', consecutive_failures = 0,"
      " updated_at = ? WHERE id = ?");
  s->Bind(1, impl_->Now()).Bind(2, cell_id).Run();
  RequireCellChanged(impl_->db, "ReleaseCell", cell_id);
  AddCellEvent(*impl_, cell_id, "released", reason, by_whom);
  tx.Commit();
}

std::vector<CellEvent> Store::ListCellEvents(const std::string& cell_id) const {
  auto s = impl_->Prepare(
      "SELECT cell_id, at, event, reason, by_whom FROM cell_events WHERE cell_id = ? ORDER BY id");
  s->Bind(1, cell_id);
  std::vector<CellEvent> out;
  while (s->Step()) out.push_back({s->Text(0), s->Real(1), s->Text(2), s->Text(3), s->Text(4)});
  return out;
}

void Store::SetCellServing(const std::string& cell_id, double lease_s, const std::string& serving) {
  impl_->RequireWritable("SetCellServing");
  if (!std::isfinite(lease_s) || lease_s < 0) BadInput("SetCellServing: lease_s must be >= 0");
  auto s = impl_->Prepare("UPDATE cells SET lease_s = ?, serving = ? WHERE id = ?");
  s->Bind(1, lease_s).Bind(2, serving).Bind(3, cell_id).Run();
  RequireCellChanged(impl_->db, "SetCellServing", cell_id);
}

void Store::MarkCellGone(const std::string& cell_id, const std::string& reason) {
  impl_->RequireWritable("MarkCellGone");
  auto s = impl_->Prepare(
      "UPDATE cells SET state = CASE WHEN state = 'quarantined' THEN state ELSE 'gone' END,"
      " quarantine_reason = CASE WHEN state = 'quarantined' THEN quarantine_reason ELSE ? END,"
      " updated_at = ? WHERE id = ?");
  s->Bind(1, reason).Bind(2, impl_->Now()).Bind(3, cell_id).Run();
  RequireCellChanged(impl_->db, "MarkCellGone", cell_id);
}

namespace {
constexpr const char* kCellCols =
    "SELECT id, state, last_seen, consecutive_failures, total_failures, capabilities_json,"
    " quarantine_reason, lease_s, serving FROM cells";
CellInfo ReadCell(const detail::Stmt& s) {
  CellInfo c;
  c.id = s.Text(0);
  c.state = ParseCellState(s.Text(1));
  c.last_seen = s.Real(2);
  c.consecutive_failures = static_cast<int>(s.Int(3));
  c.total_failures = static_cast<int>(s.Int(4));
  c.capabilities_json = s.Text(5);
  c.quarantine_reason = s.Text(6);
  c.lease_s = s.Real(7);
  c.serving = s.Text(8);
  return c;
}
}  // namespace

CellInfo Store::GetCell(const std::string& cell_id) const {
  auto s = impl_->Prepare(std::string(kCellCols) + " WHERE id = ?");
  s->Bind(1, cell_id);
  if (!s->Step())
    throw StoreError(StoreError::Kind::kNotFound, "GetCell: unknown cell '" + cell_id + "'");
  return ReadCell(*s);
}

std::vector<CellInfo> Store::ListCells() const {
  auto s = impl_->Prepare(std::string(kCellCols) + " ORDER BY id");
  std::vector<CellInfo> out;
  while (s->Step()) out.push_back(ReadCell(*s));
  return out;
}

// ---------------------------------------------------------------- status

std::vector<StartStateDrift> Store::Drift(std::optional<std::int64_t> campaign_id) const {
  auto s = impl_->Prepare(
      "SELECT campaign_id, cell_id, trials, mean_dx, mean_dy, mean_dz, mean_position_error,"
      " max_position_error, mean_angle_error, max_angle_error FROM start_state_drift"
      " WHERE ?1 IS NULL OR campaign_id = ?1 ORDER BY campaign_id, cell_id");
  if (campaign_id)
    s->Bind(1, *campaign_id);
  else
    s->BindNull(1);
  std::vector<StartStateDrift> out;
  while (s->Step()) {
    StartStateDrift d;
    d.campaign_id = s->Int(0);
    d.cell_id = s->Text(1);
    d.trials = s->Int(2);
    d.mean_dx = s->Real(3);
    d.mean_dy = s->Real(4);
    d.mean_dz = s->Real(5);
    d.mean_position_error = s->Real(6);
    d.max_position_error = s->Real(7);
    d.mean_angle_error = s->Real(8);
    d.max_angle_error = s->Real(9);
    out.push_back(d);
  }
  return out;
}

StatusSummary Store::Status() const {
  constexpr double kRateWindowS = 900;  // recent rate: the last 15 minutes
  Tx tx(impl_->db, false);              // one snapshot for the whole summary
  StatusSummary out;
  const double now = impl_->Now();
  auto s = impl_->Prepare(
      "SELECT c.id, c.name, c.state, c.priority, COUNT(t.id),"
      " SUM(t.state = 'planned'),"
      " SUM(t.state IN "
      "('dispatched','executed','resetting','reset_done','reset_failed','predicted')),"
      " SUM(t.state = 'done'), SUM(t.state = 'failed'), SUM(t.state = 'cancelled'),"
      " SUM(t.state IN ('done','failed') AND t.finished_at >= ?1),"
      " MIN(t.dispatched_at), MAX(t.finished_at), SUM(t.state IN ('done','failed')),"
      " SUM(t.state IN ('executed','resetting','reset_done','reset_failed'))"
      " FROM campaigns c LEFT JOIN trials t ON t.campaign_id = c.id GROUP BY c.id ORDER BY c.id");
  s->Bind(1, now - kRateWindowS);
  while (s->Step()) {
    CampaignStatus c;
    c.id = s->Int(0);
    c.name = s->Text(1);
    c.state = ParseCampaignState(s->Text(2));
    c.priority = static_cast<int>(s->Int(3));
    c.planned = s->Int(4);
    c.pending = s->Int(5);
    c.running = s->Int(6);
    c.done = s->Int(7);
    c.failed = s->Int(8);
    c.cancelled = s->Int(9);
    const std::int64_t recent = s->Int(10);
    c.awaiting_prediction = s->Int(14);
    const bool finished = c.pending == 0 && c.running == 0 && c.state != CampaignState::kActive;
    if (finished) {
      // Frozen: the rate it ran at, from its first dispatch to its last
      // finish, not one that decays as the clock moves on (issue 26).
      const std::int64_t finished_trials = s->Int(13);
      if (!s->IsNull(11) && !s->IsNull(12) && finished_trials > 0) {
        const double span = s->Real(12) - s->Real(11);
        if (span > 0) c.rate_per_hour = finished_trials * 3600.0 / span;
      }
    } else if (!s->IsNull(11) && recent > 0) {
      const double span = std::min(kRateWindowS, now - s->Real(11));
      if (span > 0) c.rate_per_hour = recent * 3600.0 / span;
    }
    if (c.rate_per_hour > 0 && c.state == CampaignState::kActive) {
      c.eta_s = (c.pending + c.running) * 3600.0 / c.rate_per_hour;
    }
    out.campaigns.push_back(c);
  }
  out.cells = ListCells();
  // A cell whose last sign is older than its lease is gone, whatever the last
  // service wrote (it may have died without saying so).
  for (auto& c : out.cells) {
    if (c.state == CellState::kHealthy && c.lease_s > 0 && now - c.last_seen > c.lease_s) {
      c.state = CellState::kGone;
      if (c.quarantine_reason.empty()) c.quarantine_reason = "no sign within its lease";
    }
  }
  out.drift = Drift();
  tx.Commit();
  return out;
}

}  // namespace arena::db
