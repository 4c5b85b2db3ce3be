#include "command_intake.hpp"
#include "clock.hpp"

#include <algorithm>
#include <cmath>

#include <spdlog/spdlog.h>

namespace arena::executors {
namespace {

using internal::Seconds;

}  // namespace

CommandIntake::Taken CommandIntake::Take(const msg::TrialCommand& c, Clock::time_point now,
                                         const std::string& cell_id) {
  const std::uint64_t session = c.service_session();
  if (retired_.count(session)) {
    spdlog::info(
        "cell {}: dropped a {} command of trial {} from service session {:016x}, which "
        "this cell no longer serves",
        cell_id, c.phase() == msg::PHASE_CLAIM ? "claim" : "phase", c.trial_id(), session);
    return {};
  }
  const bool free = serving_.session == 0 || now > serving_.until;
  const bool mine = serving_.session == session;
  // The same store's new service: the old one is dead (one service per store).
  const bool successor =
      !free && !mine && !serving_.store.empty() && serving_.store == c.service_store();
  Taken taken;
  if (c.phase() == msg::PHASE_CLAIM) {
    if (!std::isfinite(c.lease_s()) || c.lease_s() < 0) return taken;
    if (c.lease_s() == 0) {  // release
      if (mine) {
        Retire(session);
        serving_ = Serving{};
        taken.announce = true;
      }
      return taken;
    }
    if (free || mine || successor)
      taken.announce = Serve(c, std::min(c.lease_s(), kMaxLease_s), now, cell_id);
    return taken;
  }
  if (!mine) {
    if (!free) {
      spdlog::info(
          "cell {}: dropped trial {}'s command from service session {:016x}: serving "
          "{:016x}",
          cell_id, c.trial_id(), session, serving_.session);
      return taken;
    }
    taken.announce = Serve(c, kImplicitLease_s, now, cell_id);
  } else if (now + Seconds(serving_.lease_s) > serving_.until) {
    serving_.until = now + Seconds(serving_.lease_s);  // a command renews the lease
  }
  queue_.push_back(c);
  taken.queued = true;
  return taken;
}

bool CommandIntake::Expire(Clock::time_point now, const std::string& cell_id) {
  if (serving_.session == 0 || now <= serving_.until) return false;
  spdlog::info("cell {}: the lease of service session {:016x} ran out; free", cell_id,
               serving_.session);
  serving_.session = 0;
  serving_.host.clear();
  serving_.pid = 0;
  serving_.lease_s = 0;
  return true;
}

std::optional<msg::TrialCommand> CommandIntake::Pop() {
  if (queue_.empty()) return std::nullopt;
  msg::TrialCommand c = std::move(queue_.front());
  queue_.pop_front();
  return c;
}

void CommandIntake::Retire(std::uint64_t session) {
  if (session == 0 || !retired_.insert(session).second) return;
  retired_order_.push_back(session);
  while (retired_order_.size() > kRetiredKept) {
    retired_.erase(retired_order_.front());
    retired_order_.pop_front();
  }
}

bool CommandIntake::Serve(const msg::TrialCommand& c, double lease_s, Clock::time_point now,
                          const std::string& cell_id) {
  const bool changed = serving_.session != c.service_session();
  if (changed) {
    Retire(serving_.session);
    const auto dropped = std::erase_if(queue_, [&](const msg::TrialCommand& q) {
      return q.service_session() != c.service_session();
    });
    if (dropped > 0)
      spdlog::info(
          "cell {}: dropped {} queued commands of service session {:016x}, which this "
          "cell no longer serves",
          cell_id, dropped, serving_.session);
    spdlog::info("cell {}: now serving service session {:016x} ({}, pid {})", cell_id,
                 c.service_session(), c.service_host().empty() ? "?" : c.service_host(),
                 c.service_pid());
  }
  serving_.session = c.service_session();
  if (!c.service_host().empty() || changed) {
    serving_.host = c.service_host();
    serving_.pid = c.service_pid();
    serving_.store = c.service_store();
  }
  const bool lease_changed = serving_.lease_s != lease_s;
  serving_.lease_s = lease_s;
  serving_.until = now + Seconds(lease_s);
  return changed || lease_changed;
}

void ResetGate::ResetEnded(const msg::TrialCommand& reset, bool done, const std::string& why) {
  last_is_reset_ = true;
  done_ = done;
  session_ = reset.service_session();
  trial_id_ = reset.trial_id();
  attempt_ = reset.attempt();
  why_ = why;
}

std::string ResetGate::Check(const msg::TrialCommand& execute) const {
  if (execute.after_reset_trial_id() == 0)
    return execute.after_reset_attempt() == 0
               ? ""
               : "after_reset_attempt: set to " + std::to_string(execute.after_reset_attempt()) +
                     " without after_reset_trial_id (0 = not sent behind a reset)";
  const std::string which = "the RESET after trial " +
                            std::to_string(execute.after_reset_trial_id()) + " attempt " +
                            std::to_string(execute.after_reset_attempt());
  if (!last_is_reset_ || session_ != execute.service_session() ||
      trial_id_ != execute.after_reset_trial_id() || attempt_ != execute.after_reset_attempt())
    return "after_reset_trial_id: sent to run right after " + which +
           ", which is not what this cell ran last";
  if (!done_)
    return "after_reset_trial_id: " + which + " did not end done (" +
           (why_.empty() ? std::string("no reason given") : why_) +
           "); a trial never starts from a failed reset";
  return "";
}

}  // namespace arena::executors
