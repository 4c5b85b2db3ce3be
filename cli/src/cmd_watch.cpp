// arena watch TRIAL|--cell ID --domain D: a running trial as it happens,
// from the LiveState topic (one message per sample, issue 19), as a terminal
// readout. On a terminal one line is redrawn in place (at most 30 Hz);
// otherwise (a pipe, a log) 10 lines a second. Ends when the trial's last
// GroundTruth batch arrives (exit 0: the reliable log says for sure it is
// over), on Ctrl-C (130), or when nothing arrives for --timeout seconds (4).
//
// The watcher only reads (LiveState, GroundTruth); it never writes. Both are
// volatile: what was published before the watcher matched the cell is not
// replayed (the store has the whole trial: `arena plot`).
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Geometry>

#include "arena/schemas/arena.h"
#include "arena/schemas/dds.hpp"
#include "arena/schemas/ground_truth.hpp"
#include "arena/schemas/security.hpp"
#include "commands.hpp"
#include "dds_options.hpp"
#include "signals.hpp"

namespace arena::cli {
namespace {

constexpr std::chrono::milliseconds Millis0() { return std::chrono::milliseconds(0); }

struct WatchOptions {
  std::int64_t trial = -1;
  std::string cell;
  DdsCliOptions dds;
  double timeout_s = 30;
};

std::string Readout(const msg::LiveState& live, std::uint64_t seen) {
  const auto& raw = live.state();
  dds::PusherState pusher;
  const mechanics::TrajectorySample s = dds::DecodeSample(raw, &pusher);
  const double angle = Eigen::AngleAxisd(s.orientation).angle() * 180.0 / M_PI;
  char buf[512];
  int n = std::snprintf(buf, sizeof buf,
                        "trial %llu #%u on %s  t=%6.3f s  object [mm] x=%+8.3f y=%+8.3f z=%+8.3f  "
                        "rot=%6.2f deg  Fn [N]",
                        static_cast<unsigned long long>(live.trial_id()), live.attempt(),
                        live.cell_id().c_str(), s.t, s.position.x() * 1e3, s.position.y() * 1e3,
                        s.position.z() * 1e3, angle);
  for (const auto& c : s.contacts) {
    if (n >= static_cast<int>(sizeof buf) - 16) break;
    n += std::snprintf(buf + n, sizeof buf - n, " %6.2f", c.normal_force);
  }
  if (live.closed_loop() && n < static_cast<int>(sizeof buf) - 64)
    n += std::snprintf(buf + n, sizeof buf - n, "  %s: pusher %.1f mm/s", live.controller().c_str(),
                       pusher.velocity.norm() * 1e3);
  if (n < static_cast<int>(sizeof buf) - 48)
    std::snprintf(buf + n, sizeof buf - n, "  sample %u (live %llu)", live.sample(),
                  static_cast<unsigned long long>(seen));
  return buf;
}

int RunWatch(const WatchOptions& o) {
  if ((o.trial >= 0) == !o.cell.empty())
    throw CommandError(kExitBadInput,
                       "give either a TRIAL id or --cell ID (see `arena watch --help`)");
  std::atomic<bool> stop{false};
  SignalWatcher signals([&stop](int) { stop = true; });  // before DDS starts its threads

  dds::ParticipantOptions po;
  po.domain_id = o.dds.domain;
  po.name = "arena.watch";
  po.network = o.dds.Network();
  // The live topic (one sample as it happens) for the readout; the
  // reliable log only to know, for sure, when the trial ended (a best-effort
  // live sample, the last one included, may be lost).
  std::unique_ptr<dds::Participant> participant;
  std::unique_ptr<dds::Reader<msg::LiveState>> live;
  std::unique_ptr<dds::Reader<msg::GroundTruth>> log;
  // With --cell: the cell's statuses (a FAILED phase) and its liveliness (a
  // dead cell) end the watch within about a second, saying what happened.
  std::unique_ptr<dds::Reader<msg::TrialStatus>> statuses;
  try {
    participant = std::make_unique<dds::Participant>(po);
    live = std::make_unique<dds::Reader<msg::LiveState>>(*participant, dds::ReaderOptions{false});
    log = std::make_unique<dds::Reader<msg::GroundTruth>>(*participant, dds::ReaderOptions{false});
    if (!o.cell.empty())
      statuses =
          std::make_unique<dds::Reader<msg::TrialStatus>>(*participant, dds::ReaderOptions{true});
  } catch (const dds::SecurityError&) {
    throw;  // the identity is the user's input (main maps it)
  } catch (const dds::DdsError& e) {
    throw CommandError(e.exit_code(), std::string("cannot join DDS domain ") +
                                          std::to_string(o.dds.domain) + ": " + e.what());
  }
  const bool tty = isatty(STDOUT_FILENO) == 1;
  const std::string what = o.trial >= 0 ? "trial " + std::to_string(o.trial) : "cell " + o.cell;
  std::fprintf(stderr, "watching %s on DDS domain %d (Ctrl-C to stop)\n", what.c_str(),
               o.dds.domain);

  using Clock = std::chrono::steady_clock;
  const auto timeout =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.timeout_s));
  // A terminal is redrawn at most 30 times a second, a pipe gets 10 lines a second.
  const auto redraw = std::chrono::milliseconds(tty ? 33 : 100);
  auto last_arrival = Clock::now();
  auto last_print = Clock::time_point{};
  std::int64_t trial = o.trial;  // with --cell: the first trial seen on that cell
  std::uint32_t attempt = 0;
  std::uint64_t seen = 0, logged = 0;
  std::optional<msg::LiveState> pending;  // newest sample not yet shown
  auto mine = [&](const std::string& cell, std::uint64_t t) {
    if (!o.cell.empty() && cell != o.cell) return false;
    if (trial < 0) trial = static_cast<std::int64_t>(t);
    return t == static_cast<std::uint64_t>(trial);
  };
  auto show = [&](const msg::LiveState& m) {
    const std::string line = Readout(m, seen);
    if (tty)
      std::printf("\r\033[K%s", line.c_str());
    else
      std::printf("%s\n", line.c_str());
    std::fflush(stdout);
    last_print = Clock::now();
  };
  const std::string cell_participant = o.cell.empty() ? "" : dds::CellParticipantName(o.cell);
  while (!stop) {
    if (statuses) {
      for (const auto& st : statuses->TakeAll()) {
        if (st.cell_id() != o.cell) continue;
        if (st.state() != msg::STATE_FAILED && st.state() != msg::STATE_REFUSED) continue;
        if (trial >= 0 && st.trial_id() != static_cast<std::uint64_t>(trial)) continue;
        if (tty && seen > 0) std::fputc('\n', stdout);
        std::fflush(stdout);
        throw CommandError(kExitFailure,
                           "cell " + o.cell + ": trial " + std::to_string(st.trial_id()) +
                               " attempt " + std::to_string(st.attempt()) + " " +
                               (st.phase() == msg::PHASE_RESET ? "RESET" : "EXECUTE") + " " +
                               (st.state() == msg::STATE_REFUSED ? "refused" : "failed") + ": " +
                               st.reason());
      }
      while (auto e = participant->NextPeerEvent(std::chrono::milliseconds(0))) {
        using Kind = dds::PeerEvent::Kind;
        if (e->participant != cell_participant ||
            (e->kind != Kind::kParticipantLeft && e->kind != Kind::kWriterLost))
          continue;
        int still = 0;  // a restarted cell's new process keeps the id alive
        for (const auto& p : participant->Peers()) still += p == cell_participant;
        if (e->kind == Kind::kWriterLost) --still;
        if (still > 0) continue;
        if (tty && seen > 0) std::fputc('\n', stdout);
        std::fflush(stdout);
        throw CommandError(kExitCommunication,
                           "cell " + o.cell + " disappeared (" + dds::ToString(e->kind) + ")" +
                               (trial >= 0 ? " during trial " + std::to_string(trial) + " after " +
                                                 std::to_string(seen) + " live samples"
                                           : std::string()) +
                               "; see `arena status`");
      }
    }
    bool arrived = false;
    for (auto m = live->Take(std::chrono::milliseconds(20)); m; m = live->Take(Millis0())) {
      if (!mine(m->cell_id(), m->trial_id())) continue;
      arrived = true;
      if (m->attempt() != attempt) {  // a new attempt restarts the trial
        if (attempt != 0)
          std::fprintf(stderr, "%strial %lld: attempt %u started\n", tty ? "\n" : "",
                       static_cast<long long>(trial), m->attempt());
        attempt = m->attempt();
        seen = logged = 0;
      }
      ++seen;
      pending = std::move(*m);
    }
    if (pending && Clock::now() - last_print >= redraw) {
      show(*pending);
      pending.reset();
    }
    bool complete = false;
    for (auto b = log->Take(Millis0()); b; b = log->Take(Millis0())) {
      if (!mine(b->cell_id(), b->trial_id()) || (attempt != 0 && b->attempt() != attempt)) continue;
      arrived = true;
      logged += b->samples().size();
      complete = complete || b->last();
    }
    if (arrived) last_arrival = Clock::now();
    if (complete) {
      if (pending) show(*pending);
      if (tty && seen > 0) std::fputc('\n', stdout);
      std::printf("trial %lld attempt %u: complete, %llu samples logged (%llu seen live)\n",
                  static_cast<long long>(trial), attempt, static_cast<unsigned long long>(logged),
                  static_cast<unsigned long long>(seen));
      return kExitOk;
    }
    if (Clock::now() - last_arrival > timeout) {
      if (tty && seen > 0) std::fputc('\n', stdout);
      std::fflush(stdout);
      if (seen == 0 && logged == 0)
        throw CommandError(
            kExitCommunication,
            "no ground truth for " + what + " on DDS domain " + std::to_string(o.dds.domain) +
                " within " + std::to_string(static_cast<int>(o.timeout_s)) +
                " s: is it running (`arena status`), and is --domain the one `arena serve` uses? "
                "(a trial that already ended is in the store: `arena plot`)");
      throw CommandError(kExitCommunication, what + ": the trial stopped after " +
                                                 std::to_string(seen) +
                                                 " live samples (nothing for " +
                                                 std::to_string(static_cast<int>(o.timeout_s)) +
                                                 " s): did the cell die? see `arena status`");
    }
  }
  if (tty) std::fputc('\n', stdout);
  std::fprintf(stderr, "interrupted\n");
  return kExitInterrupted;
}

}  // namespace

void AddWatchCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<WatchOptions>();
  auto* cmd = app.add_subcommand(
      "watch", "A running trial as it happens (live state over DDS), as a terminal readout");
  cmd->add_option("trial", o->trial, "Trial id (see `arena status` / `arena query`)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--cell", o->cell, "Instead of a trial: the next trial streamed by this cell");
  AddDdsOptions(cmd, &o->dds,
                "a 'watcher' (or 'service') identity directory from `arena certs issue`");
  cmd->add_option("--timeout", o->timeout_s, "Give up after this many seconds without a sample")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->footer(
      "Examples:\n"
      "  arena watch 12 --domain 42\n"
      "  arena watch --cell sim-1 --domain 42 --timeout 60\n"
      "  arena watch --cell c1 --domain 42 --security lab-pki/alice   (a watcher identity: reads, "
      "never commands)\n"
      "Shows the object's position, rotation and each contact's normal force (fingers, then the "
      "pusher)\n"
      "sample by sample (and, closed loop, the commanded pusher speed); exits 0 when the trial's\n"
      "last batch arrives, 4 when nothing arrives.\n");
  cmd->callback([o, action] { *action = [o] { return RunWatch(*o); }; });
}

}  // namespace arena::cli
