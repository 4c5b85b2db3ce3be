// Opening the store and its versioned migrations (db/README.md documents
// each table). PRAGMA user_version is the schema version; each migration
// runs in one transaction together with the bump of user_version and its row
// in schema_migrations, so a crash mid-migration leaves the previous version.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "sqlite_util.hpp"
#include "store_internal.hpp"
#include "wal_coalescing_vfs.hpp"

namespace arena::db {
namespace {

using detail::Exec;

struct Migration {
  int version;
  const char* what;
  const char* sql;
  // Work SQL alone cannot do (decoding stored samples), run after `sql` in
  // the same transaction; nullptr for none.
  void (*after)(const Store::Impl&) = nullptr;
};

// Append only: a released migration is never edited.
const std::vector<Migration>& Migrations() {
  static const std::vector<Migration> kMigrations = {
      {1, "campaigns, cells, trials, transitions, ground truth, predictions", R"sql(
CREATE TABLE schema_migrations(
  version    INTEGER PRIMARY KEY,
  what       TEXT NOT NULL,
  applied_at REAL NOT NULL
);

CREATE TABLE campaigns(
  id                 INTEGER PRIMARY KEY,
  name               TEXT NOT NULL,
  spec_json          TEXT NOT NULL,
  state              TEXT NOT NULL DEFAULT 'active'
                     CHECK (state IN ('active','paused','cancelled','done')),
  priority           INTEGER NOT NULL DEFAULT 0,
  seed               INTEGER NOT NULL,
  sampler_state_json TEXT NOT NULL DEFAULT '{}',
  created_at         REAL NOT NULL,
  updated_at         REAL NOT NULL
);

CREATE TABLE cells(
  id                   TEXT PRIMARY KEY,
  state                TEXT NOT NULL DEFAULT 'healthy'
                       CHECK (state IN ('healthy','quarantined','gone')),
  contact_mask         INTEGER NOT NULL DEFAULT 0,
  capabilities_json    TEXT NOT NULL DEFAULT '{}',
  defects_json         TEXT NOT NULL DEFAULT '{}',
  last_seen            REAL NOT NULL,
  consecutive_failures INTEGER NOT NULL DEFAULT 0,
  total_failures       INTEGER NOT NULL DEFAULT 0,
  quarantine_reason    TEXT NOT NULL DEFAULT '',
  start_x REAL, start_y REAL, start_z REAL,
  start_qw REAL, start_qx REAL, start_qy REAL, start_qz REAL,
  start_observed_at    REAL,
  created_at           REAL NOT NULL,
  updated_at           REAL NOT NULL
);

CREATE TABLE trials(
  id            INTEGER PRIMARY KEY,
  campaign_id   INTEGER NOT NULL REFERENCES campaigns(id),
  idx           INTEGER NOT NULL CHECK (idx >= 0),
  condition     INTEGER NOT NULL CHECK (condition >= 0),
  replicate     INTEGER NOT NULL CHECK (replicate >= 0),
  seed          INTEGER NOT NULL,
  state         TEXT NOT NULL DEFAULT 'planned'
                CHECK (state IN ('planned','dispatched','executed','resetting','reset_done',
                                 'reset_failed','predicted','done','failed','cancelled')),
  attempt       INTEGER NOT NULL DEFAULT 1 CHECK (attempt >= 1),
  cell_id       TEXT REFERENCES cells(id),
  outcome       TEXT,
  not_before    REAL NOT NULL DEFAULT 0,
  object_shape  TEXT,
  object_mass   REAL,
  grip_force    REAL,
  finger_type   TEXT,
  finger_count  INTEGER,
  finger_mu     REAL,
  pusher_type   TEXT,
  pusher_mu     REAL,
  pusher_speed  REAL,
  pusher_angular_speed REAL,
  duration      REAL,
  contact_mask  INTEGER NOT NULL DEFAULT 0,
  nominal_x REAL NOT NULL DEFAULT 0, nominal_y REAL NOT NULL DEFAULT 0,
  nominal_z REAL NOT NULL DEFAULT 0, nominal_qw REAL NOT NULL DEFAULT 1,
  nominal_qx REAL NOT NULL DEFAULT 0, nominal_qy REAL NOT NULL DEFAULT 0,
  nominal_qz REAL NOT NULL DEFAULT 0,
  start_x REAL, start_y REAL, start_z REAL,
  start_qw REAL, start_qx REAL, start_qy REAL, start_qz REAL,
  start_position_error REAL,
  start_angle_error    REAL,
  reset_ok             INTEGER,
  reset_position_error REAL,
  reset_angle_error    REAL,
  reset_attempts       INTEGER,
  reset_reason         TEXT,
  scene_json        TEXT NOT NULL,
  params_json       TEXT NOT NULL DEFAULT '{}',
  defects_json      TEXT NOT NULL DEFAULT '{}',
  cell_defects_json TEXT,
  gt_stream_id  INTEGER REFERENCES gt_streams(id),
  created_at    REAL NOT NULL,
  updated_at    REAL NOT NULL,
  dispatched_at REAL,
  executed_at   REAL,
  finished_at   REAL,
  UNIQUE (campaign_id, idx)
);
CREATE INDEX trials_by_state ON trials(state, campaign_id, idx);
CREATE INDEX trials_by_campaign_state ON trials(campaign_id, state);
CREATE INDEX trials_by_grip_force ON trials(grip_force);
CREATE INDEX trials_by_finger_mu ON trials(finger_mu);
CREATE INDEX trials_by_object_mass ON trials(object_mass);
CREATE INDEX trials_by_pusher_speed ON trials(pusher_speed);
CREATE INDEX trials_by_types ON trials(finger_type, pusher_type);
CREATE INDEX trials_by_outcome ON trials(outcome);
CREATE INDEX trials_by_cell ON trials(cell_id, campaign_id);

CREATE TABLE trial_transitions(
  id         INTEGER PRIMARY KEY,
  trial_id   INTEGER NOT NULL REFERENCES trials(id),
  attempt    INTEGER NOT NULL,
  from_state TEXT NOT NULL,
  to_state   TEXT NOT NULL,
  at         REAL NOT NULL,
  cell_id    TEXT NOT NULL DEFAULT '',
  reason     TEXT NOT NULL DEFAULT ''
);
CREATE INDEX trial_transitions_by_trial ON trial_transitions(trial_id, id);

CREATE TABLE gt_streams(
  id           INTEGER PRIMARY KEY,
  trial_id     INTEGER NOT NULL REFERENCES trials(id),
  attempt      INTEGER NOT NULL,
  cell_id      TEXT NOT NULL DEFAULT '',
  complete     INTEGER NOT NULL DEFAULT 0 CHECK (complete IN (0, 1)),
  samples      INTEGER NOT NULL DEFAULT 0,
  started_at   REAL NOT NULL,
  completed_at REAL
);
CREATE INDEX gt_streams_by_trial ON gt_streams(trial_id, attempt);
CREATE UNIQUE INDEX gt_streams_one_complete ON gt_streams(trial_id, attempt) WHERE complete = 1;

CREATE TABLE gt_chunks(
  id           INTEGER PRIMARY KEY,
  stream_id    INTEGER NOT NULL REFERENCES gt_streams(id) ON DELETE CASCADE,
  seq          INTEGER NOT NULL,
  first_sample INTEGER NOT NULL,
  samples      INTEGER NOT NULL,
  t_first      REAL NOT NULL,
  t_last       REAL NOT NULL,
  data         BLOB NOT NULL,
  UNIQUE (stream_id, seq)
);

CREATE TABLE gt_summary(
  stream_id    INTEGER PRIMARY KEY REFERENCES gt_streams(id) ON DELETE CASCADE,
  trial_id     INTEGER NOT NULL REFERENCES trials(id),
  attempt      INTEGER NOT NULL,
  samples      INTEGER NOT NULL,
  observed_samples INTEGER NOT NULL,
  duration_s   REAL NOT NULL,
  final_x REAL, final_y REAL, final_z REAL,
  final_qw REAL, final_qx REAL, final_qy REAL, final_qz REAL,
  displacement_m       REAL,
  rotation_rad         REAL,
  max_contact_force_n  REAL,
  max_pusher_force_n   REAL,
  stick_fraction       REAL,
  slide_fraction       REAL,
  separate_fraction    REAL,
  observed_position_rmse_m      REAL,
  observed_position_max_error_m REAL
);
CREATE INDEX gt_summary_by_trial ON gt_summary(trial_id);

CREATE TABLE predictions(
  id          INTEGER PRIMARY KEY,
  trial_id    INTEGER NOT NULL REFERENCES trials(id),
  attempt     INTEGER NOT NULL,
  model_key   TEXT NOT NULL,
  model_json  TEXT NOT NULL DEFAULT '{}',
  status      TEXT NOT NULL,
  final_position_error REAL,
  final_angle_error    REAL,
  force_error          REAL,
  mode_agreement       REAL,
  wall_s      REAL NOT NULL CHECK (wall_s >= 0),
  detail_json TEXT NOT NULL DEFAULT '{}',
  created_at  REAL NOT NULL,
  UNIQUE (trial_id, attempt, model_key)
);
CREATE INDEX predictions_by_model ON predictions(model_key);

CREATE VIEW start_state_drift AS
  SELECT campaign_id, cell_id, count(*) AS trials,
         avg(start_x - nominal_x) AS mean_dx, avg(start_y - nominal_y) AS mean_dy,
         avg(start_z - nominal_z) AS mean_dz,
         avg(start_position_error) AS mean_position_error,
         max(start_position_error) AS max_position_error,
         avg(start_angle_error) AS mean_angle_error,
         max(start_angle_error) AS max_angle_error
  FROM trials WHERE start_position_error IS NOT NULL AND cell_id IS NOT NULL
  GROUP BY campaign_id, cell_id;

CREATE VIEW trial_results AS
  SELECT t.id AS trial_id, t.campaign_id, t.idx, t.condition, t.replicate, t.state, t.attempt,
         t.cell_id, t.outcome, t.object_shape, t.object_mass, t.grip_force, t.finger_type,
         t.finger_count, t.finger_mu, t.pusher_type, t.pusher_mu, t.pusher_speed,
         t.pusher_angular_speed, t.duration, t.start_position_error, t.start_angle_error,
         s.samples, s.observed_samples, s.duration_s, s.displacement_m, s.rotation_rad,
         s.max_contact_force_n, s.max_pusher_force_n, s.stick_fraction, s.slide_fraction,
         s.separate_fraction, s.observed_position_rmse_m
  FROM trials t LEFT JOIN gt_summary s ON s.stream_id = t.gt_stream_id;
)sql"},
      {2, "campaigns.state_reason: why a campaign is paused or cancelled", R"sql(
ALTER TABLE campaigns ADD COLUMN state_reason TEXT NOT NULL DEFAULT '';
)sql"},
      {3, "evaluation runs and their per-trial results (arena evaluate)", R"sql(
CREATE TABLE evaluations(
  id            INTEGER PRIMARY KEY,
  campaign_id   INTEGER NOT NULL REFERENCES campaigns(id),
  created_at    REAL NOT NULL,
  settings_json TEXT NOT NULL DEFAULT '{}',
  report_json   TEXT NOT NULL DEFAULT '{}'
);
CREATE INDEX evaluations_by_campaign ON evaluations(campaign_id);

CREATE TABLE evaluation_results(
  evaluation_id INTEGER NOT NULL REFERENCES evaluations(id),
  trial_id      INTEGER NOT NULL REFERENCES trials(id),
  attempt       INTEGER NOT NULL,
  model_key     TEXT NOT NULL,
  model_json    TEXT NOT NULL DEFAULT '{}',
  status        TEXT NOT NULL,
  final_position_error REAL,
  final_angle_error    REAL,
  force_error          REAL,
  mode_agreement       REAL,
  wall_s        REAL NOT NULL CHECK (wall_s >= 0),
  detail_json   TEXT NOT NULL DEFAULT '{}',
  PRIMARY KEY (evaluation_id, trial_id, model_key)
);
CREATE INDEX evaluation_results_by_model ON evaluation_results(evaluation_id, model_key);
)sql"},
      // No table changes: the version marks that gt_chunks.data may hold the
      // packed block format AGT2, so an older arena (which reads only AGT1)
      // refuses the file up front ("newer than this arena") instead of
      // failing on the first packed chunk it reads.
      {4, "ground-truth chunks may be packed (block format AGT2)", R"sql(
-- gt_chunks.data: "AGT1" (raw) or "AGT2" (packed) blocks; db/README.md.
)sql"},
      {5, "service heartbeats, the store's id, cell leases and the cell audit log", R"sql(
CREATE TABLE store_meta(
  key   TEXT PRIMARY KEY,
  value TEXT NOT NULL
);
INSERT INTO store_meta(key, value) VALUES('store_id', lower(hex(randomblob(8))));
CREATE TABLE services(
  session    TEXT PRIMARY KEY,
  pid        INTEGER NOT NULL,
  host       TEXT NOT NULL,
  domain     INTEGER NOT NULL,
  started_at REAL NOT NULL,
  last_beat  REAL NOT NULL,
  stopped_at REAL
);
CREATE INDEX services_by_beat ON services(last_beat);
ALTER TABLE cells ADD COLUMN lease_s REAL NOT NULL DEFAULT 0;
ALTER TABLE cells ADD COLUMN serving TEXT NOT NULL DEFAULT '';
-- Attempts cut short by a service restart (RecoverAfterRestart) are nobody's
-- fault: they do not count against max_attempts.
ALTER TABLE trials ADD COLUMN service_restarts INTEGER NOT NULL DEFAULT 0;
CREATE TABLE cell_events(
  id      INTEGER PRIMARY KEY,
  cell_id TEXT NOT NULL,
  at      REAL NOT NULL,
  event   TEXT NOT NULL CHECK (event IN ('quarantined','released')),
  reason  TEXT NOT NULL DEFAULT '',
  by_whom TEXT NOT NULL DEFAULT ''
);
)sql"},
      // Per-contact outcomes and the object's net motion per stream, computed
      // from the samples (outcomes.hpp) for the streams already stored too;
      // the parameter names of every campaign, which become columns of the
      // views trial_results and contact_results (result_views.cpp).
      {6, "per-contact outcomes, object net motion, parameters as view columns", R"sql(
-- gt_summary's new columns (net_dx ... net_rz, grasp_kept) are added by
-- MigrateToOutcomes, which skips a column that exists: the migration can be
-- re-applied to a file whose user_version was set back.
CREATE TABLE IF NOT EXISTS contact_outcomes(
  stream_id          INTEGER NOT NULL REFERENCES gt_streams(id) ON DELETE CASCADE,
  trial_id           INTEGER NOT NULL REFERENCES trials(id),
  attempt            INTEGER NOT NULL,
  contact            INTEGER NOT NULL CHECK (contact >= 0),
  name               TEXT NOT NULL,
  role               TEXT NOT NULL CHECK (role IN ('finger', 'pusher')),
  stick_fraction     REAL,
  slide_fraction     REAL,
  separate_fraction  REAL,
  slip_distance_m    REAL,
  max_normal_force_n REAL,
  PRIMARY KEY (stream_id, contact)
);
CREATE INDEX IF NOT EXISTS contact_outcomes_by_trial ON contact_outcomes(trial_id);

CREATE TABLE IF NOT EXISTS campaign_parameters(
  campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
  name        TEXT NOT NULL,
  PRIMARY KEY (campaign_id, name)
);
INSERT OR IGNORE INTO campaign_parameters(campaign_id, name)
  SELECT t.campaign_id, j.key FROM trials t, json_each(t.params_json) j
  WHERE j.key IS NOT NULL ORDER BY t.id, j.id;
)sql",
       internal::MigrateToOutcomes},
      // Adaptive campaigns (orchestrator/adaptive.hpp) and calibrations
      // (assessment/calibration.hpp). sampler_open = 1: an adaptive sampler
      // may still add trials, so the campaign is not done when its trials are.
      {7, "adaptive sampler decisions, campaigns.sampler_open, calibrations", R"sql(
ALTER TABLE campaigns ADD COLUMN sampler_open INTEGER NOT NULL DEFAULT 0;

CREATE TABLE sampler_decisions(
  id          INTEGER PRIMARY KEY,
  campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
  round       INTEGER NOT NULL CHECK (round >= 0),
  trial_id    INTEGER REFERENCES trials(id),
  reason      TEXT NOT NULL,
  basis_json  TEXT NOT NULL DEFAULT '{}',
  created_at  REAL NOT NULL
);
CREATE INDEX sampler_decisions_by_campaign ON sampler_decisions(campaign_id, round, id);
CREATE UNIQUE INDEX sampler_decisions_by_trial ON sampler_decisions(trial_id)
  WHERE trial_id IS NOT NULL;

CREATE VIEW trial_decisions AS
  SELECT t.id AS trial_id, t.campaign_id, t.idx, t.state, t.params_json, t.outcome,
         d.round, d.reason, d.basis_json
  FROM sampler_decisions d JOIN trials t ON t.id = d.trial_id;

CREATE TABLE calibrations(
  id            INTEGER PRIMARY KEY,
  campaign_id   INTEGER NOT NULL REFERENCES campaigns(id),
  created_at    REAL NOT NULL,
  params_json   TEXT NOT NULL DEFAULT '{}',
  settings_json TEXT NOT NULL DEFAULT '{}',
  heldout_error_before REAL NOT NULL,
  heldout_error_after  REAL NOT NULL,
  applied       INTEGER NOT NULL CHECK (applied IN (0, 1)),
  report_json   TEXT NOT NULL DEFAULT '{}'
);
CREATE INDEX calibrations_by_campaign ON calibrations(campaign_id);
)sql"},
      {8, "sensitivity runs: predicted vs observed spread and unstable conditions", R"sql(
-- IF NOT EXISTS: a file rolled back to an older version by hand (as the
-- migration tests do) may still hold these tables; they are kept as they are.
CREATE TABLE IF NOT EXISTS sensitivity_runs(
  id            INTEGER PRIMARY KEY,
  campaign_id   INTEGER NOT NULL REFERENCES campaigns(id),
  created_at    REAL NOT NULL,
  settings_json TEXT NOT NULL DEFAULT '{}',
  report_json   TEXT NOT NULL DEFAULT '{}'
);
CREATE INDEX IF NOT EXISTS sensitivity_runs_by_campaign ON sensitivity_runs(campaign_id);

CREATE TABLE IF NOT EXISTS sensitivity_conditions(
  run_id        INTEGER NOT NULL REFERENCES sensitivity_runs(id),
  condition     INTEGER NOT NULL CHECK (condition >= 0),
  params_json   TEXT NOT NULL DEFAULT '{}',
  replicates    INTEGER NOT NULL CHECK (replicates >= 0),
  ensemble      INTEGER NOT NULL CHECK (ensemble >= 0),
  ensemble_failed INTEGER NOT NULL DEFAULT 0 CHECK (ensemble_failed >= 0),
  predicted_position_spread REAL,
  observed_position_spread  REAL,
  predicted_rotation_spread REAL,
  observed_rotation_spread  REAL,
  predicted_displacement    REAL,
  observed_displacement     REAL,
  predicted_rotation        REAL,
  observed_rotation         REAL,
  verdict       TEXT NOT NULL,
  flip_fraction REAL NOT NULL DEFAULT 0,
  unstable      INTEGER NOT NULL CHECK (unstable IN (0, 1)),
  boundary_parameter  TEXT NOT NULL DEFAULT '',
  boundary_offset     REAL,
  boundary_tolerances REAL,
  reason        TEXT NOT NULL DEFAULT '',
  detail_json   TEXT NOT NULL DEFAULT '{}',
  PRIMARY KEY (run_id, condition)
);

-- The latest run of each campaign, one row per condition (what `arena plot
-- --map` and `arena export` read).
CREATE VIEW IF NOT EXISTS sensitivity_latest AS
  SELECT r.campaign_id, c.*
  FROM sensitivity_conditions c JOIN sensitivity_runs r ON r.id = c.run_id
  WHERE r.id = (SELECT max(id) FROM sensitivity_runs WHERE campaign_id = r.campaign_id);
)sql"},
      // Closed-loop trials (issue 19): the controller, its own outcome, and
      // every command the cell applied (ground truth like the samples).
      // IF NOT EXISTS: tests fake an older file by lowering user_version
      // without dropping later tables.
      {9, "closed-loop runs and their applied pusher commands", R"sql(
CREATE TABLE IF NOT EXISTS closed_loop_runs(
  trial_id      INTEGER NOT NULL REFERENCES trials(id),
  attempt       INTEGER NOT NULL,
  controller    TEXT NOT NULL,
  lockstep      INTEGER NOT NULL CHECK (lockstep IN (0, 1)),
  target        REAL NOT NULL,
  gain          REAL NOT NULL,
  tolerance     REAL NOT NULL,
  hold_s        REAL NOT NULL,
  reached       INTEGER CHECK (reached IN (0, 1)),  -- NULL: not a library law (not scored)
  final_error   REAL,
  settle_time_s REAL,                               -- NULL: never settled
  held          INTEGER NOT NULL,                   -- samples without a fresh answer
  loop_p50_ms   REAL,
  loop_p99_ms   REAL,
  failure       TEXT NOT NULL DEFAULT '',           -- why the phase failed ('' if it ran through)
  created_at    REAL NOT NULL,
  PRIMARY KEY (trial_id, attempt)
);
CREATE TABLE IF NOT EXISTS closed_loop_commands(
  trial_id   INTEGER NOT NULL,
  attempt    INTEGER NOT NULL,
  sample     INTEGER NOT NULL,   -- the sample it answered; applied from the next step on
  t          REAL NOT NULL,
  vx REAL NOT NULL, vy REAL NOT NULL, vz REAL NOT NULL,                 -- commanded (m/s)
  applied_vx REAL NOT NULL, applied_vy REAL NOT NULL, applied_vz REAL NOT NULL,  -- actuated
  loop_ms    REAL,               -- live sample -> command accepted; NULL: held
  PRIMARY KEY (trial_id, attempt, sample),
  FOREIGN KEY (trial_id, attempt) REFERENCES closed_loop_runs(trial_id, attempt)
) WITHOUT ROWID;
)sql"},
      // What a trial's ground truth is and which defects were really applied
      // (issue 13): every report can say which truth it measured against.
      {10, "trials: the cell backend, its kind of truth and the defects applied", R"sql(
ALTER TABLE trials ADD COLUMN backend TEXT;          -- "model", "mujoco", "exec:...", "replay:..."
ALTER TABLE trials ADD COLUMN truth TEXT;            -- self-consistency | simulator | robot | recorded
ALTER TABLE trials ADD COLUMN defects_applied TEXT;  -- JSON: cell, campaign, effective profile, draws
)sql"},
      // Versions 11-13 are left to work on other branches; versions apply in order.
      // A reset is aimed at the trial the service expects next on the cell;
      // another cell may take that trial. Without knowing which trial a
      // cell's observed start was prepared for, a trial run from another
      // trial's reset was charged that reset's placement error.
      {14, "cells.start_for_trial: the trial a cell's observed start was aimed at", R"sql(
ALTER TABLE cells ADD COLUMN start_for_trial INTEGER;  -- 0: aimed at no trial; NULL: not known
)sql"},
      // "Why did trial 17 go to resetting?": every audit row names the rule
      // that decided it (orchestrator/trial_policy.hpp, retry_rule.hpp, or
      // the store's own edge). Older rows keep ''.
      {15, "trial_transitions.rule: the rule that decided each transition", R"sql(
ALTER TABLE trial_transitions ADD COLUMN rule TEXT NOT NULL DEFAULT '';
)sql"},
      // Issue 29: suspensions (a condition paused dispatch for a cell, a
      // campaign or the whole service, and when it was lifted, by which rule
      // or by `arena resume`) and the service's events (what `arena serve
      // --notify` is told, also kept here). IF NOT EXISTS: tests fake an
      // older file by lowering user_version without dropping later tables.
      {16, "suspensions and service events", R"sql(
CREATE TABLE IF NOT EXISTS suspensions(
  id          INTEGER PRIMARY KEY,
  condition   TEXT NOT NULL,        -- reset_failure_rate, start_pose_drift, ... (suspender_policy.hpp)
  scope       TEXT NOT NULL CHECK (scope IN ('cell', 'campaign', 'service')),
  campaign_id INTEGER REFERENCES campaigns(id),  -- campaign scope (NULL otherwise)
  cell_id     TEXT,                              -- cell scope (NULL otherwise)
  rule        TEXT NOT NULL,        -- the rule that fired it ("reset_failure_rate.fired")
  evidence    TEXT NOT NULL,        -- the reading against its limit
  fired_at    REAL NOT NULL,
  lifted_at   REAL,                 -- NULL: still holds dispatch back
  lifted_by   TEXT,                 -- the rule that lifted it, or 'arena resume'
  lift_reason TEXT
);
CREATE INDEX IF NOT EXISTS suspensions_active ON suspensions(lifted_at, scope);
CREATE TABLE IF NOT EXISTS service_events(
  id          INTEGER PRIMARY KEY,
  at          REAL NOT NULL,
  kind        TEXT NOT NULL,        -- campaign_done, cell_gone, suspension_fired, ...
  campaign_id INTEGER,
  cell_id     TEXT,
  message     TEXT NOT NULL,
  event_json  TEXT NOT NULL         -- what the --notify command was given on stdin
);
)sql"},
      // Issue 29: a cell's fixture changes (finger pads, pusher, object),
      // each with what it changed from and to and the seconds it cost, so
      // that change-aware scheduling's saving is measured from the store.
      {17, "fixture_changes: each change of a cell's fixtures, from, to and seconds", R"sql(
CREATE TABLE IF NOT EXISTS fixture_changes(
  id          INTEGER PRIMARY KEY,
  trial_id    INTEGER NOT NULL REFERENCES trials(id),  -- the trial whose phase made it
  attempt     INTEGER NOT NULL,
  cell_id     TEXT NOT NULL REFERENCES cells(id),
  phase       TEXT NOT NULL CHECK (phase IN ('reset', 'execute')),  -- when the cell made it
  what        TEXT NOT NULL CHECK (what IN ('finger', 'pusher', 'object')),
  from_key    TEXT NOT NULL,  -- '' when nothing was known to be mounted
  to_key      TEXT NOT NULL,
  seconds     REAL NOT NULL CHECK (seconds >= 0),
  at          REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS fixture_changes_trial ON fixture_changes(trial_id);
)sql"},
      // Issue 26: why an active campaign's trials wait at claim: no live cell
      // can host them (orchestrator/claim_gate.hpp). One row per waiting
      // campaign; deleted when a cell that can host it announces. The claim
      // skips a campaign that has one.
      {18, "campaign_waits: why no live cell can host a campaign's trials", R"sql(
CREATE TABLE IF NOT EXISTS campaign_waits(
  campaign_id INTEGER PRIMARY KEY REFERENCES campaigns(id),
  kind        TEXT NOT NULL
              CHECK (kind IN ('defects', 'contact_types', 'workspace', 'pusher_speed')),
  reason      TEXT NOT NULL CHECK (reason <> ''),
  rule        TEXT NOT NULL,
  since       REAL NOT NULL
);
)sql"},
  };
  return kMigrations;
}

std::int64_t PageSize(sqlite3* db) {
  detail::Stmt s(db, "PRAGMA page_size");
  s.Step();
  return s.Int(0);
}

int UserVersion(sqlite3* db) {
  detail::Stmt s(db, "PRAGMA user_version");
  s.Step();
  return static_cast<int>(s.Int(0));
}

// Whether the connection can read the schema (the first access that needs
// the WAL's shared memory).
bool CanRead(sqlite3* db) {
  sqlite3_stmt* st = nullptr;
  int rc = sqlite3_prepare_v2(db, "SELECT count(*) FROM sqlite_master", -1, &st, nullptr);
  if (rc == SQLITE_OK) rc = sqlite3_step(st);
  sqlite3_finalize(st);
  return rc == SQLITE_ROW;
}

// Whether the connection failed for want of the WAL's shared memory (cannot
// create or write the -shm / -wal files), rather than e.g. a corrupt file.
bool NeedsSharedMemory(sqlite3* db) {
  if (CanRead(db)) return false;
  const int rc = sqlite3_extended_errcode(db) & 0xff;
  return rc == SQLITE_CANTOPEN || rc == SQLITE_READONLY;
}

std::int64_t FileSize(const std::string& path) {
  std::error_code ec;
  const auto n = std::filesystem::file_size(path, ec);
  return ec ? -1 : static_cast<std::int64_t>(n);
}

// Read-only access to a store whose directory is not writable. Without a
// -wal file (or with an empty one) every committed transaction is in the main
// file, and SQLite's immutable=1 reads it with no lock and no -shm. With a
// non-empty -wal (a writer stopped without a checkpoint), immutable=1 would
// silently miss those transactions: the file and its WAL are copied into a
// private temporary directory and the copy is read (removed on close).
void OpenWithoutSharedMemory(Store::Impl& impl) {
  sqlite3_close_v2(impl.db);
  impl.db = nullptr;
  const std::string& path = impl.path;
  std::string target = path;
  if (FileSize(path + "-wal") > 0) {
    const char* tmp = std::getenv("TMPDIR");
    std::string tmpl = std::string(tmp && *tmp ? tmp : "/tmp") + "/arena-readonly-XXXXXX";
    if (::mkdtemp(tmpl.data()) == nullptr) {
      throw StoreError(StoreError::Kind::kIo,
                       "Store::Open: '" + path +
                           "' is in a directory this user cannot write and has an unmerged "
                           "WAL; reading it needs a private copy, but no temporary directory "
                           "could be made (set TMPDIR to a writable directory)");
    }
    impl.private_copy_dir = tmpl;
    const std::filesystem::path dir(tmpl);
    std::error_code ec;
    std::filesystem::copy_file(path, dir / "store.db", ec);
    if (!ec) std::filesystem::copy_file(path + "-wal", dir / "store.db-wal", ec);
    if (ec) {
      throw StoreError(StoreError::Kind::kIo,
                       "Store::Open: cannot copy '" + path + "' for reading: " + ec.message());
    }
    target = (dir / "store.db").string();
    const int rc =
        sqlite3_open_v2(target.c_str(), &impl.db, SQLITE_OPEN_NOMUTEX | SQLITE_OPEN_READONLY,
                        detail::WalCoalescingVfsName());
    if (rc == SQLITE_OK && CanRead(impl.db)) return;
  } else {
    // URI form: the path's own '?' and '#' must not be taken as URI syntax.
    std::string uri = "file:";
    for (char c : std::filesystem::absolute(path).string()) {
      if (c == '?' || c == '#' || c == '%') {
        char buf[4];
        std::snprintf(buf, sizeof buf, "%%%02X", static_cast<unsigned char>(c));
        uri += buf;
      } else {
        uri += c;
      }
    }
    uri += "?mode=ro&immutable=1";
    const int rc = sqlite3_open_v2(uri.c_str(), &impl.db,
                                   SQLITE_OPEN_NOMUTEX | SQLITE_OPEN_READONLY | SQLITE_OPEN_URI,
                                   detail::WalCoalescingVfsName());
    if (rc == SQLITE_OK && CanRead(impl.db)) return;
  }
  const std::string why = impl.db ? sqlite3_errmsg(impl.db) : "out of memory";
  throw StoreError(StoreError::Kind::kIo, "Store::Open: cannot read '" + path + "': " + why);
}

struct Progress {
  std::chrono::steady_clock::time_point deadline;
  bool bounded = false;
};

int PastDeadline(void* p) {
  const auto* g = static_cast<const Progress*>(p);
  return g->bounded && std::chrono::steady_clock::now() > g->deadline ? 1 : 0;
}

Store::QuickCheckResult RunQuickCheck(sqlite3* db, double budget_s) {
  const auto start = std::chrono::steady_clock::now();
  Progress p{start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                         std::chrono::duration<double>(budget_s > 0 ? budget_s : 0)),
             budget_s > 0};
  Store::QuickCheckResult r;
  sqlite3_progress_handler(db, 4096, PastDeadline, &p);
  sqlite3_stmt* s = nullptr;
  int rc = sqlite3_prepare_v2(db, "PRAGMA quick_check(20)", -1, &s, nullptr);
  std::string problems;
  while (rc == SQLITE_OK || rc == SQLITE_ROW) {
    rc = sqlite3_step(s);
    if (rc != SQLITE_ROW) break;
    const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
    const std::string line = text ? text : "";
    if (line == "ok") continue;
    if (!problems.empty()) problems += "; ";
    problems += line;
  }
  const std::string error = sqlite3_errmsg(db);
  sqlite3_finalize(s);
  sqlite3_progress_handler(db, 0, nullptr, nullptr);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if ((rc & 0xff) == SQLITE_INTERRUPT) return r;  // out of time: complete = false
  r.complete = true;
  if (rc != SQLITE_DONE) {
    // A page too broken to walk (or not a database at all) fails the pragma itself.
    if (detail::KindOf(rc) == StoreError::Kind::kBusy) detail::Throw(db, rc, "PRAGMA quick_check");
    problems = error;
  }
  r.problems = problems;
  return r;
}

Store::QuickCheckResult CheckSound(sqlite3* db, const std::string& path, double budget_s) {
  std::error_code ec;
  if (std::filesystem::file_size(path, ec) == 0) {  // a new store: nothing to check
    Store::QuickCheckResult r;
    r.complete = true;
    return r;
  }
  auto r = RunQuickCheck(db, budget_s);
  if (!r.problems.empty()) {
    throw StoreError(StoreError::Kind::kCorrupt,
                     "Store::Open: '" + path +
                         "' is corrupt (PRAGMA quick_check: " + r.problems.substr(0, 400) +
                         "); nothing was written to it. Restore a backup, or salvage what "
                         "is readable with `sqlite3 " +
                         path + " .recover | sqlite3 NEW.db`");
  }
  return r;
}

void Migrate(Store::Impl& impl) {
  sqlite3* db = impl.db;
  const int target = Store::SchemaVersion();
  if (UserVersion(db) == target) return;
  detail::Tx tx(db, /*immediate=*/true);
  // Re-read under the write lock: another process may have migrated meanwhile.
  const int current = UserVersion(db);
  if (current > target) {
    throw StoreError(StoreError::Kind::kTooNew,
                     "Store::Open: '" + impl.path + "' has schema version " +
                         std::to_string(current) + ", newer than this arena's " +
                         std::to_string(target) + "; use a newer arena binary");
  }
  for (const auto& m : Migrations()) {
    if (m.version <= current) continue;
    Exec(db, m.sql, "Store::Open: migration " + std::to_string(m.version));
    if (m.after) m.after(impl);
    detail::Stmt ins(db, "INSERT INTO schema_migrations(version, what, applied_at) VALUES(?,?,?)");
    ins.Bind(1, m.version).Bind(2, m.what).Bind(3, impl.Now()).Run();
    Exec(db, "PRAGMA user_version = " + std::to_string(m.version), "Store::Open: user_version");
  }
  tx.Commit();
}

}  // namespace

int Store::SchemaVersion() { return Migrations().back().version; }

Store::Store(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Store::~Store() = default;

namespace {

void CheckOpenOptions(const StoreOptions& options) {
  if (options.wal_autocheckpoint_bytes < 65536) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "Store::Open: wal_autocheckpoint_bytes must be at least 65536 (got " +
                         std::to_string(options.wal_autocheckpoint_bytes) + ")");
  }
  const int ps = options.new_file_page_size;
  if (ps < 512 || ps > 65536 || (ps & (ps - 1)) != 0) {
    throw StoreError(
        StoreError::Kind::kBadInput,
        "Store::Open: new_file_page_size must be a power of two in [512, 65536] (got " +
            std::to_string(ps) + ")");
  }
}

// A path that names no store: a missing file (read-only) or a directory.
void RefuseNoStoreAt(const std::string& path, const StoreOptions& options) {
  if (options.read_only && !std::filesystem::exists(path)) {
    throw StoreError(StoreError::Kind::kIo,
                     "Store::Open: no store at '" + path + "' (create one with 'arena submit')");
  }
  std::error_code ec;
  // A new store in a folder that is not there: SQLite says only "unable to
  // open database file"; name the folder (the README's out/smoke.db).
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  if (!options.read_only && !folder.empty() && !std::filesystem::exists(path, ec) &&
      !std::filesystem::is_directory(folder, ec)) {
    throw StoreError(StoreError::Kind::kIo,
                     "Store::Open: cannot create '" + path + "': the folder '" + folder.string() +
                         "' does not exist (mkdir -p " + folder.string() + ")");
  }
  if (std::filesystem::is_directory(path, ec)) {
    throw StoreError(StoreError::Kind::kIo,
                     "Store::Open: '" + path +
                         "' is a directory; --db names the store file (e.g. '" +
                         (std::filesystem::path(path) / "lab.db").string() + "')");
  }
}

void OpenConnection(Store::Impl& impl, const StoreOptions& options) {
  int flags = SQLITE_OPEN_NOMUTEX;  // one connection per thread (documented)
  if (options.read_only) {
    flags |= SQLITE_OPEN_READONLY;
  } else {
    flags |= SQLITE_OPEN_READWRITE | (options.create ? SQLITE_OPEN_CREATE : 0);
  }
  // The WAL's frames of a commit go to the file in one write (wal_coalescing_vfs.cpp).
  int rc = sqlite3_open_v2(impl.path.c_str(), &impl.db, flags, detail::WalCoalescingVfsName());
  if (rc == SQLITE_OK && options.read_only && NeedsSharedMemory(impl.db)) {
    // A WAL store in a directory we cannot write (a copy made for reading,
    // a read-only mount): SQLite cannot create the -shm file next to it.
    OpenWithoutSharedMemory(impl);
  }
  if (rc != SQLITE_OK) {
    std::string msg = "Store::Open: cannot open '" + impl.path +
                      "': " + (impl.db ? sqlite3_errmsg(impl.db) : sqlite3_errstr(rc));
    throw StoreError(detail::KindOf(rc) == StoreError::Kind::kCorrupt ? StoreError::Kind::kCorrupt
                                                                      : StoreError::Kind::kIo,
                     msg);
  }
}

// WAL: readers never block the writer and the writer never blocks readers.
// Switching a new file to WAL needs an exclusive lock and SQLite does not
// always call the busy handler for it: two processes creating the same
// store at once (`arena serve` and `arena submit`) saw "database is
// locked". Retry for up to busy_timeout_ms.
void SwitchToWal(sqlite3* db, const StoreOptions& options, const std::string& ctx) {
  std::string mode;
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(options.busy_timeout_ms);
  for (;;) {
    try {
      detail::Stmt wal(db, "PRAGMA journal_mode = WAL");
      wal.Step();
      mode = wal.Text(0);
      break;
    } catch (const StoreError& e) {
      if (e.kind() != StoreError::Kind::kBusy || std::chrono::steady_clock::now() > give_up) throw;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  if (mode != "wal") {
    throw StoreError(StoreError::Kind::kIo,
                     ctx + ": cannot switch to WAL mode (got '" + mode + "')");
  }
}

// After each commit of a connection whose checkpoints another thread runs
// (StoreOptions::wal_checkpoint_due): past the due size it asks for one;
// past the backstop it runs one itself, as SQLite's autocheckpoint would.
int WalCommitted(void* arg, sqlite3* db, const char* schema, int frames) {
  const auto& impl = *static_cast<const Store::Impl*>(arg);
  if (frames >= impl.wal_backstop_frames) {
    sqlite3_wal_checkpoint_v2(db, schema, SQLITE_CHECKPOINT_PASSIVE, nullptr, nullptr);
  } else if (frames >= impl.wal_due_frames) {
    try {
      impl.options.wal_checkpoint_due();
    } catch (...) {  // a callback that threw must not fail a commit that is done
    }
  }
  return SQLITE_OK;
}

// The pragmas of the connection; a read-write one is switched to WAL and migrated.
void ConfigureAndMigrate(Store::Impl& impl, const StoreOptions& options, const std::string& ctx) {
  sqlite3* db = impl.db;
  if (!options.read_only && options.open_check_budget_s > 0) {
    // Before anything writes: a page of `trials` garbled left SQLite able
    // to append to the file without a word (the damage shows only when a
    // reader reaches it), so a writing command refuses it up front.
    impl.open_check = CheckSound(db, impl.path, options.open_check_budget_s);
  }
  Exec(db, "PRAGMA foreign_keys = ON", ctx);
  if (!options.read_only) {
    // A new file gets 8 KiB pages (no effect on an existing one, whose
    // page size is fixed): a ground-truth chunk spans half as many
    // overflow pages, each a WAL frame write and a checkpoint copy, so
    // ingest costs ~25 % less CPU; small commits (claims, transitions)
    // cost about the same as with 4 KiB. 16 KiB and more made each small
    // commit 2-5x slower (bench/README.md, "Store").
    Exec(db, "PRAGMA page_size = " + std::to_string(options.new_file_page_size), ctx);
  }
  const std::int64_t page_size = PageSize(db);
  if (options.max_pages > 0) {
    const std::int64_t pages = std::max<std::int64_t>(1, options.max_pages * 4096 / page_size);
    Exec(db, "PRAGMA max_page_count = " + std::to_string(pages), ctx);
  }
  if (options.read_only) {
    Exec(db, "PRAGMA query_only = ON", ctx);
    return;
  }
  SwitchToWal(db, options, ctx);
  Exec(db, options.synchronous_full ? "PRAGMA synchronous = FULL" : "PRAGMA synchronous = NORMAL",
       ctx);
  const std::int64_t due_frames =
      std::max<std::int64_t>(1, options.wal_autocheckpoint_bytes / page_size);
  if (options.wal_checkpoint_due) {
    // One hook slot per connection: it replaces the autocheckpoint's.
    impl.wal_due_frames = due_frames;
    impl.wal_backstop_frames = 4 * due_frames;
    sqlite3_wal_hook(db, &WalCommitted, &impl);
  } else {
    Exec(db, "PRAGMA wal_autocheckpoint = " + std::to_string(due_frames), ctx);
  }
  Migrate(impl);
}

void CheckSchemaVersion(sqlite3* db, const std::string& path) {
  const int version = UserVersion(db);
  if (version > Store::SchemaVersion()) {
    throw StoreError(StoreError::Kind::kTooNew,
                     "Store::Open: '" + path + "' has schema version " + std::to_string(version) +
                         ", newer than this arena's " + std::to_string(Store::SchemaVersion()) +
                         "; use a newer arena binary");
  }
  if (version < Store::SchemaVersion()) {
    throw StoreError(StoreError::Kind::kIo,
                     "Store::Open: '" + path + "' has schema version " + std::to_string(version) +
                         " (this arena writes " + std::to_string(Store::SchemaVersion()) +
                         "); open it read-write once (e.g. 'arena serve') to migrate it");
  }
}

}  // namespace

std::unique_ptr<Store> Store::Open(const std::string& path, const StoreOptions& options) {
  CheckOpenOptions(options);
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->options = options;
  RefuseNoStoreAt(path, options);
  OpenConnection(*impl, options);
  sqlite3* db = impl->db;
  sqlite3_extended_result_codes(db, 1);
  sqlite3_busy_timeout(db, options.busy_timeout_ms);
  const std::string ctx = "Store::Open '" + path + "'";
  if (!options.read_only && sqlite3_db_readonly(db, "main") == 1) {
    // SQLite silently opens a write-protected file read-only; say so now.
    throw StoreError(StoreError::Kind::kReadOnly,
                     "Store::Open: '" + path +
                         "' is not writable (file or directory permissions, "
                         "or a read-only file system); fix the permissions or open it read-only");
  }
  try {
    ConfigureAndMigrate(*impl, options, ctx);
    CheckSchemaVersion(db, path);
  } catch (const StoreError& e) {
    if (e.kind() == StoreError::Kind::kBadInput) {
      // "file is not a database" and friends surface as generic errors here.
      throw StoreError(StoreError::Kind::kCorrupt, e.what());
    }
    throw;
  }
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) {
    impl->file_dev = static_cast<unsigned long long>(st.st_dev);
    impl->file_ino = static_cast<unsigned long long>(st.st_ino);
  }
  return std::unique_ptr<Store>(new Store(std::move(impl)));
}

int Store::FileSchemaVersion() const { return UserVersion(impl_->db); }
bool Store::read_only() const { return impl_->options.read_only; }
const std::string& Store::path() const { return impl_->path; }
double Store::Now() const { return impl_->Now(); }

Store::QuickCheckResult Store::QuickCheck(double budget_s) const {
  return RunQuickCheck(impl_->db, budget_s);
}

const Store::QuickCheckResult& Store::open_check() const { return impl_->open_check; }

std::int64_t Store::CheckpointWal() {
  impl_->RequireWritable("CheckpointWal");
  int log = 0, copied = 0;
  const int rc =
      sqlite3_wal_checkpoint_v2(impl_->db, nullptr, SQLITE_CHECKPOINT_PASSIVE, &log, &copied);
  if (rc == SQLITE_BUSY) return 0;  // another connection's checkpoint runs
  if (rc != SQLITE_OK) detail::Throw(impl_->db, rc, "CheckpointWal");
  return copied;
}

void Store::Interrupt() const { sqlite3_interrupt(impl_->db); }

std::string Store::IntegrityCheck() const {
  detail::Stmt s(impl_->db, "PRAGMA integrity_check");
  std::string out;
  while (s.Step()) {
    if (!out.empty()) out += "; ";
    out += s.Text(0);
  }
  detail::Stmt fk(impl_->db, "PRAGMA foreign_key_check");
  while (fk.Step()) {
    out += "; foreign key violation in " + fk.Text(0) + " rowid " + std::to_string(fk.Int(1));
  }
  return out;
}

}  // namespace arena::db
