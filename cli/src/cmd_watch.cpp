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

using Clock = std::chrono::steady_clock;

// One watch: the DDS readers and what has been seen of the trial so far.
class Watcher {
 public:
  explicit Watcher(const WatchOptions& o)
      : o_(o),
        tty_(isatty(STDOUT_FILENO) == 1),
        what_(o.trial >= 0 ? "trial " + std::to_string(o.trial) : "cell " + o.cell),
        cell_participant_(o.cell.empty() ? "" : dds::CellParticipantName(o.cell)),
        trial_(o.trial) {
    Join();
  }

  const std::string& what() const { return what_; }

  // With --cell: a FAILED or REFUSED phase, or the cell's disappearance,
  // ends the watch (a typed error saying what happened).
  void CheckCell() {
    if (!statuses_) return;
    for (const auto& st : statuses_->TakeAll()) {
      if (st.cell_id() != o_.cell) continue;
      if (st.state() != msg::STATE_FAILED && st.state() != msg::STATE_REFUSED) continue;
      if (trial_ >= 0 && st.trial_id() != static_cast<std::uint64_t>(trial_)) continue;
      EndLine();
      throw CommandError(kExitFailure,
                         "cell " + o_.cell + ": trial " + std::to_string(st.trial_id()) +
                             " attempt " + std::to_string(st.attempt()) + " " +
                             (st.phase() == msg::PHASE_RESET ? "RESET" : "EXECUTE") + " " +
                             (st.state() == msg::STATE_REFUSED ? "refused" : "failed") + ": " +
                             st.reason());
    }
    while (auto e = participant_->NextPeerEvent(std::chrono::milliseconds(0))) {
      using Kind = dds::PeerEvent::Kind;
      if (e->participant != cell_participant_ ||
          (e->kind != Kind::kParticipantLeft && e->kind != Kind::kWriterLost))
        continue;
      int still = 0;  // a restarted cell's new process keeps the id alive
      for (const auto& p : participant_->Peers()) still += p == cell_participant_;
      if (e->kind == Kind::kWriterLost) --still;
      if (still > 0) continue;
      EndLine();
      throw CommandError(kExitCommunication,
                         "cell " + o_.cell + " disappeared (" + dds::ToString(e->kind) + ")" +
                             (trial_ >= 0 ? " during trial " + std::to_string(trial_) + " after " +
                                                std::to_string(seen_) + " live samples"
                                          : std::string()) +
                             "; see `arena status`");
    }
  }

  // Takes the live samples (waiting up to 20 ms for the first) and shows the
  // newest at the redraw rate. @returns whether any of the trial's arrived.
  bool TakeLive() {
    bool arrived = false;
    for (auto m = live_->Take(std::chrono::milliseconds(20)); m; m = live_->Take(Millis0())) {
      if (!Mine(m->cell_id(), m->trial_id())) continue;
      arrived = true;
      if (m->attempt() != attempt_) {  // a new attempt restarts the trial
        if (attempt_ != 0)
          std::fprintf(stderr, "%strial %lld: attempt %u started\n", tty_ ? "\n" : "",
                       static_cast<long long>(trial_), m->attempt());
        attempt_ = m->attempt();
        seen_ = logged_ = 0;
      }
      ++seen_;
      pending_ = std::move(*m);
    }
    // A terminal is redrawn at most 30 times a second, a pipe gets 10 lines a second.
    const auto redraw = std::chrono::milliseconds(tty_ ? 33 : 100);
    if (pending_ && Clock::now() - last_print_ >= redraw) {
      Show(*pending_);
      pending_.reset();
    }
    return arrived;
  }

  // Takes the reliable log's batches. @returns whether any of the trial's
  // arrived; *complete when its last one did.
  bool TakeLog(bool* complete) {
    bool arrived = false;
    for (auto b = log_->Take(Millis0()); b; b = log_->Take(Millis0())) {
      if (!Mine(b->cell_id(), b->trial_id()) || (attempt_ != 0 && b->attempt() != attempt_))
        continue;
      arrived = true;
      logged_ += b->samples().size();
      *complete = *complete || b->last();
    }
    return arrived;
  }

  int Complete() {
    if (pending_) Show(*pending_);
    if (tty_ && seen_ > 0) std::fputc('\n', stdout);
    std::printf("trial %lld attempt %u: complete, %llu samples logged (%llu seen live)\n",
                static_cast<long long>(trial_), attempt_, static_cast<unsigned long long>(logged_),
                static_cast<unsigned long long>(seen_));
    return kExitOk;
  }

  [[noreturn]] void TimedOut() {
    EndLine();
    const std::string wait = std::to_string(static_cast<int>(o_.timeout_s)) + " s";
    if (seen_ == 0 && logged_ == 0)
      throw CommandError(
          kExitCommunication,
          "no ground truth for " + what_ + " on DDS domain " + std::to_string(o_.dds.domain) +
              " within " + wait +
              ": is it running (`arena status`), and is --domain the one `arena serve` uses? "
              "(a trial that already ended is in the store: `arena plot`)");
    throw CommandError(kExitCommunication, what_ + ": the trial stopped after " +
                                               std::to_string(seen_) +
                                               " live samples (nothing for " + wait +
                                               "): did the cell die? see `arena status`");
  }

  int Interrupted() const {
    if (tty_) std::fputc('\n', stdout);
    std::fprintf(stderr, "interrupted\n");
    return kExitInterrupted;
  }

 private:
  // The live topic (one sample as it happens) for the readout; the reliable
  // log only to know, for sure, when the trial ended (a best-effort live
  // sample, the last one included, may be lost). With --cell: the cell's
  // statuses (a FAILED phase) and its liveliness (a dead cell) end the watch
  // within about a second, saying what happened.
  void Join() {
    dds::ParticipantOptions po;
    po.domain_id = o_.dds.domain;
    po.name = "arena.watch";
    po.network = o_.dds.Network();
    try {
      participant_ = std::make_unique<dds::Participant>(po);
      live_ =
          std::make_unique<dds::Reader<msg::LiveState>>(*participant_, dds::ReaderOptions{false});
      log_ =
          std::make_unique<dds::Reader<msg::GroundTruth>>(*participant_, dds::ReaderOptions{false});
      if (!o_.cell.empty())
        statuses_ = std::make_unique<dds::Reader<msg::TrialStatus>>(*participant_,
                                                                    dds::ReaderOptions{true});
    } catch (const dds::SecurityError&) {
      throw;  // the identity is the user's input (main maps it)
    } catch (const dds::DdsError& e) {
      throw CommandError(e.exit_code(), std::string("cannot join DDS domain ") +
                                            std::to_string(o_.dds.domain) + ": " + e.what());
    }
  }

  // With --cell: the first trial seen on that cell is the one watched.
  bool Mine(const std::string& cell, std::uint64_t t) {
    if (!o_.cell.empty() && cell != o_.cell) return false;
    if (trial_ < 0) trial_ = static_cast<std::int64_t>(t);
    return t == static_cast<std::uint64_t>(trial_);
  }

  void Show(const msg::LiveState& m) {
    const std::string line = Readout(m, seen_);
    if (tty_)
      std::printf("\r\033[K%s", line.c_str());
    else
      std::printf("%s\n", line.c_str());
    std::fflush(stdout);
    last_print_ = Clock::now();
  }

  // Ends a redrawn line before a message that stops the watch.
  void EndLine() const {
    if (tty_ && seen_ > 0) std::fputc('\n', stdout);
    std::fflush(stdout);
  }

  const WatchOptions& o_;
  const bool tty_;
  const std::string what_;
  const std::string cell_participant_;
  std::unique_ptr<dds::Participant> participant_;
  std::unique_ptr<dds::Reader<msg::LiveState>> live_;
  std::unique_ptr<dds::Reader<msg::GroundTruth>> log_;
  std::unique_ptr<dds::Reader<msg::TrialStatus>> statuses_;
  std::int64_t trial_;  // with --cell: the first trial seen on that cell
  std::uint32_t attempt_ = 0;
  std::uint64_t seen_ = 0, logged_ = 0;
  std::optional<msg::LiveState> pending_;  // newest sample not yet shown
  Clock::time_point last_print_{};
};

int RunWatch(const WatchOptions& o) {
  if ((o.trial >= 0) == !o.cell.empty())
    throw CommandError(kExitBadInput,
                       "give either a TRIAL id or --cell ID (see `arena watch --help`)");
  std::atomic<bool> stop{false};
  SignalWatcher signals([&stop](int) { stop = true; });  // before DDS starts its threads
  Watcher watcher(o);
  std::fprintf(stderr, "watching %s on DDS domain %d (Ctrl-C to stop)\n", watcher.what().c_str(),
               o.dds.domain);
  const auto timeout =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.timeout_s));
  auto last_arrival = Clock::now();
  while (!stop) {
    watcher.CheckCell();
    bool complete = false;
    const bool live = watcher.TakeLive();
    const bool logged = watcher.TakeLog(&complete);
    if (live || logged) last_arrival = Clock::now();
    if (complete) return watcher.Complete();
    if (Clock::now() - last_arrival > timeout) watcher.TimedOut();
  }
  return watcher.Interrupted();
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
