#include "dds_options.hpp"

namespace arena::cli {

dds::NetworkOptions DdsCliOptions::Network() const {
  dds::NetworkOptions n = network;
  if (!peers.empty()) n.peers = dds::ParsePeers(peers);
  return n;
}

void AddDdsOptions(CLI::App* cmd, DdsCliOptions* o, const std::string& security_help) {
  cmd->add_option("--domain", o->domain,
                  "DDS domain id (0.." + std::to_string(dds::kMaxDomainId) + ")")
      ->required()
      ->check(CLI::Range(0, dds::kMaxDomainId));
  cmd->add_option("--peers", o->peers, "Reach other hosts: initial peers host[:port],...");
  cmd->add_option("--discovery-server", o->network.discovery_server,
                  "Reach other hosts through a Fast DDS discovery server [id@]host:port");
  cmd->add_option("--profile-xml", o->network.profile_xml,
                  "Fast DDS XML profile file (its default participant profile sets transports)");
  cmd->add_option("--security", o->network.security_dir, "DDS-Security: " + security_help);
  cmd->add_flag("--shm,!--no-shm", o->network.shared_memory,
                std::string("Use the shared-memory transport beside UDP (default: ") +
                    (o->network.shared_memory ? "on" : "off") + ")");
}

}  // namespace arena::cli
