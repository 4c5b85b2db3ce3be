// Closed-loop runs and their applied pusher commands (issue 19; migration 9).
#include <cmath>
#include <string>

#include "arena/db/store.hpp"
#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db {

namespace {

void CheckFinite(double v, const std::string& field) {
  if (!std::isfinite(v))
    throw StoreError(StoreError::Kind::kBadInput, "RecordClosedLoop: " + field + ": not finite");
}

void CheckRun(const ClosedLoopRun& run) {
  if (run.controller.empty())
    throw StoreError(StoreError::Kind::kBadInput, "RecordClosedLoop: controller: empty");
  CheckFinite(run.target, "target");
  CheckFinite(run.gain, "gain");
  CheckFinite(run.tolerance, "tolerance");
  CheckFinite(run.hold_s, "hold_s");
  for (const auto* o : {&run.final_error, &run.settle_time_s, &run.loop_p50_ms, &run.loop_p99_ms})
    if (*o) CheckFinite(**o, "outcome");
  int previous = -1;
  for (const auto& c : run.commands) {
    const std::string at = "commands[sample " + std::to_string(c.sample) + "]";
    if (c.sample <= previous)
      throw StoreError(StoreError::Kind::kBadInput,
                       "RecordClosedLoop: " + at + ": samples must increase");
    previous = c.sample;
    CheckFinite(c.t, at + ".t");
    for (int k = 0; k < 3; ++k) {
      CheckFinite(c.commanded[k], at + ".commanded");
      CheckFinite(c.applied[k], at + ".applied");
    }
    if (c.loop_ms) CheckFinite(*c.loop_ms, at + ".loop_ms");
  }
}

}  // namespace

void Store::RecordClosedLoop(const ClosedLoopRun& run) {
  impl_->RequireWritable("RecordClosedLoop");
  CheckRun(run);
  detail::Tx tx(impl_->db, true);
  internal::LoadTrialRow(*impl_, run.trial_id, "RecordClosedLoop");
  {
    auto d = impl_->Prepare("DELETE FROM closed_loop_commands WHERE trial_id = ? AND attempt = ?");
    d->Bind(1, run.trial_id).Bind(2, run.attempt).Run();
    auto r = impl_->Prepare("DELETE FROM closed_loop_runs WHERE trial_id = ? AND attempt = ?");
    r->Bind(1, run.trial_id).Bind(2, run.attempt).Run();
  }
  auto s = impl_->Prepare(
      "INSERT INTO closed_loop_runs(trial_id, attempt, controller, lockstep, target, gain,"
      " tolerance, hold_s, reached, final_error, settle_time_s, held, loop_p50_ms, loop_p99_ms,"
      " failure, created_at) VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
  s->Bind(1, run.trial_id)
      .Bind(2, run.attempt)
      .Bind(3, run.controller)
      .Bind(4, run.lockstep ? 1 : 0)
      .Bind(5, run.target)
      .Bind(6, run.gain)
      .Bind(7, run.tolerance)
      .Bind(8, run.hold_s);
  if (run.reached)
    s->Bind(9, *run.reached ? 1 : 0);
  else
    s->BindNull(9);
  s->Bind(10, run.final_error)
      .Bind(11, run.settle_time_s)
      .Bind(12, run.held)
      .Bind(13, run.loop_p50_ms)
      .Bind(14, run.loop_p99_ms)
      .Bind(15, run.failure)
      .Bind(16, impl_->Now());
  s->Run();
  auto c = impl_->Prepare(
      "INSERT INTO closed_loop_commands(trial_id, attempt, sample, t, vx, vy, vz, applied_vx,"
      " applied_vy, applied_vz, loop_ms) VALUES(?,?,?,?,?,?,?,?,?,?,?)");
  for (const auto& cmd : run.commands) {
    c->Reset();
    c->Bind(1, run.trial_id)
        .Bind(2, run.attempt)
        .Bind(3, cmd.sample)
        .Bind(4, cmd.t)
        .Bind(5, cmd.commanded[0])
        .Bind(6, cmd.commanded[1])
        .Bind(7, cmd.commanded[2])
        .Bind(8, cmd.applied[0])
        .Bind(9, cmd.applied[1])
        .Bind(10, cmd.applied[2])
        .Bind(11, cmd.loop_ms);
    c->Run();
  }
  tx.Commit();
}

std::optional<ClosedLoopRun> Store::GetClosedLoop(std::int64_t trial_id) const {
  detail::Tx tx(impl_->db, false);
  auto s = impl_->Prepare(
      "SELECT attempt, controller, lockstep, target, gain, tolerance, hold_s, reached,"
      " final_error, settle_time_s, held, loop_p50_ms, loop_p99_ms, failure"
      " FROM closed_loop_runs WHERE trial_id = ? ORDER BY attempt DESC LIMIT 1");
  s->Bind(1, trial_id);
  if (!s->Step()) return std::nullopt;
  ClosedLoopRun run;
  run.trial_id = trial_id;
  run.attempt = static_cast<int>(s->Int(0));
  run.controller = s->Text(1);
  run.lockstep = s->Int(2) != 0;
  run.target = s->Real(3);
  run.gain = s->Real(4);
  run.tolerance = s->Real(5);
  run.hold_s = s->Real(6);
  if (!s->IsNull(7)) run.reached = s->Int(7) != 0;
  run.final_error = s->OptReal(8);
  run.settle_time_s = s->OptReal(9);
  run.held = static_cast<int>(s->Int(10));
  run.loop_p50_ms = s->OptReal(11);
  run.loop_p99_ms = s->OptReal(12);
  run.failure = s->Text(13);
  s->Reset();
  auto c = impl_->Prepare(
      "SELECT sample, t, vx, vy, vz, applied_vx, applied_vy, applied_vz, loop_ms"
      " FROM closed_loop_commands WHERE trial_id = ? AND attempt = ? ORDER BY sample");
  c->Bind(1, trial_id).Bind(2, run.attempt);
  while (c->Step()) {
    ClosedLoopCommand cmd;
    cmd.sample = static_cast<int>(c->Int(0));
    cmd.t = c->Real(1);
    for (int k = 0; k < 3; ++k) {
      cmd.commanded[k] = c->Real(2 + k);
      cmd.applied[k] = c->Real(5 + k);
    }
    cmd.loop_ms = c->OptReal(8);
    run.commands.push_back(cmd);
  }
  c->Reset();
  tx.Commit();
  return run;
}

}  // namespace arena::db
