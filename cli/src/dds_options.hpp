// The options of every command that joins a DDS domain (cell, controller,
// serve, watch), written once: the same flag names, help and checks
// everywhere (issue 27).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "arena/schemas/dds.hpp"

namespace arena::cli {

struct DdsCliOptions {
  int domain = -1;
  std::string peers;            // "host[:port],...", parsed by Network()
  dds::NetworkOptions network;  // network.shared_memory's default is the command's

  // `network` with --peers parsed.
  // @throws dds::DdsError (bad input) naming --peers and the bad entry.
  dds::NetworkOptions Network() const;
};

// Adds --domain (required, 0..dds::kMaxDomainId: a parse error, exit 2),
// --peers, --discovery-server, --profile-xml, --security (`security_help`
// says which identity the command wants) and --shm / --no-shm (default:
// o->network.shared_memory as the caller set it).
void AddDdsOptions(CLI::App* cmd, DdsCliOptions* o, const std::string& security_help);

}  // namespace arena::cli
