// The one DDS set-up every arena process shares (Fast DDS 2.9).
//
// Definitions
//   participant  one Fast DDS DomainParticipant per process, named
//                "arena.<role>.<id>" (e.g. "arena.cell.c1", "arena.service");
//                the name is how peers recognise each other in discovery.
//   topic        one of CellAnnounce, TrialCommand, TrialStatus, GroundTruth,
//                LiveState, PusherCommand (schemas/arena.idl); one type per
//                topic, same name.
//
// QoS (docs/architecture.md, DDS topics) and why
//   CellAnnounce  reliable, transient-local, keep-last 1 per cell: a service
//                 that starts after the cell still learns of it.
//   TrialCommand  reliable, keep-all, volatile: a restarted cell gets no stale
//                 commands; the service re-sends what is still pending.
//   TrialStatus   reliable, keep-all, volatile: a cell re-sends a final status
//                 when it sees a command again (idempotency), so nothing needs
//                 to be kept for late joiners.
//   GroundTruth   reliable, keep-all, bounded in flight (the writer waits for
//                 acknowledgements every kGroundTruthMaxBatches/4 batches);
//                 a short heartbeat period so lost fragments are repaired fast.
//                 It is a log, not telemetry: a full history blocks the writer
//                 (Write returns false after max_blocking_time) instead of
//                 dropping a sample.
//   LiveState     best-effort, keep-last 1 per cell, volatile, deadline one
//                 sample period (kLiveDeadline_s): what a controller or a
//                 watcher needs now. Nothing is acknowledged, so a write never
//                 waits; the reliable GroundTruth log beside it is unchanged.
//   PusherCommand best-effort, keep-last 1 per cell, volatile, deadline one
//                 period: a controller's answer to a LiveState sample; the
//                 next answer supersedes a lost one (the cell holds the last
//                 command a bounded time, executors/README.md). A cell reads
//                 it through a content filter on its own cell id, evaluated by
//                 the writer: a command crosses to its cell only (one send,
//                 not one per cell: bench/README.md). Writer-side filtering
//                 needs a writer of infinite liveliness, so this topic's
//                 writers assert none (a silent controller is found by the
//                 cell's hold time instead).
//                 Each controller publishes on a topic of its own name,
//                 "PusherCommand.<name>" (ControllerTopic), same type and
//                 QoS; a cell reads the topic of its scene's controller.
//   Real-time readers  (LiveState, PusherCommand) of a local-only participant
//                 with shared memory listen on a loopback UDP port of their
//                 own only: Fast DDS 2.9 sends a best-effort message to every
//                 locator a reader announces, so with shared memory and UDP
//                 each message arrived twice (and was decoded, secured:
//                 authenticated, twice). Every local participant reaches UDP
//                 loopback, shared memory or not.
//   Cell topics   (CellAnnounce, TrialStatus, GroundTruth, LiveState) writers assert
//                 automatic liveliness with lease kCellLivelinessLease_s and
//                 readers request it: a reader sees a dead cell within that
//                 lease. (A writer offering a longer lease does not match.)
//   Participants  lease ParticipantOptions::lease_s (2.5 s, not Fast DDS's 20 s).
//                 Each introduces itself in its user data ("pid P on host H"),
//                 so a peer can name who holds a name (WaitForNamesake).
//   Instances     CellAnnounce and TrialCommand are keyed by cell, with no
//                 instance limit. TrialStatus and GroundTruth have no key:
//                 Fast DDS 2.9 never frees an instance, so one per trial grew
//                 a cell by ~14 KB per trial; unkeyed, memory stays flat.
//   Intra-process delivery is off (it deadlocks against the liveliness
//                 protocol in Fast DDS 2.9.1); same-process participants use
//                 the transports.
//
// Transports (secure by default)
//   No network option: Fast DDS's built-in transports are off; shared memory
//   plus UDPv4 restricted to 127.0.0.1; discovery is unicast to 127.0.0.1 (no
//   multicast at all). Nothing leaves this host and no other host sees us.
//   --peers h[:p],...  adds UDPv4 on every interface and unicast discovery to
//                      those peers (still no multicast).
//   --discovery-server [id@]h:p  makes this participant a client of a Fast
//                      DDS discovery server (`fastdds discovery -i id -l h -p p`).
//   --profile-xml F    loads a Fast DDS XML profile file first; its default
//                      participant profile decides the transports.
//   --security DIR     DDS-Security (security.hpp): DIR is an identity from
//                      `arena certs issue`; every file there is checked
//                      (SecurityError naming it), then the participant's
//                      dds.sec.* properties point at them. Applied last, on
//                      top of any of the above (profiles included).
//
// Invariants
//   1. Every entity is created through Participant / Writer / Reader; a null
//      from Fast DDS throws DdsError naming the step.
//   2. A Writer or Reader keeps its Participant's internals alive; the
//      participant is torn down with delete_contained_entities() when the
//      last of them goes.
//   3. Listener callbacks never run user code: they take samples
//      (take_next_sample, valid_data only, known schema_version only) into a
//      queue and notify a condition variable; user threads call Take().
//   4. Every wait has a timeout.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "arena/errors/error.hpp"

namespace arena::dds {

using Millis = std::chrono::milliseconds;

// Fast DDS refused to create or configure an entity (communication), or an
// option is invalid (bad input). what() starts with the step or the option
// ("--peers: ...").
class DdsError : public Error {
 public:
  explicit DdsError(const std::string& what, ErrorCategory category = ErrorCategory::kCommunication)
      : Error(category, what) {}
};

inline constexpr double kCellLivelinessLease_s = 1.0;
// The largest domain id whose ports Fast DDS can form (7400 + 250 x domain +
// offsets for participant ids up to 65535): 232 fails on the first user port.
inline constexpr int kMaxDomainId = 231;
inline constexpr int kGroundTruthMaxBatches = 256;  // unacknowledged batches at most
inline constexpr double kGroundTruthHeartbeat_s = 0.05;
// One sample period at 250 Hz: the deadline of the real-time topics.
inline constexpr double kLiveDeadline_s = 0.004;

struct NetworkOptions {
  // "host" or "host:port" (the peer's metatraffic unicast port; without one,
  // the well-known ports of the first kPeerParticipantRange participants of
  // the domain are tried). Empty: stay on this host.
  std::vector<std::string> peers;
  // "[id@]host:port" of a Fast DDS discovery server; empty: simple discovery.
  std::string discovery_server;
  // Fast DDS XML profile file, loaded before anything else; empty: none.
  std::string profile_xml;
  bool shared_memory = true;
  // DDS-Security identity directory (security.hpp); empty: no security.
  std::string security_dir;
};

// Participants tried per host (well-known ports) when a peer has no port.
inline constexpr int kPeerParticipantRange = 64;

// "a,b:7410, c" -> {"a", "b:7410", "c"}; validates every entry.
// @throws DdsError("--peers: ...") naming the bad entry.
std::vector<std::string> ParsePeers(const std::string& text);

struct ParticipantOptions {
  int domain_id = 0;  // 0..kMaxDomainId (Fast DDS port arithmetic)
  std::string name;   // "arena.cell.<id>", "arena.service", ...
  NetworkOptions network;
  double lease_s = 2.5;  // participant lease (s); announcements every lease/5
};

// Something a peer did, as seen by this participant's discovery or by one of
// its readers' liveliness tracking.
struct PeerEvent {
  enum class Kind {
    kParticipantJoined,  // discovered a participant
    kParticipantLeft,    // participant removed (clean exit) or dropped (lease expired)
    kWriterLost,         // a writer's liveliness lease expired
    kWriterAlive,        // a writer became alive (again)
  };
  Kind kind = Kind::kParticipantJoined;
  std::string participant;  // the peer's participant name ("" if not yet known)
  std::string topic;        // kWriter*: the topic of the reader that saw it
  std::chrono::steady_clock::time_point when{};
};
const char* ToString(PeerEvent::Kind kind);

class Participant;
namespace detail {
struct ParticipantCore;
}

// One DomainParticipant with the four types registered, one publisher and one
// subscriber. Thread-safe.
class Participant {
 public:
  // @throws DdsError when an option is invalid or Fast DDS refuses.
  explicit Participant(const ParticipantOptions& options);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  const std::string& name() const;
  int domain_id() const;

  // Next discovery/liveliness event, waiting up to timeout.
  std::optional<PeerEvent> NextPeerEvent(Millis timeout);
  // Names of the participants currently known (discovered and not left).
  std::vector<std::string> Peers() const;
  // Waits until a participant with this name is known. @returns false on timeout.
  bool WaitForPeer(const std::string& name, Millis timeout);
  // Waits until another participant with this participant's own name is
  // known (a name that must be unique on the domain, e.g. a controller's).
  // @returns how it introduced itself ("pid 123 on host h"), nullopt on timeout.
  std::optional<std::string> WaitForNamesake(Millis timeout);
  // DDS-Security: remote participants whose authentication handshake this
  // participant completed (0 without security). Discovery reports a peer
  // before that; its endpoints match after it.
  int AuthenticatedPeers() const;
  // Waits until at least `peers` remote participants are authenticated.
  // @returns false on timeout.
  bool WaitForAuthenticated(int peers, Millis timeout);

  std::shared_ptr<detail::ParticipantCore> core() const { return core_; }

 private:
  std::shared_ptr<detail::ParticipantCore> core_;
};

struct WriterOptions {
  // How long Write() may block on a full history (s).
  double max_blocking_s = 1.0;
  // PusherCommand only: write on the topic of this controller's commands,
  // ControllerTopic(controller). Empty: the plain PusherCommand topic.
  std::string controller;
};

// A typed DataWriter on the topic of T (one of the six arena::msg types).
template <class T>
class Writer {
 public:
  // @throws DdsError when Fast DDS refuses.
  explicit Writer(Participant& participant, const WriterOptions& options = {});
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // Sets schema_version and publishes. GroundTruth: after every
  // kGroundTruthMaxBatches/4 batches, first waits up to max_blocking_s for
  // the readers to acknowledge everything (the bounded history).
  // @returns false when that wait or the write timed out or failed; the
  // sample was not sent (try again later).
  // Not thread-safe: one thread writes through a Writer.
  bool Write(T& sample);
  // Number of matched readers.
  int Matched() const;
  // @returns false on timeout.
  bool WaitForMatched(int readers, Millis timeout) const;
  // Waits until every matched reader acknowledged everything written.
  bool WaitForAcknowledgments(Millis timeout) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Rung by every reader that names it (ReaderOptions::doorbell) when a sample
// arrives, so one loop serving several topics waits on all of them at once:
// a sample of one topic never waits out another topic's timeout (issue 27:
// a trial's last ground-truth batch sat behind the service's status wait).
class Doorbell {
 public:
  Doorbell();
  ~Doorbell();
  Doorbell(const Doorbell&) = delete;
  Doorbell& operator=(const Doorbell&) = delete;
  void Ring();
  // Waits until rung or `timeout`, and clears the ring. @returns true if rung.
  bool Wait(std::chrono::nanoseconds timeout);
  // Rung since the last Wait (the ring stays for the next Wait).
  bool Rung() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct ReaderOptions {
  ReaderOptions() = default;
  // ReaderOptions{false}, ReaderOptions{false, "c1"}.
  ReaderOptions(bool liveliness, std::string cell = "")
      : report_liveliness(liveliness), only_cell(std::move(cell)) {}

  // Track writers' liveliness and report kWriterLost / kWriterAlive as
  // participant PeerEvents.
  bool report_liveliness = true;
  // LiveState / PusherCommand only: this cell's messages only. The reader
  // reads a content-filtered topic (filter class kCellFilterClass), so a
  // writer that filters for its readers (every PusherCommand writer: see
  // QoS above) sends a cell only its own messages; other writers' messages
  // are filtered on arrival. Empty: all cells.
  std::string only_cell;
  // false: only_cell is checked in the listener alone, every message of the
  // topic crosses to this reader (how it was before the content filter;
  // bench_dds measures both).
  bool cell_filter_in_dds = true;
  // PusherCommand only: read the topic of this controller's commands,
  // ControllerTopic(controller), and no other. Empty: the plain topic.
  std::string controller;
  // Rung after each arrival queued for Take()/TakeAll(). Empty: none.
  std::shared_ptr<Doorbell> doorbell;
};

// What a reader saw and did not hand over (Reader::counters()).
struct ReaderCounters {
  std::uint64_t taken = 0;       // handed to Take()/TakeAll()
  std::uint64_t superseded = 0;  // real-time topics: replaced in the queue by a newer
                                 // message of the same cell before anyone took it
  std::uint64_t lost = 0;        // best-effort: reported lost by DDS (sequence gaps; for an
                                 // only_cell reader these include the other cells' messages
                                 // its writer filtered out)
  std::uint64_t other_cell = 0;  // only_cell: arrived for another cell (crossed for nothing)
};

// Content filter class of ReaderOptions::only_cell: expression "cell_id = %0",
// parameter 0 the cell id (the topic's key, the first member of the type).
inline constexpr const char* kCellFilterClass = "arena.cell_id";

// A typed DataReader on the topic of T; samples are queued by the listener
// and taken by the caller's thread.
template <class T>
class Reader {
 public:
  // @throws DdsError when Fast DDS refuses.
  explicit Reader(Participant& participant, const ReaderOptions& options = {});
  ~Reader();
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  // Next sample in arrival order, waiting up to timeout (0: a poll that
  // never yields the thread). LiveState and
  // PusherCommand queue keep-last 1 per cell as their QoS does: a newer
  // message of a cell replaces one not yet taken.
  // (Any duration: a real-time reader waits to the microsecond.)
  std::optional<T> Take(std::chrono::nanoseconds timeout);
  // Every queued sample, without waiting.
  std::vector<T> TakeAll();
  int Matched() const;
  bool WaitForMatched(int writers, Millis timeout) const;
  // Samples dropped because their schema_version is unknown.
  std::uint64_t rejected_version() const;
  ReaderCounters counters() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Topic name of each message type ("CellAnnounce", ...).
template <class T>
const char* TopicName();

// Removes the /dev/shm files of Fast DDS participants whose process died
// without closing them (a SIGKILLed cell leaves ~0.5 MB): a segment or port
// whose lock file nobody holds. Live processes' files are never touched.
// @returns the number of files removed.
std::size_t CleanZombieSharedMemory();

// A DDS domain this process holds on this host against every other arena
// process choosing one at the same moment (`arena run` picking a quiet
// domain, a test picking its own): an exclusive flock() on
// /tmp/arena-domain-<id>.lock, held while the claim lives and dropped by the
// kernel when the process dies. A probe for peers alone cannot see a domain
// another process has chosen but not joined yet: two test suites met each
// other's cells that way.
class HostDomainClaim {
 public:
  // The claim, or nothing when another process holds the domain (or the
  // lock file cannot be opened: then nobody can claim it either).
  static std::optional<HostDomainClaim> TryClaim(int domain_id);
  HostDomainClaim(HostDomainClaim&& other) noexcept;
  HostDomainClaim& operator=(HostDomainClaim&& other) noexcept;
  HostDomainClaim(const HostDomainClaim&) = delete;
  HostDomainClaim& operator=(const HostDomainClaim&) = delete;
  ~HostDomainClaim();
  int domain_id() const { return domain_id_; }
  // Where the lock file of `domain_id` lives.
  static std::string LockPath(int domain_id);

 private:
  HostDomainClaim(int domain_id, int fd) : domain_id_(domain_id), fd_(fd) {}
  int domain_id_ = -1;
  int fd_ = -1;
};

// Participant names by role; cells are "arena.cell.<cell id>".
std::string CellParticipantName(const std::string& cell_id);
// A controller registered under `name` is "arena.controller.<name>".
std::string ControllerParticipantName(const std::string& name);

// The topic a controller registered under `name` publishes its pusher
// commands on: "PusherCommand.<name>". A cell reads only the topic of the
// controller its scene names, and under DDS-Security a controller identity's
// grant allows publishing on its own name's topic only (security.hpp), so
// the name is bound to the identity by access control, not by a field.
std::string ControllerTopic(const std::string& name);

}  // namespace arena::dds
