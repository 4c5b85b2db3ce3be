// The shared Fast DDS set-up: contract and QoS rationale in
// schemas/include/arena/schemas/dds.hpp.
#include "arena/schemas/dds.hpp"

#include <arpa/inet.h>
#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>
#include <type_traits>

#include <fastdds/rtps/attributes/ServerAttributes.h>
#include <fastdds/rtps/common/InstanceHandle.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>
#include <fastrtps/xmlparser/XMLProfileManager.h>
#include <spdlog/spdlog.h>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/ContentFilteredTopic.hpp>
#include <fastdds/dds/topic/IContentFilter.hpp>
#include <fastdds/dds/topic/IContentFilterFactory.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include "arena/schemas/arena.h"
#include "arena/schemas/arenaPubSubTypes.h"
#include "arena/schemas/security.hpp"

namespace arena::dds {

namespace fdds = eprosima::fastdds::dds;
namespace frtps = eprosima::fastrtps::rtps;
using eprosima::fastrtps::Duration_t;

// ---------------------------------------------------------------------------
// Options

namespace {

struct HostPort {
  std::string host;
  int port = 0;  // 0 = not given
};

HostPort SplitHostPort(const std::string& entry, const std::string& option) {
  HostPort hp;
  const auto colon = entry.rfind(':');
  hp.host = entry.substr(0, colon);
  if (colon != std::string::npos) {
    const std::string port = entry.substr(colon + 1);
    char* end = nullptr;
    const long value = std::strtol(port.c_str(), &end, 10);
    if (port.empty() || *end != '\0' || value < 1 || value > 65535) {
      throw DdsError(option + ": bad port in '" + entry + "' (want host:1..65535)",
                     ErrorCategory::kBadInput);
    }
    hp.port = static_cast<int>(value);
  }
  if (hp.host.empty())
    throw DdsError(option + ": empty host in '" + entry + "'", ErrorCategory::kBadInput);
  return hp;
}

// Resolves a host name or dotted quad to a dotted quad (IPv4).
std::string ResolveIPv4(const std::string& host, const std::string& option) {
  in_addr addr{};
  if (inet_pton(AF_INET, host.c_str(), &addr) == 1) return host;
  addrinfo hints{};
  hints.ai_family = AF_INET;
  addrinfo* result = nullptr;
  if (getaddrinfo(host.c_str(), nullptr, &hints, &result) != 0 || result == nullptr) {
    throw DdsError(option + ": cannot resolve host '" + host + "'", ErrorCategory::kBadInput);
  }
  char buf[INET_ADDRSTRLEN] = {};
  inet_ntop(AF_INET, &reinterpret_cast<sockaddr_in*>(result->ai_addr)->sin_addr, buf, sizeof buf);
  freeaddrinfo(result);
  return buf;
}

frtps::Locator_t UdpLocator(const std::string& address, int port) {
  frtps::Locator_t loc;
  loc.kind = LOCATOR_KIND_UDPv4;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(loc, address);
  loc.port = static_cast<uint32_t>(port);
  return loc;
}

std::string Trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t");
  return s.substr(b, e - b + 1);
}

}  // namespace

std::vector<std::string> ParsePeers(const std::string& text) {
  std::vector<std::string> peers;
  std::stringstream in(text);
  std::string entry;
  while (std::getline(in, entry, ',')) {
    entry = Trim(entry);
    if (entry.empty())
      throw DdsError("--peers: empty entry in '" + text + "'", ErrorCategory::kBadInput);
    SplitHostPort(entry, "--peers");  // validates
    peers.push_back(entry);
  }
  if (peers.empty()) throw DdsError("--peers: no peer given", ErrorCategory::kBadInput);
  return peers;
}

std::string CellParticipantName(const std::string& cell_id) { return "arena.cell." + cell_id; }
std::string ControllerParticipantName(const std::string& name) {
  return "arena.controller." + name;
}
std::string ControllerTopic(const std::string& name) { return "PusherCommand." + name; }

const char* ToString(PeerEvent::Kind kind) {
  switch (kind) {
    case PeerEvent::Kind::kParticipantJoined:
      return "participant-joined";
    case PeerEvent::Kind::kParticipantLeft:
      return "participant-left";
    case PeerEvent::Kind::kWriterLost:
      return "writer-lost";
    case PeerEvent::Kind::kWriterAlive:
      return "writer-alive";
  }
  return "?";
}

// ---------------------------------------------------------------------------
// Topic traits

template <class T>
struct Traits;
template <>
struct Traits<msg::CellAnnounce> {
  using PubSub = msg::CellAnnouncePubSubType;
  static constexpr const char* kTopic = "CellAnnounce";
};
template <>
struct Traits<msg::TrialCommand> {
  using PubSub = msg::TrialCommandPubSubType;
  static constexpr const char* kTopic = "TrialCommand";
};
template <>
struct Traits<msg::TrialStatus> {
  using PubSub = msg::TrialStatusPubSubType;
  static constexpr const char* kTopic = "TrialStatus";
};
template <>
struct Traits<msg::GroundTruth> {
  using PubSub = msg::GroundTruthPubSubType;
  static constexpr const char* kTopic = "GroundTruth";
};
template <>
struct Traits<msg::LiveState> {
  using PubSub = msg::LiveStatePubSubType;
  static constexpr const char* kTopic = "LiveState";
};
template <>
struct Traits<msg::PusherCommand> {
  using PubSub = msg::PusherCommandPubSubType;
  static constexpr const char* kTopic = "PusherCommand";
};

template <class T>
const char* TopicName() {
  return Traits<T>::kTopic;
}

// ---------------------------------------------------------------------------
// QoS per topic

namespace {

// The DDS topic an endpoint of `topic` uses: a controller's own topic for
// PusherCommand (ControllerTopic), the type's topic otherwise.
std::string DdsTopic(const std::string& topic, const std::string& controller) {
  if (controller.empty()) return topic;
  if (topic != "PusherCommand")
    throw DdsError("dds: " + topic + ": only PusherCommand endpoints name a controller");
  return ControllerTopic(controller);
}

bool IsRealTime(const std::string& topic) {
  return topic == "LiveState" || topic == "PusherCommand";
}

void ApplyTopicQos(const std::string& topic, fdds::ReliabilityQosPolicy* reliability,
                   fdds::DurabilityQosPolicy* durability, fdds::HistoryQosPolicy* history,
                   fdds::ResourceLimitsQosPolicy* limits) {
  reliability->kind = fdds::RELIABLE_RELIABILITY_QOS;
  durability->kind = fdds::VOLATILE_DURABILITY_QOS;
  history->kind = fdds::KEEP_ALL_HISTORY_QOS;
  // CellAnnounce and TrialCommand are keyed by cell, and Fast DDS 2.9 never
  // frees an instance slot, so the default max_instances (10) would stall a
  // service after ten cells. (The per-trial topics are unkeyed for the same
  // reason: one instance per trial grew without bound.) No instance limit
  // anywhere; the only bound that matters,
  // ground truth in flight, is the writer's acknowledgement window
  // (kGroundTruthMaxBatches, see Writer::Write).
  limits->max_instances = 0;
  limits->max_samples_per_instance = 0;
  limits->max_samples = 0;
  limits->allocated_samples = 32;
  if (topic == "CellAnnounce") {
    durability->kind = fdds::TRANSIENT_LOCAL_DURABILITY_QOS;
    history->kind = fdds::KEEP_LAST_HISTORY_QOS;
    history->depth = 1;
  }
  if (IsRealTime(topic)) {
    // Telemetry: the newest sample per cell is all that matters; nothing is
    // acknowledged, so nothing ever waits (the reliable log's tail, see
    // bench/README.md, was its acknowledgement window).
    reliability->kind = fdds::BEST_EFFORT_RELIABILITY_QOS;
    history->kind = fdds::KEEP_LAST_HISTORY_QOS;
    history->depth = 1;
  }
}

// Topics that cells write: their writers assert liveliness, their readers
// track it. Not PusherCommand: a writer filters for its readers (one send per
// command, to its cell) only with infinite liveliness (Fast DDS 2.9), and a
// cell finds a silent controller by its hold time anyway.
bool CellWritten(const std::string& topic) {
  return topic != "TrialCommand" && topic != "PusherCommand";
}

// ReaderOptions::only_cell as a DDS content filter (kCellFilterClass): the
// sample's first member, the key cell_id, equals parameter 0. Registered in
// every participant, so a writer evaluates its readers' filters and sends a
// message to the readers that want it only; a reader filters on arrival
// what a writer did not. Reads the CDR string in place: no type objects
// (Fast DDS's SQL filter needs them and arena's generated types carry none).
class CellFilter final : public fdds::IContentFilter {
 public:
  explicit CellFilter(std::string cell) : cell_(std::move(cell)) {}
  void set_cell(std::string cell) { cell_ = std::move(cell); }
  bool evaluate(const SerializedPayload& payload, const FilterSampleInfo&,
                const GUID_t&) const override {
    // Encapsulation (2 bytes kind, 2 options), then uint32 length with the
    // terminating NUL, then the characters.
    if (payload.data == nullptr || payload.length < 9) return false;
    const bool little = (payload.data[1] & 1) != 0;
    const unsigned char* p = payload.data + 4;
    const std::uint32_t n = little ? (p[0] | p[1] << 8 | p[2] << 16 | std::uint32_t{p[3]} << 24)
                                   : (std::uint32_t{p[0]} << 24 | p[1] << 16 | p[2] << 8 | p[3]);
    if (n == 0 || n - 1 != cell_.size() || 8 + n > payload.length) return false;
    return std::memcmp(payload.data + 8, cell_.data(), cell_.size()) == 0;
  }

 private:
  std::string cell_;
};

constexpr const char* kCellFilterExpression = "cell_id = %0";

class CellFilterFactory : public fdds::IContentFilterFactory {
 public:
  ReturnCode_t create_content_filter(const char*, const char*, const fdds::TopicDataType*,
                                     const char* expression, const ParameterSeq& parameters,
                                     fdds::IContentFilter*& filter) override {
    if (expression != nullptr && std::string(expression) != kCellFilterExpression)
      return ReturnCode_t::RETCODE_BAD_PARAMETER;
    if (parameters.length() != 1 || parameters[0] == nullptr)
      return ReturnCode_t::RETCODE_BAD_PARAMETER;
    if (filter != nullptr) {  // new parameters for a filter made before
      static_cast<CellFilter*>(filter)->set_cell(parameters[0]);
    } else {
      filter = new CellFilter(parameters[0]);
    }
    return ReturnCode_t::RETCODE_OK;
  }
  ReturnCode_t delete_content_filter(const char*, fdds::IContentFilter* filter) override {
    delete static_cast<CellFilter*>(filter);
    return ReturnCode_t::RETCODE_OK;
  }
};

CellFilterFactory& TheCellFilterFactory() {
  static CellFilterFactory factory;
  return factory;
}

std::string Describe(const fdds::ReliabilityQosPolicy& r, const fdds::DurabilityQosPolicy& d,
                     const fdds::HistoryQosPolicy& h, const fdds::ResourceLimitsQosPolicy& l,
                     const fdds::LivelinessQosPolicy& lv) {
  std::ostringstream out;
  out << (r.kind == fdds::RELIABLE_RELIABILITY_QOS ? "reliable" : "best-effort") << ", "
      << (d.kind == fdds::TRANSIENT_LOCAL_DURABILITY_QOS ? "transient-local"
          : d.kind == fdds::VOLATILE_DURABILITY_QOS      ? "volatile"
                                                         : "other-durability")
      << ", "
      << (h.kind == fdds::KEEP_ALL_HISTORY_QOS ? std::string("keep-all")
                                               : "keep-last " + std::to_string(h.depth))
      << ", max_samples " << l.max_samples << ", liveliness "
      << (lv.kind == fdds::AUTOMATIC_LIVELINESS_QOS ? "automatic" : "manual") << " lease "
      << (lv.lease_duration == eprosima::fastrtps::c_TimeInfinite
              ? std::string("inf")
              : std::to_string(lv.lease_duration.to_ns() * 1e-9) + " s");
  return out.str();
}

}  // namespace

// ---------------------------------------------------------------------------
// Participant core

namespace detail {

struct ParticipantCore : public fdds::DomainParticipantListener {
  std::string name;
  int domain_id = 0;
  std::string security_dir;  // --security: the identity (for a denied endpoint's message)
  fdds::DomainParticipant* participant = nullptr;
  fdds::Publisher* publisher = nullptr;
  fdds::Subscriber* subscriber = nullptr;
  std::map<std::string, fdds::Topic*> topics;
  // Local-only with shared memory: the real-time readers listen on a UDP
  // loopback port of their own only (see Reader).
  bool real_time_on_udp = false;

  mutable std::mutex mutex;
  std::condition_variable changed;
  std::deque<PeerEvent> events;
  std::map<frtps::GuidPrefix_t, std::string> peers;          // discovered participants
  std::map<frtps::GuidPrefix_t, std::string> introductions;  // their user data
  std::set<frtps::GuidPrefix_t> authenticated;               // DDS-Security: handshake done
  std::uint64_t started_unix_ns = 0;  // when this participant was made (its user data)

  ~ParticipantCore() override {
    if (participant != nullptr) {
      participant->set_listener(nullptr);
      participant->delete_contained_entities();
      fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
    }
  }

  void Push(PeerEvent event) {
    event.when = std::chrono::steady_clock::now();
    {
      std::lock_guard<std::mutex> lock(mutex);
      events.push_back(std::move(event));
    }
    changed.notify_all();
  }

  std::string PeerName(const frtps::GuidPrefix_t& prefix) const {
    std::lock_guard<std::mutex> lock(mutex);
    auto it = peers.find(prefix);
    return it == peers.end() ? std::string() : it->second;
  }

  void on_participant_discovery(fdds::DomainParticipant*,
                                frtps::ParticipantDiscoveryInfo&& info) override {
    using S = frtps::ParticipantDiscoveryInfo::DISCOVERY_STATUS;
    const std::string peer = info.info.m_participantName.to_string();
    const auto prefix = info.info.m_guid.guidPrefix;
    if (info.status == S::DISCOVERED_PARTICIPANT) {
      {
        std::lock_guard<std::mutex> lock(mutex);
        peers[prefix] = peer;
        const auto& data = info.info.m_userData.data_vec();
        introductions[prefix] = std::string(data.begin(), data.end());
      }
      spdlog::debug("dds: {} discovered participant {}", name, peer);
      Push({PeerEvent::Kind::kParticipantJoined, peer, "", {}});
    } else if (info.status == S::REMOVED_PARTICIPANT || info.status == S::DROPPED_PARTICIPANT) {
      {
        std::lock_guard<std::mutex> lock(mutex);
        peers.erase(prefix);
        introductions.erase(prefix);
        authenticated.erase(prefix);
      }
      spdlog::debug("dds: {} lost participant {} ({})", name, peer,
                    info.status == S::DROPPED_PARTICIPANT ? "lease expired" : "removed");
      Push({PeerEvent::Kind::kParticipantLeft, peer, "", {}});
    }
  }

  // DDS-Security: a remote participant passed (or failed) authentication.
  // Discovery reports a peer before its handshake; its endpoints match only
  // after it, and until every handshake of a domain is done they cost CPU.
  void onParticipantAuthentication(fdds::DomainParticipant*,
                                   frtps::ParticipantAuthenticationInfo&& info) override {
    using S = frtps::ParticipantAuthenticationInfo::AUTHENTICATION_STATUS;
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (info.status == S::AUTHORIZED_PARTICIPANT) {
        authenticated.insert(info.guid.guidPrefix);
      } else {
        authenticated.erase(info.guid.guidPrefix);
      }
    }
    spdlog::debug("dds: {} {} participant {}", name,
                  info.status == S::AUTHORIZED_PARTICIPANT ? "authenticated" : "refused",
                  PeerName(info.guid.guidPrefix));
    changed.notify_all();
  }

  fdds::Topic* TopicFor(const std::string& topic, const std::string& type) {
    std::lock_guard<std::mutex> lock(mutex);
    return TopicLocked(topic, type);
  }

  // `topic` restricted to one cell's messages (ReaderOptions::only_cell).
  fdds::TopicDescription* CellTopicFor(const std::string& topic, const std::string& type,
                                       const std::string& cell) {
    std::lock_guard<std::mutex> lock(mutex);
    const std::string name = topic + ".cell." + cell;
    auto it = filtered.find(name);
    if (it != filtered.end()) return it->second;
    fdds::ContentFilteredTopic* t = participant->create_contentfilteredtopic(
        name, TopicLocked(topic, type), kCellFilterExpression, {cell}, kCellFilterClass);
    if (t == nullptr) throw DdsError("dds: create_contentfilteredtopic(" + name + ") failed");
    filtered[name] = t;
    return t;
  }

 private:
  fdds::Topic* TopicLocked(const std::string& topic, const std::string& type) {
    auto it = topics.find(topic);
    if (it != topics.end()) return it->second;
    fdds::Topic* t = participant->create_topic(topic, type, fdds::TOPIC_QOS_DEFAULT);
    if (t == nullptr) throw DdsError("dds: create_topic(" + topic + ") failed");
    topics[topic] = t;
    return t;
  }
  std::map<std::string, fdds::ContentFilteredTopic*> filtered;
};

}  // namespace detail

namespace {

void ApplyNetwork(const ParticipantOptions& opt, fdds::DomainParticipantQos* qos) {
  const NetworkOptions& net = opt.network;
  auto& builtin = qos->wire_protocol().builtin;
  const bool local_only = net.peers.empty() && net.discovery_server.empty();

  qos->transport().use_builtin_transports = false;
  qos->transport().user_transports.clear();
  if (net.shared_memory) {
    qos->transport().user_transports.push_back(
        std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>());
  }
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  udp->maxInitialPeersRange = kPeerParticipantRange;
  if (local_only) udp->interfaceWhiteList.push_back("127.0.0.1");
  qos->transport().user_transports.push_back(udp);

  // A metatraffic unicast locator of our own means Fast DDS creates no
  // multicast discovery locators; port 0 = the well-known port of this
  // participant (moved along when taken).
  builtin.metatrafficMulticastLocatorList.clear();
  builtin.metatrafficUnicastLocatorList.clear();
  builtin.initialPeersList.clear();
  builtin.metatrafficUnicastLocatorList.push_back(
      UdpLocator(local_only ? "127.0.0.1" : "0.0.0.0", 0));
  // Same-host peers are always found through loopback.
  builtin.initialPeersList.push_back(UdpLocator("127.0.0.1", 0));
  for (const std::string& peer : net.peers) {
    const HostPort hp = SplitHostPort(peer, "--peers");
    builtin.initialPeersList.push_back(UdpLocator(ResolveIPv4(hp.host, "--peers"), hp.port));
  }
  // User data goes to every transport's default locators: shared memory
  // between processes of this host, UDPv4 (127.0.0.1 only when local).

  if (!net.discovery_server.empty()) {
    std::string entry = net.discovery_server;
    int server_id = 0;
    if (auto at = entry.find('@'); at != std::string::npos) {
      const std::string id = entry.substr(0, at);
      char* end = nullptr;
      const long v = std::strtol(id.c_str(), &end, 10);
      if (id.empty() || *end != '\0' || v < 0 || v > 255) {
        throw DdsError("--discovery-server: bad server id '" + id + "' (want 0..255)",
                       ErrorCategory::kBadInput);
      }
      server_id = static_cast<int>(v);
      entry = entry.substr(at + 1);
    }
    const HostPort hp = SplitHostPort(entry, "--discovery-server");
    frtps::RemoteServerAttributes server;
    if (!eprosima::fastdds::rtps::get_server_client_default_guidPrefix(server_id,
                                                                       server.guidPrefix)) {
      throw DdsError("--discovery-server: server id " + std::to_string(server_id) + " not usable",
                     ErrorCategory::kBadInput);
    }
    server.metatrafficUnicastLocatorList.push_back(
        UdpLocator(ResolveIPv4(hp.host, "--discovery-server"), hp.port == 0 ? 11811 : hp.port));
    builtin.discovery_config.discoveryProtocol = frtps::DiscoveryProtocol_t::CLIENT;
    builtin.discovery_config.m_DiscoveryServers.push_back(server);
    builtin.initialPeersList.clear();
  }
}

// The last step of the chain: DDS-Security fills the participant's property
// policy from an identity directory (security.hpp), after checking every file
// there, so that a bad file is named here rather than in Fast DDS's log.
void ApplySecurity(const NetworkOptions& net, fdds::DomainParticipantQos* qos) {
  if (net.security_dir.empty()) return;
  IdentityFiles files;
  try {
    files = CheckIdentityDir(net.security_dir);
  } catch (const SecurityError& e) {
    throw SecurityError(std::string("--security: ") + e.what());
  }
  auto& properties = qos->properties().properties();
  auto set = [&properties](const std::string& name, const std::string& value) {
    properties.emplace_back(name, value);
  };
  const std::string auth = "dds.sec.auth.builtin.PKI-DH.";
  const std::string access = "dds.sec.access.builtin.Access-Permissions.";
  set("dds.sec.auth.plugin", "builtin.PKI-DH");
  set(auth + "identity_ca", "file://" + files.ca_cert);
  set(auth + "identity_certificate", "file://" + files.cert);
  set(auth + "private_key", "file://" + files.key);
  set("dds.sec.access.plugin", "builtin.Access-Permissions");
  set(access + "permissions_ca", "file://" + files.ca_cert);
  set(access + "governance", "file://" + files.governance);
  set(access + "permissions", "file://" + files.permissions);
  set("dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC");
}

template <class T>
void Register(fdds::DomainParticipant* participant) {
  fdds::TypeSupport type(new typename Traits<T>::PubSub());
  if (type.register_type(participant) != ReturnCode_t::RETCODE_OK) {
    throw DdsError(std::string("dds: register_type(") + Traits<T>::kTopic + ") failed");
  }
}

}  // namespace

Participant::Participant(const ParticipantOptions& options)
    : core_(std::make_shared<detail::ParticipantCore>()) {
  if (options.domain_id < 0 || options.domain_id > kMaxDomainId) {
    throw DdsError("--domain: must be 0.." + std::to_string(kMaxDomainId) + ", got " +
                       std::to_string(options.domain_id),
                   ErrorCategory::kBadInput);
  }
  if (!(options.lease_s > 0.2) || options.lease_s > 3600) {
    throw DdsError("dds: participant lease must be in (0.2, 3600] s", ErrorCategory::kBadInput);
  }
  auto* factory = fdds::DomainParticipantFactory::get_instance();
  // Fast DDS 2.9.1 deadlocks when a writer delivers intra-process while the
  // liveliness protocol asserts (seen in bench_dds: WLP assertion against
  // StatefulWriter::deliver_sample_to_intraprocesses). Participants of one
  // process therefore talk through the transports like any other.
  static std::once_flag library_once;
  std::call_once(library_once, [] {
    eprosima::fastrtps::LibrarySettingsAttributes library;
    library.intraprocess_delivery = eprosima::fastrtps::INTRAPROCESS_OFF;
    eprosima::fastrtps::xmlparser::XMLProfileManager::library_settings(library);
  });
  // Profiles first, then our overrides, then log what is in effect.
  if (!options.network.profile_xml.empty()) {
    if (factory->load_XML_profiles_file(options.network.profile_xml) != ReturnCode_t::RETCODE_OK) {
      throw DdsError("--profile-xml: cannot load '" + options.network.profile_xml + "'",
                     ErrorCategory::kBadInput);
    }
    // Fast DDS 2.9's load_XML_profiles_file leaves the factory's default
    // participant QoS alone; load_profiles() (its first call in a process)
    // takes the default profile of everything loaded so far into it. Without
    // this the file's participant profile was silently ignored.
    factory->load_profiles();
  }
  fdds::DomainParticipantQos qos = factory->get_default_participant_qos();
  qos.name(options.name);
  {  // who we are, for a peer that must name us (Participant::WaitForNamesake)
    char host[256] = {};
    if (gethostname(host, sizeof host - 1) != 0) std::strcpy(host, "?");
    // "<unix ns at start> pid P on host H": the start orders namesakes.
    core_->started_unix_ns =
        static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                       std::chrono::system_clock::now().time_since_epoch())
                                       .count());
    const std::string intro = std::to_string(core_->started_unix_ns) + " pid " +
                              std::to_string(static_cast<long>(getpid())) + " on host " + host;
    qos.user_data().data_vec(std::vector<frtps::octet>(intro.begin(), intro.end()));
  }
  auto& discovery = qos.wire_protocol().builtin.discovery_config;
  discovery.leaseDuration = Duration_t(options.lease_s);
  discovery.leaseDuration_announcementperiod = Duration_t(options.lease_s / 5.0);
  if (options.network.profile_xml.empty()) ApplyNetwork(options, &qos);
  core_->real_time_on_udp = options.network.profile_xml.empty() && options.network.peers.empty() &&
                            options.network.discovery_server.empty() &&
                            options.network.shared_memory;
  ApplySecurity(options.network, &qos);

  core_->name = options.name;
  core_->domain_id = options.domain_id;
  core_->security_dir = options.network.security_dir;
  const fdds::StatusMask mask = fdds::StatusMask::none();  // participant discovery only
  core_->participant = factory->create_participant(options.domain_id, qos, core_.get(), mask);
  if (core_->participant == nullptr) {
    if (!options.network.security_dir.empty()) {
      throw SecurityError(
          "--security " + options.network.security_dir +
          ": Fast DDS refused this identity on domain " + std::to_string(options.domain_id) +
          " (is the domain outside the lab's or the grant's range? see the Fast DDS log above)");
    }
    throw DdsError("dds: create_participant(domain " + std::to_string(options.domain_id) +
                   ") failed (see Fast DDS log above)");
  }
  Register<msg::CellAnnounce>(core_->participant);
  Register<msg::TrialCommand>(core_->participant);
  Register<msg::TrialStatus>(core_->participant);
  Register<msg::GroundTruth>(core_->participant);
  Register<msg::LiveState>(core_->participant);
  Register<msg::PusherCommand>(core_->participant);
  if (core_->participant->register_content_filter_factory(
          kCellFilterClass, &TheCellFilterFactory()) != ReturnCode_t::RETCODE_OK) {
    throw DdsError(std::string("dds: register_content_filter_factory(") + kCellFilterClass +
                   ") failed");
  }
  core_->publisher = core_->participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  if (core_->publisher == nullptr) throw DdsError("dds: create_publisher failed");
  core_->subscriber = core_->participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  if (core_->subscriber == nullptr) throw DdsError("dds: create_subscriber failed");

  const auto& effective = core_->participant->get_qos();
  spdlog::debug(
      "dds: participant {} domain {} lease {} s, transports: {}{}, peers {}, {}", options.name,
      options.domain_id, options.lease_s, options.network.shared_memory ? "shm+" : "",
      options.network.peers.empty() && options.network.discovery_server.empty() ? "udpv4@127.0.0.1"
                                                                                : "udpv4",
      effective.wire_protocol().builtin.initialPeersList.size(),
      options.network.discovery_server.empty()
          ? "simple discovery"
          : "discovery server " + options.network.discovery_server);
}

Participant::~Participant() = default;

const std::string& Participant::name() const { return core_->name; }
int Participant::domain_id() const { return core_->domain_id; }

std::optional<PeerEvent> Participant::NextPeerEvent(Millis timeout) {
  std::unique_lock<std::mutex> lock(core_->mutex);
  // A poll (timeout 0) must not enter a timed wait: an expired futex wait
  // still yields the CPU, and the service polls here on every loop turn.
  const auto has_event = [&] { return !core_->events.empty(); };
  if (timeout.count() <= 0 ? !has_event() : !core_->changed.wait_for(lock, timeout, has_event)) {
    return std::nullopt;
  }
  PeerEvent e = std::move(core_->events.front());
  core_->events.pop_front();
  return e;
}

std::vector<std::string> Participant::Peers() const {
  std::lock_guard<std::mutex> lock(core_->mutex);
  std::vector<std::string> names;
  for (const auto& [prefix, name] : core_->peers) names.push_back(name);
  return names;
}

bool Participant::WaitForPeer(const std::string& name, Millis timeout) {
  std::unique_lock<std::mutex> lock(core_->mutex);
  return core_->changed.wait_for(lock, timeout, [&] {
    for (const auto& [prefix, n] : core_->peers) {
      if (n == name) return true;
    }
    return false;
  });
}

namespace {

// core.TopicFor, with a refused topic under DDS-Security reported like a
// refused endpoint (the grant names the topics an identity may use).
fdds::Topic* TopicOrDenied(detail::ParticipantCore& core, const std::string& topic,
                           const std::string& type, bool publish) {
  try {
    return core.TopicFor(topic, type);
  } catch (const DdsError&) {
    if (core.security_dir.empty()) throw;
    throw SecurityError(DeniedEndpoint(core.security_dir, topic, publish));
  }
}

}  // namespace

std::optional<std::string> Participant::WaitForNamesake(Millis timeout) {
  const frtps::GuidPrefix_t self = core_->participant->guid().guidPrefix;
  std::unique_lock<std::mutex> lock(core_->mutex);
  std::optional<std::string> found;
  // Only a namesake that started before us counts (ties: the smaller GUID
  // prefix): one that started after us finds us and yields, so of two
  // started at once exactly one stays.
  const auto own = std::make_pair(core_->started_unix_ns, self);
  core_->changed.wait_for(lock, timeout, [&] {
    for (const auto& [prefix, n] : core_->peers) {
      if (n != core_->name || prefix == self) continue;
      const auto it = core_->introductions.find(prefix);
      const std::string intro = it == core_->introductions.end() ? "" : it->second;
      std::uint64_t started = 0;
      const auto space = intro.find(' ');
      try {
        started = std::stoull(intro.substr(0, space));
      } catch (const std::exception&) {
        started = 0;  // not an arena participant's introduction: it was there first
      }
      if (std::make_pair(started, prefix) > own) continue;
      found = space == std::string::npos ? std::string("?") : intro.substr(space + 1);
      return true;
    }
    return false;
  });
  return found;
}

int Participant::AuthenticatedPeers() const {
  std::lock_guard<std::mutex> lock(core_->mutex);
  return static_cast<int>(core_->authenticated.size());
}

bool Participant::WaitForAuthenticated(int peers, Millis timeout) {
  std::unique_lock<std::mutex> lock(core_->mutex);
  return core_->changed.wait_for(
      lock, timeout, [&] { return static_cast<int>(core_->authenticated.size()) >= peers; });
}

namespace {
bool PollUntil(Millis timeout, const std::function<bool()>& done) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(Millis(5));
  }
  return true;
}
}  // namespace

namespace {
// A UDP port on 127.0.0.1 that nobody holds now (the kernel's choice); 0 if
// none could be had.
int FreeLoopbackUdpPort() {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  if (fd < 0) return 0;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  int port = 0;
  if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
    port = ntohs(a.sin_port);
  }
  close(fd);
  return port;
}

// True when someone (the reader's receiver, we trust) holds the port.
bool LoopbackUdpPortHeld(int port) {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  if (fd < 0) return false;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  const bool held = bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0;
  close(fd);
  return held;
}
}  // namespace

// ---------------------------------------------------------------------------
// Writer

template <class T>
struct Writer<T>::Impl {
  std::shared_ptr<detail::ParticipantCore> core;
  fdds::DataWriter* writer = nullptr;
  double max_blocking_s = 1.0;
  int window = 0;  // GroundTruth: batches written before an acknowledgement check
  int unconfirmed = 0;

  ~Impl() {
    if (writer != nullptr) core->publisher->delete_datawriter(writer);
  }
};

template <class T>
Writer<T>::Writer(Participant& participant, const WriterOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->core = participant.core();
  auto& core = *impl_->core;
  const std::string topic = Traits<T>::kTopic;  // the QoS are the type's
  const std::string dds_topic = DdsTopic(topic, options.controller);
  fdds::Topic* t = TopicOrDenied(core, dds_topic, typename Traits<T>::PubSub().getName(),
                                 /*publish=*/true);

  fdds::DataWriterQos qos = core.publisher->get_default_datawriter_qos();
  ApplyTopicQos(topic, &qos.reliability(), &qos.durability(), &qos.history(),
                &qos.resource_limits());
  qos.reliability().max_blocking_time = Duration_t(options.max_blocking_s);
  // Payload buffers sized to each sample, reused: the preallocating default
  // sizes every buffer for the type's maximum (1.9 MB for a GroundTruth batch)
  // and zeroes it, which was most of the service's CPU per trial.
  qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;
  impl_->max_blocking_s = options.max_blocking_s;
  if (CellWritten(topic)) {
    qos.liveliness().kind = fdds::AUTOMATIC_LIVELINESS_QOS;
    qos.liveliness().lease_duration = Duration_t(kCellLivelinessLease_s);
    qos.liveliness().announcement_period = Duration_t(kCellLivelinessLease_s / 4.0);
  }
  if (IsRealTime(topic)) {
    qos.deadline().period = Duration_t(kLiveDeadline_s);
    qos.reliability().max_blocking_time = Duration_t(0, 0);
    // Evaluate the readers' cell filters here, for up to this many readers
    // (more are filtered on arrival).
    qos.writer_resource_limits().reader_filters_allocation =
        eprosima::fastrtps::ResourceLimitedContainerConfig(0, 1024, 1);
  }
  if (topic == "GroundTruth") {
    impl_->window = kGroundTruthMaxBatches / 4;
    auto& times = qos.reliable_writer_qos().times;
    times.heartbeatPeriod = Duration_t(kGroundTruthHeartbeat_s);
  }
  impl_->writer = core.publisher->create_datawriter(t, qos, nullptr);
  if (impl_->writer == nullptr) {
    // Under DDS-Security the usual cause is an identity of another role.
    if (!core.security_dir.empty())
      throw SecurityError(DeniedEndpoint(core.security_dir, dds_topic, /*publish=*/true));
    throw DdsError("dds: create_datawriter(" + dds_topic + ") failed");
  }
  const auto q = impl_->writer->get_qos();
  spdlog::debug(
      "dds: {} writer {}: {}", core.name, topic,
      Describe(q.reliability(), q.durability(), q.history(), q.resource_limits(), q.liveliness()));
}

template <class T>
Writer<T>::~Writer() = default;

template <class T>
bool Writer<T>::Write(T& sample) {
  sample.schema_version(msg::SCHEMA_VERSION);
  if (impl_->window > 0 && impl_->unconfirmed >= impl_->window) {
    // Bounded history: at most `window` batches unacknowledged; a reader that
    // does not keep up throttles us here (false = try again later).
    if (impl_->writer->wait_for_acknowledgments(Duration_t(impl_->max_blocking_s)) !=
        ReturnCode_t::RETCODE_OK) {
      return false;
    }
    impl_->unconfirmed = 0;
  }
  if (!impl_->writer->write(&sample)) return false;
  ++impl_->unconfirmed;
  return true;
}

template <class T>
int Writer<T>::Matched() const {
  fdds::PublicationMatchedStatus status;
  impl_->writer->get_publication_matched_status(status);
  return status.current_count;
}

template <class T>
bool Writer<T>::WaitForMatched(int readers, Millis timeout) const {
  return PollUntil(timeout, [&] { return Matched() >= readers; });
}

template <class T>
bool Writer<T>::WaitForAcknowledgments(Millis timeout) const {
  return impl_->writer->wait_for_acknowledgments(Duration_t(timeout.count() * 1e-3)) ==
         ReturnCode_t::RETCODE_OK;
}

// ---------------------------------------------------------------------------
// Reader

template <class T>
struct Reader<T>::Impl : public fdds::DataReaderListener {
  std::shared_ptr<detail::ParticipantCore> core;
  fdds::DataReader* reader = nullptr;
  bool report_liveliness = true;

  std::mutex mutex;
  std::condition_variable arrived;
  std::deque<T> queue;
  std::atomic<std::uint64_t> rejected{0};
  ReaderCounters counters;  // under mutex

  std::string only_cell;  // real-time topics: this cell's messages only
  std::shared_ptr<Doorbell> doorbell;

  ~Impl() override {
    if (reader != nullptr) {
      reader->set_listener(nullptr);
      core->subscriber->delete_datareader(reader);
    }
  }

  void on_data_available(fdds::DataReader* r) override {
    T sample;
    fdds::SampleInfo info;
    std::vector<T> taken;
    while (r->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;  // instance disposed / no writers: not a message
      if (sample.schema_version() != msg::SCHEMA_VERSION) {
        if (rejected.fetch_add(1) == 0) {
          spdlog::warn("dds: {} dropped a {} message of schema version {} (known: {})", core->name,
                       Traits<T>::kTopic, sample.schema_version(), msg::SCHEMA_VERSION);
        }
        continue;
      }
      taken.push_back(std::move(sample));
      sample = T();
    }
    if (taken.empty()) return;
    {
      std::lock_guard<std::mutex> lock(mutex);
      for (auto& s : taken) Enqueue(std::move(s));
    }
    arrived.notify_all();
    if (doorbell) doorbell->Ring();
  }

  void on_sample_lost(fdds::DataReader*, const fdds::SampleLostStatus& status) override {
    std::lock_guard<std::mutex> lock(mutex);
    counters.lost += static_cast<std::uint64_t>(std::max(0, status.total_count_change));
  }

  // Real-time topics: keep-last 1 per cell in our queue too (a reader that
  // fell behind gets each cell's newest message, not a backlog).
  void Enqueue(T&& s) {
    if constexpr (std::is_same_v<T, msg::LiveState> || std::is_same_v<T, msg::PusherCommand>) {
      if (!only_cell.empty() && s.cell_id() != only_cell) {
        ++counters.other_cell;
        return;
      }
      for (auto& q : queue) {
        if (q.cell_id() == s.cell_id()) {
          q = std::move(s);
          ++counters.superseded;
          return;
        }
      }
    }
    queue.push_back(std::move(s));
  }

  void on_liveliness_changed(fdds::DataReader*,
                             const fdds::LivelinessChangedStatus& status) override {
    if (!report_liveliness) return;
    const frtps::GUID_t guid = frtps::iHandle2GUID(status.last_publication_handle);
    const std::string peer = core->PeerName(guid.guidPrefix);
    if (status.not_alive_count_change > 0 || status.alive_count_change < 0) {
      core->Push({PeerEvent::Kind::kWriterLost, peer, Traits<T>::kTopic, {}});
    }
    if (status.alive_count_change > 0) {
      core->Push({PeerEvent::Kind::kWriterAlive, peer, Traits<T>::kTopic, {}});
    }
  }
};

template <class T>
Reader<T>::Reader(Participant& participant, const ReaderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->core = participant.core();
  impl_->report_liveliness = options.report_liveliness;
  impl_->doorbell = options.doorbell;
  auto& core = *impl_->core;
  const std::string topic = Traits<T>::kTopic;  // the QoS are the type's
  const std::string dds_topic = DdsTopic(topic, options.controller);
  fdds::Topic* t = TopicOrDenied(core, dds_topic, typename Traits<T>::PubSub().getName(),
                                 /*publish=*/false);

  fdds::DataReaderQos qos = core.subscriber->get_default_datareader_qos();
  ApplyTopicQos(topic, &qos.reliability(), &qos.durability(), &qos.history(),
                &qos.resource_limits());
  qos.endpoint().history_memory_policy =
      eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;  // as writers
  // Fast DDS tracks a writer's liveliness only for a finite requested lease.
  qos.liveliness().kind = fdds::AUTOMATIC_LIVELINESS_QOS;
  qos.liveliness().lease_duration =
      CellWritten(topic) ? Duration_t(kCellLivelinessLease_s) : eprosima::fastrtps::c_TimeInfinite;
  if (IsRealTime(topic)) qos.deadline().period = Duration_t(kLiveDeadline_s);
  fdds::StatusMask mask = fdds::StatusMask::data_available();
  mask << fdds::StatusMask::liveliness_changed();
  mask << fdds::StatusMask::sample_lost();
  // only_cell: a content-filtered topic (kCellFilterClass, evaluated by the
  // writer where it can); the listener checks again (belt and braces, and
  // counts what crossed for nothing).
  impl_->only_cell = IsRealTime(topic) ? options.only_cell : std::string();
  fdds::TopicDescription* description = t;
  if (!impl_->only_cell.empty() && options.cell_filter_in_dds) {
    description =
        core.CellTopicFor(dds_topic, typename Traits<T>::PubSub().getName(), impl_->only_cell);
  }
  // A best-effort writer sends to every transport's locators of a reader
  // (Fast DDS 2.9: each transport selects its own), so a reader announcing
  // shared memory and UDP got every live sample twice and decoded (secured:
  // authenticated) it twice; the reliable log goes by shared memory alone.
  // A real-time reader therefore listens on a loopback UDP port of its own
  // only, which every local participant reaches, shared memory or not
  // (bench/README.md). The port is one the kernel just called free, checked
  // to be held after the reader made its receiver (another process may have
  // taken it in between: then another port; after 8 tries the defaults).
  if (IsRealTime(topic) && core.real_time_on_udp) {
    for (int attempt = 0; attempt < 8 && impl_->reader == nullptr; ++attempt) {
      const int port = FreeLoopbackUdpPort();
      if (port == 0) break;
      fdds::DataReaderQos own = qos;
      own.endpoint().unicast_locator_list.clear();
      own.endpoint().unicast_locator_list.push_back(UdpLocator("127.0.0.1", port));
      fdds::DataReader* r = core.subscriber->create_datareader(description, own, impl_.get(), mask);
      if (r == nullptr) break;
      if (LoopbackUdpPortHeld(port)) {
        impl_->reader = r;
      } else {
        r->set_listener(nullptr);
        core.subscriber->delete_datareader(r);
      }
    }
  }
  if (impl_->reader == nullptr)
    impl_->reader = core.subscriber->create_datareader(description, qos, impl_.get(), mask);
  if (impl_->reader == nullptr) {
    if (!core.security_dir.empty())
      throw SecurityError(DeniedEndpoint(core.security_dir, dds_topic, /*publish=*/false));
    throw DdsError("dds: create_datareader(" + dds_topic + ") failed");
  }
  const auto q = impl_->reader->get_qos();
  spdlog::debug(
      "dds: {} reader {}: {}", core.name, topic,
      Describe(q.reliability(), q.durability(), q.history(), q.resource_limits(), q.liveliness()));
}

template <class T>
Reader<T>::~Reader() = default;

// ---------------------------------------------------------------------------
// Doorbell

struct Doorbell::Impl {
  mutable std::mutex mutex;
  std::condition_variable rung_cv;
  bool rung = false;
};

Doorbell::Doorbell() : impl_(std::make_unique<Impl>()) {}
Doorbell::~Doorbell() = default;

void Doorbell::Ring() {
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->rung = true;
  }
  impl_->rung_cv.notify_all();
}

bool Doorbell::Wait(std::chrono::nanoseconds timeout) {
  std::unique_lock<std::mutex> lock(impl_->mutex);
  const bool rung = timeout.count() <= 0
                        ? impl_->rung
                        : impl_->rung_cv.wait_for(lock, timeout, [&] { return impl_->rung; });
  impl_->rung = false;
  return rung;
}

bool Doorbell::Rung() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->rung;
}

template <class T>
std::optional<T> Reader<T>::Take(std::chrono::nanoseconds timeout) {
  std::unique_lock<std::mutex> lock(impl_->mutex);
  const auto queued = [&] { return !impl_->queue.empty(); };
  if (timeout.count() <= 0 ? !queued() : !impl_->arrived.wait_for(lock, timeout, queued)) {
    return std::nullopt;
  }
  T sample = std::move(impl_->queue.front());
  impl_->queue.pop_front();
  ++impl_->counters.taken;
  return sample;
}

template <class T>
std::vector<T> Reader<T>::TakeAll() {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  std::vector<T> all(std::make_move_iterator(impl_->queue.begin()),
                     std::make_move_iterator(impl_->queue.end()));
  impl_->queue.clear();
  impl_->counters.taken += all.size();
  return all;
}

template <class T>
ReaderCounters Reader<T>::counters() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->counters;
}

template <class T>
int Reader<T>::Matched() const {
  fdds::SubscriptionMatchedStatus status;
  impl_->reader->get_subscription_matched_status(status);
  return status.current_count;
}

template <class T>
bool Reader<T>::WaitForMatched(int writers, Millis timeout) const {
  return PollUntil(timeout, [&] { return Matched() >= writers; });
}

template <class T>
std::uint64_t Reader<T>::rejected_version() const {
  return impl_->rejected.load();
}

#define ARENA_DDS_INSTANTIATE(T) \
  template class Writer<T>;      \
  template class Reader<T>;      \
  template const char* TopicName<T>();
ARENA_DDS_INSTANTIATE(msg::CellAnnounce)
ARENA_DDS_INSTANTIATE(msg::TrialCommand)
ARENA_DDS_INSTANTIATE(msg::TrialStatus)
ARENA_DDS_INSTANTIATE(msg::GroundTruth)
ARENA_DDS_INSTANTIATE(msg::LiveState)
ARENA_DDS_INSTANTIATE(msg::PusherCommand)
#undef ARENA_DDS_INSTANTIATE

}  // namespace arena::dds
