// The query views over trials (trial_results, contact_results) carry one
// column per varied parameter of any campaign in the store, and the
// per-contact / object outcomes of every published stream (schema version 6;
// db/README.md, "Parameters as columns").
//
// Why views over params_json rather than real columns: the set of parameter
// names grows with the campaigns a lab submits (another sampler, another
// variation), and ALTER TABLE on a store that a running service writes would
// be a schema change per campaign. The views are rebuilt (in the writing
// transaction) only when a campaign brings a name not seen before; the values
// stay where the sampler put them (trials.params_json), so nothing is stored
// twice and nothing can disagree.
#include <cctype>
#include <set>
#include <string>
#include <vector>

#include "arena/db/outcomes.hpp"
#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db::internal {
namespace {

// The columns trial_results had before version 6, in order (kept as they were).
constexpr const char* kTrialColumns =
    "t.id AS trial_id, t.campaign_id, t.idx, t.condition, t.replicate, t.state, t.attempt,"
    " t.cell_id, t.outcome, t.object_shape, t.object_mass, t.grip_force, t.finger_type,"
    " t.finger_count, t.finger_mu, t.pusher_type, t.pusher_mu, t.pusher_speed,"
    " t.pusher_angular_speed, t.duration, t.start_position_error, t.start_angle_error,"
    " s.samples, s.observed_samples, s.duration_s, s.displacement_m, s.rotation_rad,"
    " s.max_contact_force_n, s.max_pusher_force_n, s.stick_fraction, s.slide_fraction,"
    " s.separate_fraction, s.observed_position_rmse_m,"
    // version 6: the object's outcome
    " s.net_dx, s.net_dy, s.net_dz, s.net_rx, s.net_ry, s.net_rz, s.grasp_kept";

constexpr const char* kContactColumns =
    "c.trial_id, t.campaign_id, t.idx, t.condition, t.replicate, t.state, t.attempt, t.cell_id,"
    " t.outcome, c.contact, c.name AS contact_name, c.role, c.stick_fraction, c.slide_fraction,"
    " c.separate_fraction, c.slip_distance_m, c.max_normal_force_n, t.object_shape,"
    " t.object_mass, t.grip_force, t.finger_type, t.finger_count, t.finger_mu, t.pusher_type,"
    " t.pusher_mu, t.pusher_speed, t.duration, s.grasp_kept, s.displacement_m, s.rotation_rad";

// Column names a parameter may not take (already a column of either view).
const std::set<std::string>& Taken() {
  static const std::set<std::string> kTaken = [] {
    std::set<std::string> out;
    for (const char* list : {kTrialColumns, kContactColumns}) {
      std::string text(list);
      std::size_t pos = 0;
      while (pos < text.size()) {
        std::size_t end = text.find(',', pos);
        if (end == std::string::npos) end = text.size();
        std::string item = text.substr(pos, end - pos);
        const auto as = item.find(" AS ");
        std::string name = as != std::string::npos ? item.substr(as + 4) : item;
        const auto dot = name.find('.');
        if (dot != std::string::npos) name = name.substr(dot + 1);
        std::string clean;
        for (char ch : name)
          if (std::isalnum(static_cast<unsigned char>(ch)) || ch == '_') clean += ch;
        // "// version 6" comment words never reach here: the list is plain SQL.
        out.insert(clean);
        pos = end + 1;
      }
    }
    return out;
  }();
  return kTaken;
}

}  // namespace

bool IsParameterColumnName(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  if (!(std::isalpha(static_cast<unsigned char>(name[0])) || name[0] == '_')) return false;
  for (char ch : name)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_')) return false;
  std::string lower;
  for (char ch : name) lower += static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return Taken().count(lower) == 0;
}

std::vector<std::string> ParameterColumns(sqlite3* db) {
  std::vector<std::string> out;
  std::set<std::string> seen;
  detail::Stmt s(db, "SELECT name FROM campaign_parameters ORDER BY rowid");
  while (s.Step()) {
    const std::string name = s.Text(0);
    std::string lower;
    for (char ch : name) lower += static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (IsParameterColumnName(name) && seen.insert(lower).second) out.push_back(name);
  }
  return out;
}

void RebuildResultViews(sqlite3* db) {
  std::string params;
  for (const auto& name : ParameterColumns(db))
    params += ", json_extract(t.params_json, '$." + name + "') AS \"" + name + "\"";
  detail::Exec(db, "DROP VIEW IF EXISTS trial_results", "rebuild trial_results");
  detail::Exec(db,
               std::string("CREATE VIEW trial_results AS SELECT ") + kTrialColumns + params +
                   " FROM trials t LEFT JOIN gt_summary s ON s.stream_id = t.gt_stream_id",
               "rebuild trial_results");
  detail::Exec(db, "DROP VIEW IF EXISTS contact_results", "rebuild contact_results");
  detail::Exec(db,
               std::string("CREATE VIEW contact_results AS SELECT ") + kContactColumns + params +
                   " FROM contact_outcomes c JOIN trials t ON t.gt_stream_id = c.stream_id"
                   " LEFT JOIN gt_summary s ON s.stream_id = c.stream_id",
               "rebuild contact_results");
}

void RegisterParameters(const Store::Impl& impl, std::int64_t campaign_id) {
  // The names of this campaign's trials' parameters, in first-seen order;
  // the views change only when one of them is new to the store.
  const auto before = ParameterColumns(impl.db);
  auto ins = impl.Prepare(
      "INSERT OR IGNORE INTO campaign_parameters(campaign_id, name)"
      " SELECT DISTINCT t.campaign_id, j.key FROM trials t, json_each(t.params_json) j"
      " WHERE t.campaign_id = ? AND j.key IS NOT NULL");
  ins->Bind(1, campaign_id).Run();
  if (ParameterColumns(impl.db) != before) RebuildResultViews(impl.db);
}

void WriteOutcome(const Store::Impl& impl, std::int64_t stream_id, std::int64_t trial_id,
                  int attempt, const TrialOutcome& o) {
  auto c = impl.Prepare(
      "INSERT OR REPLACE INTO contact_outcomes(stream_id, trial_id, attempt, contact, name, role,"
      " stick_fraction, slide_fraction, separate_fraction, slip_distance_m, max_normal_force_n)"
      " VALUES(?,?,?,?,?,?,?,?,?,?,?)");
  for (const auto& k : o.contacts) {
    detail::Binder b(*c);
    b << stream_id << trial_id << attempt << static_cast<std::int64_t>(k.contact) << k.name
      << std::string(k.pusher ? "pusher" : "finger") << k.stick_fraction << k.slide_fraction
      << k.separate_fraction << k.slip_distance << k.max_normal_force;
    c->Run();
    c->Reset();
  }
  auto s = impl.Prepare(
      "UPDATE gt_summary SET net_dx = ?, net_dy = ?, net_dz = ?, net_rx = ?, net_ry = ?,"
      " net_rz = ?, grasp_kept = ? WHERE stream_id = ?");
  detail::Binder b(*s);
  for (int i = 0; i < 3; ++i)
    b << (o.net_translation ? std::optional<double>((*o.net_translation)[i]) : std::nullopt);
  for (int i = 0; i < 3; ++i)
    b << (o.net_rotation ? std::optional<double>((*o.net_rotation)[i]) : std::nullopt);
  if (o.grasp_kept)
    b << static_cast<std::int64_t>(*o.grasp_kept ? 1 : 0);
  else
    b << std::nullopt;
  b << stream_id;
  s->Run();
}

// The contact sites of a stored scene, from the opener's reader (db reads no
// scene). A scene it cannot read has none: its outcome has no slip distances.
static std::vector<ContactSite> StoredSceneContacts(const Store::Impl& impl,
                                                    const std::string& scene_json) {
  if (!impl.options.scene_facts) {
    throw StoreError(
        StoreError::Kind::kIo,
        "Store::Open: migration 6 computes the outcomes of the streams stored before "
        "it from their scenes' contacts: open this store with StoreOptions::scene_facts "
        "set (the caller's reader of scenes)");
  }
  try {
    return impl.options.scene_facts(scene_json).contacts;
  } catch (const std::exception&) {
    return {};
  }
}

void MigrateToOutcomes(const Store::Impl& impl) {
  std::set<std::string> have;
  {
    detail::Stmt cols(impl.db, "PRAGMA table_info(gt_summary)");
    while (cols.Step()) have.insert(cols.Text(1));
  }
  for (const char* c : {"net_dx", "net_dy", "net_dz", "net_rx", "net_ry", "net_rz"}) {
    if (!have.count(c))
      detail::Exec(impl.db, std::string("ALTER TABLE gt_summary ADD COLUMN ") + c + " REAL",
                   "migration 6");
  }
  if (!have.count("grasp_kept")) {
    detail::Exec(
        impl.db,
        "ALTER TABLE gt_summary ADD COLUMN grasp_kept INTEGER CHECK (grasp_kept IN (0, 1))",
        "migration 6");
  }
  // Every published stream gets its outcome from its stored samples, once.
  detail::Stmt streams(impl.db,
                       "SELECT g.id, g.trial_id, g.attempt, g.samples, t.scene_json"
                       " FROM gt_streams g JOIN trials t ON t.id = g.trial_id"
                       " WHERE g.complete = 1 ORDER BY g.id");
  while (streams.Step()) {
    const auto samples =
        ReadStreamSamples(impl, streams.Int(0), streams.Int(3), "migration 6 (outcomes)");
    WriteOutcome(impl, streams.Int(0), streams.Int(1), static_cast<int>(streams.Int(2)),
                 ComputeOutcome(samples, StoredSceneContacts(impl, streams.Text(4))));
  }
  RebuildResultViews(impl.db);
}

}  // namespace arena::db::internal

namespace arena::db {

std::map<std::int64_t, TrialOutcome> Store::ReadTrialOutcomes(std::int64_t campaign_id) const {
  detail::Tx tx(impl_->db, false);  // one snapshot of both tables
  std::map<std::int64_t, TrialOutcome> out;
  auto c = impl_->Prepare(
      "SELECT t.id, c.contact, c.name, c.role, c.stick_fraction, c.slide_fraction,"
      " c.separate_fraction, c.slip_distance_m, c.max_normal_force_n FROM trials t"
      " JOIN contact_outcomes c ON c.stream_id = t.gt_stream_id WHERE t.campaign_id = ?"
      " ORDER BY t.id, c.contact");
  c->Bind(1, campaign_id);
  while (c->Step()) {
    ContactOutcome o;
    o.contact = static_cast<std::size_t>(c->Int(1));
    o.name = c->Text(2);
    o.pusher = c->Text(3) == "pusher";
    o.stick_fraction = c->OptReal(4).value_or(0);
    o.slide_fraction = c->OptReal(5).value_or(0);
    o.separate_fraction = c->OptReal(6).value_or(0);
    o.slip_distance = c->OptReal(7);
    o.max_normal_force = c->OptReal(8).value_or(0);
    out[c->Int(0)].contacts.push_back(std::move(o));
  }
  auto s = impl_->Prepare(
      "SELECT t.id, s.net_dx, s.net_dy, s.net_dz, s.net_rx, s.net_ry, s.net_rz, s.grasp_kept"
      " FROM trials t JOIN gt_summary s ON s.stream_id = t.gt_stream_id"
      " WHERE t.campaign_id = ? AND s.net_dx IS NOT NULL");
  s->Bind(1, campaign_id);
  while (s->Step()) {
    TrialOutcome& o = out[s->Int(0)];
    o.net_translation = std::array<double, 3>{s->Real(1), s->Real(2), s->Real(3)};
    o.net_rotation = std::array<double, 3>{s->Real(4), s->Real(5), s->Real(6)};
    if (!s->IsNull(7)) o.grasp_kept = s->Int(7) != 0;
  }
  return out;
}

}  // namespace arena::db
