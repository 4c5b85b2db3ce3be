// Ground-truth ingest: samples are encoded as they arrive, written as BLOB
// chunks in batched transactions, and published together with the trial's
// move to `executed` (store.hpp, invariants 3 and 4).
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "arena/db/outcomes.hpp"
#include "arena/db/store.hpp"
#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db {

using detail::Tx;
using internal::CheckAttempt;
using internal::LoadTrialRow;
using internal::QuatAngle;

namespace {

bool HasGroundTruthState(TrialState s) {
  switch (s) {
    case TrialState::kExecuted:
    case TrialState::kResetting:
    case TrialState::kResetDone:
    case TrialState::kResetFailed:
    case TrialState::kPredicted:
    case TrialState::kDone:
      return true;
    default:
      return false;
  }
}

// Refuses unless the trial can take ground truth of `attempt`: dispatched
// (first ingest), or already past executed at the same attempt (re-ingest).
internal::TrialRow CheckIngestable(const Store::Impl& impl, std::int64_t trial_id, int attempt,
                                   const char* function) {
  const auto row = LoadTrialRow(impl, trial_id, function);
  CheckAttempt(row, trial_id, attempt, function);
  if (row.state != TrialState::kDispatched && !HasGroundTruthState(row.state)) {
    throw StoreError(StoreError::Kind::kIllegalTransition,
                     std::string(function) + ": trial " + std::to_string(trial_id) + " is " +
                         ToString(row.state) + "; ground truth is taken only while dispatched");
  }
  return row;
}

double Norm3(const std::array<double, 3>& v) {
  return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

// trials.start_*: the start the executing cell measured, the pose the trial's
// predictions start from. It replaces the claim's copy of the cell's last
// reset observation, which a trial lacks when it is a cell's first or another
// cell claimed the trial that reset was aimed at.
void WriteMeasuredStart(const Store::Impl& impl, std::int64_t trial_id,
                        const std::array<double, 7>& start) {
  auto r = impl.Prepare(
      "SELECT nominal_x, nominal_y, nominal_z, nominal_qw, nominal_qx, nominal_qy, nominal_qz"
      " FROM trials WHERE id = ?");
  r->Bind(1, trial_id);
  r->Step();
  double nominal[7];
  for (int i = 0; i < 7; ++i) nominal[i] = r->Real(i);
  const double dx = start[0] - nominal[0], dy = start[1] - nominal[1], dz = start[2] - nominal[2];
  auto u = impl.Prepare(
      "UPDATE trials SET start_x = ?, start_y = ?, start_z = ?, start_qw = ?, start_qx = ?,"
      " start_qy = ?, start_qz = ?, start_position_error = ?, start_angle_error = ? WHERE id = ?");
  detail::Binder b(*u);
  for (double v : start) b << v;
  b << std::sqrt(dx * dx + dy * dy + dz * dz) << QuatAngle(start.data() + 3, nominal + 3)
    << trial_id;
  u->Run();
}

struct Chunk {
  std::int64_t first_sample = 0;
  std::uint32_t samples = 0;
  double t_first = 0, t_last = 0;
  std::string data;
};

}  // namespace

struct Ingest::Impl {
  Store::Impl* store = nullptr;
  std::int64_t trial_id = 0;
  int attempt = 0;
  std::int64_t stream_id = 0;
  bool has_pusher = false;
  IngestOptions options;
  bool finished = false;

  // The chunk being encoded and the closed chunks not yet committed.
  std::string body;
  Chunk open;
  std::vector<Chunk> ready;
  std::int64_t buffered = 0;
  std::int64_t next_seq = 0;
  std::int64_t total = 0;
  std::chrono::steady_clock::time_point oldest{};

  // Per-trial summary, accumulated as samples arrive.
  double last_t = -INFINITY;
  std::array<double, 7> first_pose{}, last_pose{};
  // The start the cell measured: the first sample's observed pose, or its own
  // pose when the sensors dropped it (the rule of assessment::StartOf).
  std::array<double, 7> measured_start{};
  std::int64_t observed = 0;
  double max_contact_force = 0, max_pusher_force = 0;
  std::int64_t modes[3] = {0, 0, 0};
  double obs_sq_sum = 0, obs_max = 0;
  // Per-contact and object outcomes (outcomes.hpp), from the scene's contact sites.
  std::unique_ptr<OutcomeAccumulator> outcome;

  // Shape of the open chunk's samples: only a uniform chunk can be packed.
  int chunk_contacts = -1, chunk_finger_values = -1;
  bool chunk_uniform = true;

  void CloseChunk() {
    if (open.samples == 0) return;
    PatchBlockCount(open.samples, &body);
    if (options.pack_chunks && chunk_uniform && PackBlock(body.data(), body.size(), &open.data)) {
      body.clear();  // keep its capacity for the next chunk
    } else {
      open.data = std::move(body);
      body = std::string();
    }
    ready.push_back(std::move(open));
    open = Chunk{};
    chunk_uniform = true;
  }

  void WriteReady() {
    auto s = store->Prepare(
        "INSERT INTO gt_chunks(stream_id, seq, first_sample, samples, t_first, t_last, data)"
        " VALUES(?,?,?,?,?,?,?)");
    for (const auto& c : ready) {
      s->Bind(1, stream_id)
          .Bind(2, next_seq++)
          .Bind(3, c.first_sample)
          .Bind(4, static_cast<std::int64_t>(c.samples))
          .Bind(5, c.t_first)
          .Bind(6, c.t_last)
          .BindBlob(7, c.data.data(), c.data.size());
      s->Run();
      s->Reset();
    }
    ready.clear();
    buffered = 0;
  }

  void Flush() {
    CloseChunk();
    if (ready.empty()) return;
    Tx tx(store->db, true);
    WriteReady();
    tx.Commit();
  }
};

Ingest::Ingest(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Ingest::~Ingest() = default;

std::int64_t Ingest::samples() const { return impl_->total; }

void Ingest::Add(const Sample& s) {
  auto& m = *impl_;
  if (m.finished)
    throw StoreError(StoreError::Kind::kBadInput, "Ingest::Add: the stream is finished");
  const std::string bad = CheckSample(s);
  if (!bad.empty()) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "Ingest::Add: trial " + std::to_string(m.trial_id) + " sample " +
                         std::to_string(m.total) + ": " + bad + "; sample refused");
  }
  if (s.t < m.last_t) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "Ingest::Add: trial " + std::to_string(m.trial_id) + " sample " +
                         std::to_string(m.total) + ": t = " + std::to_string(s.t) +
                         " s is before the previous sample's " + std::to_string(m.last_t) +
                         " s (out of order); sample refused");
  }
  if (m.total == 0) {
    m.first_pose = s.object_pose;
    m.measured_start = s.observed_valid ? s.observed_object_pose : s.object_pose;
  }
  m.outcome->Add(s);
  m.last_pose = s.object_pose;
  m.last_t = s.t;
  for (std::size_t c = 0; c < s.contacts.size(); ++c) {
    const double f = Norm3(s.contacts[c].force);
    m.max_contact_force = std::max(m.max_contact_force, f);
    if (m.has_pusher && c + 1 == s.contacts.size())
      m.max_pusher_force = std::max(m.max_pusher_force, f);
    ++m.modes[static_cast<int>(s.contacts[c].mode)];
  }
  if (s.observed_valid) {
    ++m.observed;
    double sq = 0;
    for (int i = 0; i < 3; ++i) {
      const double d = s.observed_object_pose[i] - s.object_pose[i];
      sq += d * d;
    }
    m.obs_sq_sum += sq;
    m.obs_max = std::max(m.obs_max, std::sqrt(sq));
  }
  if (m.open.samples == 0) {
    // The block header goes first; its count is patched when the chunk closes.
    m.body.reserve(8 + static_cast<std::size_t>(m.options.samples_per_chunk) * 600);
    EncodeBlockHeader(0, &m.body);
    m.open.first_sample = m.total;
    m.open.t_first = s.t;
    m.chunk_contacts = static_cast<int>(s.contacts.size());
    m.chunk_finger_values = static_cast<int>(s.observed_finger_wrenches.size());
  } else if (static_cast<int>(s.contacts.size()) != m.chunk_contacts ||
             static_cast<int>(s.observed_finger_wrenches.size()) != m.chunk_finger_values) {
    m.chunk_uniform = false;
    if (m.buffered == 0) m.oldest = std::chrono::steady_clock::now();
  }
  EncodeSampleBody(s, &m.body);
  m.open.t_last = s.t;
  ++m.open.samples;
  ++m.buffered;
  ++m.total;
  if (static_cast<int>(m.open.samples) >= m.options.samples_per_chunk) m.CloseChunk();
  if (m.buffered >= m.options.samples_per_commit) m.Flush();
}

void Ingest::Add(const std::vector<Sample>& samples) {
  for (const auto& s : samples) Add(s);
}

void Ingest::Poll() {
  auto& m = *impl_;
  if (m.buffered == 0) return;
  const double age =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - m.oldest).count();
  if (age >= m.options.max_commit_interval_s) m.Flush();
}

void Ingest::Flush() { impl_->Flush(); }

std::int64_t Ingest::Finish(TrialEnd outcome) { return Finish(outcome, FinishAlso{}); }

std::int64_t Ingest::Finish(TrialEnd outcome, const FinishAlso& also) {
  auto& m = *impl_;
  if (m.finished) throw StoreError(StoreError::Kind::kBadInput, "Ingest::Finish: already finished");
  if (outcome == TrialEnd::kNone)
    throw StoreError(StoreError::Kind::kBadInput, "Ingest::Finish: outcome is not set");
  m.CloseChunk();
  Tx tx(m.store->db, true);
  const auto row = CheckIngestable(*m.store, m.trial_id, m.attempt, "Ingest::Finish");
  if (also.execution)
    internal::WriteExecution(*m.store, m.trial_id, m.attempt, *also.execution, "Ingest::Finish");
  m.WriteReady();
  const double now = m.store->Now();
  {
    auto u = m.store->Prepare("UPDATE trials SET gt_stream_id = ? WHERE id = ?");
    u->Bind(1, m.stream_id).Bind(2, m.trial_id).Run();
  }
  if (m.total > 0) WriteMeasuredStart(*m.store, m.trial_id, m.measured_start);
  {  // Replace, never duplicate: drop every other stream of this (trial, attempt).
    auto d =
        m.store->Prepare("DELETE FROM gt_streams WHERE trial_id = ? AND attempt = ? AND id != ?");
    d->Bind(1, m.trial_id).Bind(2, m.attempt).Bind(3, m.stream_id).Run();
  }
  {
    auto u = m.store->Prepare(
        "UPDATE gt_streams SET complete = 1, samples = ?, completed_at = ? WHERE id = ?");
    u->Bind(1, m.total).Bind(2, now).Bind(3, m.stream_id).Run();
  }
  {
    auto s = m.store->Prepare(
        "INSERT INTO gt_summary(stream_id, trial_id, attempt, samples, observed_samples, "
        "duration_s,"
        " final_x, final_y, final_z, final_qw, final_qx, final_qy, final_qz, displacement_m,"
        " rotation_rad, max_contact_force_n, max_pusher_force_n, stick_fraction, slide_fraction,"
        " separate_fraction, observed_position_rmse_m, observed_position_max_error_m)"
        " VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
    detail::Binder b(*s);
    b << m.stream_id << m.trial_id << m.attempt << m.total << m.observed
      << (m.total > 0 ? m.last_t : 0.0);
    if (m.total > 0) {
      for (double v : m.last_pose) b << v;
      const double dx = m.last_pose[0] - m.first_pose[0], dy = m.last_pose[1] - m.first_pose[1],
                   dz = m.last_pose[2] - m.first_pose[2];
      b << std::sqrt(dx * dx + dy * dy + dz * dz)
        << QuatAngle(m.first_pose.data() + 3, m.last_pose.data() + 3);
    } else {
      for (int i = 0; i < 9; ++i) b << std::nullopt;
    }
    b << m.max_contact_force << m.max_pusher_force;
    const double contact_samples = static_cast<double>(m.modes[0] + m.modes[1] + m.modes[2]);
    for (int i = 0; i < 3; ++i) {
      if (contact_samples > 0)
        b << m.modes[i] / contact_samples;
      else
        b << std::nullopt;
    }
    if (m.observed > 0) {
      b << std::sqrt(m.obs_sq_sum / m.observed) << m.obs_max;
    } else {
      b << std::nullopt << std::nullopt;
    }
    s->Run();
  }
  internal::WriteOutcome(*m.store, m.stream_id, m.trial_id, m.attempt, m.outcome->Result());
  if (row.state == TrialState::kDispatched) {
    internal::WriteTransition(*m.store, m.trial_id, m.attempt, row.state, TrialState::kExecuted,
                              row.cell_id,
                              "ground truth complete (" + std::to_string(m.total) + " samples)",
                              "execute.ground_truth_complete", "Ingest::Finish");
    auto u = m.store->Prepare("UPDATE trials SET outcome = ?, executed_at = ? WHERE id = ?");
    u->Bind(1, ToString(outcome)).Bind(2, now).Bind(3, m.trial_id).Run();
  }
  if (!also.begin_reset_rule.empty())
    internal::WriteBeginReset(*m.store, m.trial_id, m.attempt, also.begin_reset_rule,
                              "Ingest::Finish");
  tx.Commit();
  m.finished = true;
  return m.total;
}

std::unique_ptr<Ingest> Store::BeginIngest(std::int64_t trial_id, int attempt,
                                           std::vector<ContactSite> sites,
                                           const IngestOptions& options) {
  impl_->RequireWritable("BeginIngest");
  if (options.samples_per_chunk < 1 ||
      options.samples_per_chunk > static_cast<int>(kMaxBlockSamples)) {
    throw StoreError(StoreError::Kind::kBadInput, "BeginIngest: samples_per_chunk must be in [1, " +
                                                      std::to_string(kMaxBlockSamples) + "]");
  }
  if (options.samples_per_commit < 1) {
    throw StoreError(StoreError::Kind::kBadInput, "BeginIngest: samples_per_commit must be >= 1");
  }
  if (!std::isfinite(options.max_commit_interval_s) || options.max_commit_interval_s < 0) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "BeginIngest: max_commit_interval_s must be finite and >= 0");
  }
  auto m = std::make_unique<Ingest::Impl>();
  m->store = impl_.get();
  m->trial_id = trial_id;
  m->attempt = attempt;
  m->options = options;
  Tx tx(impl_->db, true);
  const auto row = CheckIngestable(*impl_, trial_id, attempt, "BeginIngest");
  {
    auto p = impl_->Prepare("SELECT pusher_type IS NOT NULL FROM trials WHERE id = ?");
    p->Bind(1, trial_id);
    p->Step();
    m->has_pusher = p->Int(0) != 0;
    m->outcome = std::make_unique<OutcomeAccumulator>(std::move(sites));
  }
  auto s = impl_->Prepare(
      "INSERT INTO gt_streams(trial_id, attempt, cell_id, complete, samples, started_at) "
      "VALUES(?,?,?,0,0,?)");
  s->Bind(1, trial_id).Bind(2, attempt).Bind(3, row.cell_id).Bind(4, impl_->Now()).Run();
  m->stream_id = static_cast<std::int64_t>(sqlite3_last_insert_rowid(impl_->db));
  tx.Commit();
  return std::unique_ptr<Ingest>(new Ingest(std::move(m)));
}

std::vector<Sample> internal::ReadStreamSamples(const Store::Impl& impl, std::int64_t stream_id,
                                                std::int64_t expected, const char* function) {
  std::vector<Sample> out;
  out.reserve(static_cast<std::size_t>(expected));
  auto c = impl.Prepare("SELECT data FROM gt_chunks WHERE stream_id = ? ORDER BY seq");
  c->Bind(1, stream_id);
  while (c->Step()) {
    auto part = DecodeSamples(c->Blob(0), static_cast<std::size_t>(c->Bytes(0)));
    for (auto& s : part) out.push_back(std::move(s));
  }
  if (static_cast<std::int64_t>(out.size()) != expected) {
    throw StoreError(StoreError::Kind::kCorrupt,
                     std::string(function) + ": stream " + std::to_string(stream_id) + " has " +
                         std::to_string(out.size()) + " samples, expected " +
                         std::to_string(expected));
  }
  return out;
}

GroundTruth Store::ReadGroundTruth(std::int64_t trial_id) const {
  Tx tx(impl_->db, false);  // one snapshot: the stream cannot change under us
  auto t = impl_->Prepare(
      "SELECT t.gt_stream_id, g.attempt, g.cell_id, g.samples, IFNULL(t.truth, '') FROM trials t"
      " LEFT JOIN gt_streams g ON g.id = t.gt_stream_id WHERE t.id = ?");
  t->Bind(1, trial_id);
  if (!t->Step()) {
    throw StoreError(StoreError::Kind::kNotFound,
                     "ReadGroundTruth: no trial " + std::to_string(trial_id));
  }
  if (t->IsNull(0)) {
    throw StoreError(
        StoreError::Kind::kNotFound,
        "ReadGroundTruth: trial " + std::to_string(trial_id) + " has no ground truth yet");
  }
  GroundTruth gt;
  gt.trial_id = trial_id;
  const std::int64_t stream = t->Int(0);
  gt.attempt = static_cast<int>(t->Int(1));
  gt.cell_id = t->Text(2);
  const std::int64_t expected = t->Int(3);
  gt.truth = t->Text(4);
  gt.samples = internal::ReadStreamSamples(*impl_, stream, expected, "ReadGroundTruth");
  tx.Commit();
  return gt;
}

}  // namespace arena::db
