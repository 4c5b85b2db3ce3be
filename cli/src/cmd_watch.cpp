// arena watch TRIAL|--cell ID --domain D: a running trial's ground truth,
// live over DDS, as a terminal readout. On a terminal one line is refreshed
// in place; otherwise (a pipe, a log) one line per batch. Ends when the
// trial's last batch arrives (exit 0), on Ctrl-C (130), or when nothing
// arrives for --timeout seconds (4, with what to check).
//
// The watcher only reads the GroundTruth topic; it never writes. Ground truth
// is volatile: batches published before the watcher matched the cell are not
// replayed (the store has the whole trial: `arena plot`).
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include <Eigen/Geometry>

#include "arena/schemas/arena.h"
#include "arena/schemas/dds.hpp"
#include "arena/schemas/ground_truth.hpp"
#include "arena/schemas/security.hpp"
#include "commands.hpp"
#include "signals.hpp"

namespace arena::cli {
namespace {

struct WatchOptions {
  std::int64_t trial = -1;
  std::string cell;
  int domain = -1;
  std::string peers;
  std::string discovery_server;
  std::string security_dir;
  double timeout_s = 30;
};

std::string Readout(const msg::GroundTruth& batch, std::uint64_t samples, std::uint64_t observed) {
  const auto& raw = batch.samples().back();
  const mechanics::TrajectorySample s = dds::DecodeSample(raw);
  const double angle = Eigen::AngleAxisd(s.orientation).angle() * 180.0 / M_PI;
  char buf[512];
  int n = std::snprintf(buf, sizeof buf,
                        "trial %llu #%u on %s  t=%6.3f s  object [mm] x=%+8.3f y=%+8.3f z=%+8.3f  "
                        "rot=%6.2f deg  Fn [N]",
                        static_cast<unsigned long long>(batch.trial_id()), batch.attempt(),
                        batch.cell_id().c_str(), s.t, s.position.x() * 1e3, s.position.y() * 1e3,
                        s.position.z() * 1e3, angle);
  for (const auto& c : s.contacts) {
    if (n >= static_cast<int>(sizeof buf) - 16) break;
    n += std::snprintf(buf + n, sizeof buf - n, " %6.2f", c.normal_force);
  }
  if (n < static_cast<int>(sizeof buf) - 48)
    std::snprintf(buf + n, sizeof buf - n, "  samples %llu (observed %llu)",
                  static_cast<unsigned long long>(samples),
                  static_cast<unsigned long long>(observed));
  return buf;
}

int RunWatch(const WatchOptions& o) {
  if ((o.trial >= 0) == !o.cell.empty())
    throw CommandError(kExitBadInput,
                       "give either a TRIAL id or --cell ID (see `arena watch --help`)");
  std::atomic<bool> stop{false};
  SignalWatcher signals([&stop](int) { stop = true; });  // before DDS starts its threads

  dds::ParticipantOptions po;
  po.domain_id = o.domain;
  po.name = "arena.watch";
  try {
    if (!o.peers.empty()) po.network.peers = dds::ParsePeers(o.peers);
    po.network.discovery_server = o.discovery_server;
    po.network.security_dir = o.security_dir;
  } catch (const dds::DdsError& e) {
    throw CommandError(kExitBadInput, e.what());
  }
  std::unique_ptr<dds::Participant> participant;
  std::unique_ptr<dds::Reader<msg::GroundTruth>> reader;
  // With --cell: the cell's statuses (a FAILED phase) and its liveliness (a
  // dead cell) end the watch within about a second, saying what happened.
  std::unique_ptr<dds::Reader<msg::TrialStatus>> statuses;
  try {
    participant = std::make_unique<dds::Participant>(po);
    reader =
        std::make_unique<dds::Reader<msg::GroundTruth>>(*participant, dds::ReaderOptions{false});
    if (!o.cell.empty())
      statuses =
          std::make_unique<dds::Reader<msg::TrialStatus>>(*participant, dds::ReaderOptions{true});
  } catch (const dds::SecurityError& e) {
    throw CommandError(kExitBadInput, e.what());
  } catch (const dds::DdsError& e) {
    throw CommandError(kExitCommunication, std::string("cannot join DDS domain ") +
                                               std::to_string(o.domain) + ": " + e.what());
  }
  const bool tty = isatty(STDOUT_FILENO) == 1;
  const std::string what = o.trial >= 0 ? "trial " + std::to_string(o.trial) : "cell " + o.cell;
  std::fprintf(stderr, "watching %s on DDS domain %d (Ctrl-C to stop)\n", what.c_str(), o.domain);

  using Clock = std::chrono::steady_clock;
  const auto timeout =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.timeout_s));
  auto last_arrival = Clock::now();
  std::int64_t trial = o.trial;  // with --cell: the first trial seen on that cell
  std::uint32_t attempt = 0;
  std::uint64_t samples = 0, observed = 0;
  std::uint32_t next_sample = 0;
  const std::string cell_participant = o.cell.empty() ? "" : dds::CellParticipantName(o.cell);
  while (!stop) {
    if (statuses) {
      for (const auto& st : statuses->TakeAll()) {
        if (st.cell_id() != o.cell) continue;
        if (st.state() != msg::STATE_FAILED && st.state() != msg::STATE_REFUSED) continue;
        if (trial >= 0 && st.trial_id() != static_cast<std::uint64_t>(trial)) continue;
        if (tty && samples > 0) std::fputc('\n', stdout);
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
        if (tty && samples > 0) std::fputc('\n', stdout);
        std::fflush(stdout);
        throw CommandError(kExitCommunication,
                           "cell " + o.cell + " disappeared (" + dds::ToString(e->kind) + ")" +
                               (trial >= 0 ? " during trial " + std::to_string(trial) + " after " +
                                                 std::to_string(samples) + " samples"
                                           : std::string()) +
                               "; see `arena status`");
      }
    }
    auto batch = reader->Take(std::chrono::milliseconds(statuses ? 50 : 200));
    if (!batch) {
      if (Clock::now() - last_arrival > timeout) {
        if (tty && samples > 0) std::fputc('\n', stdout);
        std::fflush(stdout);
        if (samples == 0)
          throw CommandError(
              kExitCommunication,
              "no ground truth for " + what + " on DDS domain " + std::to_string(o.domain) +
                  " within " + std::to_string(static_cast<int>(o.timeout_s)) +
                  " s: is it running (`arena status`), and is --domain the one `arena serve` uses? "
                  "(a trial that already ended is in the store: `arena plot`)");
        throw CommandError(kExitCommunication, what + ": the stream stopped after " +
                                                   std::to_string(samples) +
                                                   " samples (no batch for " +
                                                   std::to_string(static_cast<int>(o.timeout_s)) +
                                                   " s): did the cell die? see `arena status`");
      }
      continue;
    }
    if (trial < 0 && batch->cell_id() == o.cell)
      trial = static_cast<std::int64_t>(batch->trial_id());
    if (trial < 0 || batch->trial_id() != static_cast<std::uint64_t>(trial)) continue;
    if (!o.cell.empty() && batch->cell_id() != o.cell) continue;
    if (batch->attempt() != attempt) {  // a new attempt restarts the stream
      if (attempt != 0)
        std::fprintf(stderr, "%strial %lld: attempt %u started\n", tty ? "\n" : "",
                     static_cast<long long>(trial), batch->attempt());
      attempt = batch->attempt();
      samples = observed = 0;
      next_sample = batch->first_sample();
    }
    last_arrival = Clock::now();
    if (const std::string why = dds::CheckBatch(*batch, next_sample); !why.empty()) {
      std::fprintf(stderr, "%s%s: malformed batch %u: %s\n", tty ? "\n" : "", what.c_str(),
                   batch->batch(), why.c_str());
      next_sample = batch->first_sample() + static_cast<std::uint32_t>(batch->samples().size());
      continue;
    }
    next_sample += static_cast<std::uint32_t>(batch->samples().size());
    samples += batch->samples().size();
    for (const auto& s : batch->samples()) observed += s.observed_valid() ? 1 : 0;
    if (batch->samples().empty()) continue;
    const std::string line = Readout(*batch, samples, observed);
    if (tty)
      std::printf("\r\033[K%s", line.c_str());
    else
      std::printf("%s\n", line.c_str());
    std::fflush(stdout);
    if (batch->last()) {
      if (tty) std::fputc('\n', stdout);
      std::printf("trial %lld attempt %u: complete, %llu samples (%llu observed)\n",
                  static_cast<long long>(trial), attempt, static_cast<unsigned long long>(samples),
                  static_cast<unsigned long long>(observed));
      return kExitOk;
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
      "watch", "Live ground truth of a running trial over DDS, as a terminal readout");
  cmd->add_option("trial", o->trial, "Trial id (see `arena status` / `arena query`)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--cell", o->cell, "Instead of a trial: the next trial streamed by this cell");
  cmd->add_option("--domain", o->domain, "DDS domain id of the service and cells (0..231)")
      ->required()
      ->check(CLI::Range(0, dds::kMaxDomainId));
  cmd->add_option("--peers", o->peers, "Reach cells on other hosts: initial peers host[:port],...");
  cmd->add_option("--discovery-server", o->discovery_server,
                  "Client of a Fast DDS discovery server [id@]host:port");
  cmd->add_option(
      "--security", o->security_dir,
      "DDS-Security: a 'watcher' (or 'service') identity directory from `arena certs issue`");
  cmd->add_option("--timeout", o->timeout_s, "Give up after this many seconds without a batch")
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
      "as the cell streams them; exits 0 when the trial's last batch arrives, 4 when nothing "
      "arrives.\n");
  cmd->callback([o, action] { *action = [o] { return RunWatch(*o); }; });
}

}  // namespace arena::cli
