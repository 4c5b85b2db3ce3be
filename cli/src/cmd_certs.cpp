// arena certs init LAB | arena certs issue LAB --role R --name N: the lab's
// DDS-Security material (schemas/include/arena/schemas/security.hpp).
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>

#include "arena/schemas/security.hpp"
#include "commands.hpp"

namespace arena::cli {
namespace {

struct CertsOptions {
  std::string dir;
  dds::LabOptions lab;
  std::string role;
  dds::IdentityOptions identity;
  std::string domains = "0-231";
};

// "A-B" or "A" -> [A, B].
void ParseDomains(const std::string& text, int* min, int* max) {
  const auto dash = text.find('-');
  try {
    std::size_t used = 0;
    const std::string a = text.substr(0, dash);
    *min = std::stoi(a, &used);
    if (used != a.size()) throw std::invalid_argument(a);
    *max = *min;
    if (dash != std::string::npos) {
      const std::string b = text.substr(dash + 1);
      *max = std::stoi(b, &used);
      if (used != b.size()) throw std::invalid_argument(b);
    }
  } catch (const std::exception&) {
    throw CommandError(kExitBadInput,
                       "--domains: want MIN-MAX (e.g. 0-231) or one id, got '" + text + "'");
  }
}

int RunInit(CertsOptions o) {
  ParseDomains(o.domains, &o.lab.domain_min, &o.lab.domain_max);
  try {
    dds::InitLab(o.dir, o.lab);
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, e.what());
  } catch (const dds::SecurityError& e) {
    throw CommandError(kExitFailure, e.what());
  }
  std::fprintf(stderr,
               "lab '%s': CA and signed governance (domains %d-%d) in %s\n"
               "keep %s/%s secret; issue identities with `arena certs issue %s --role "
               "cell|service|watcher --name NAME`\n",
               o.lab.lab_name.c_str(), o.lab.domain_min, o.lab.domain_max, o.dir.c_str(),
               o.dir.c_str(), dds::kCaKeyFile, o.dir.c_str());
  return kExitOk;
}

int RunIssue(CertsOptions o) {
  ParseDomains(o.domains, &o.identity.domain_min, &o.identity.domain_max);
  o.identity.role = dds::ParseRole(o.role);
  std::string dir;
  try {
    dir = dds::IssueIdentity(o.dir, o.identity);
  } catch (const std::invalid_argument& e) {
    throw CommandError(kExitBadInput, e.what());
  } catch (const dds::SecurityError& e) {
    throw CommandError(kExitFailure, e.what());
  }
  const auto topics = dds::TopicsOf(o.identity.role);
  auto list = [](const std::vector<std::string>& v) {
    std::string s;
    for (const auto& t : v) s += (s.empty() ? "" : ", ") + t;
    return s.empty() ? std::string("nothing") : s;
  };
  std::fprintf(stderr, "%s '%s' (%s): publishes %s; subscribes %s; valid %d days\n", o.role.c_str(),
               o.identity.name.c_str(),
               dds::CertificateSubject(dir + "/" + dds::kIdentityCertFile).c_str(),
               list(topics.publish).c_str(), list(topics.subscribe).c_str(), o.identity.valid_days);
  std::printf("%s\n", dir.c_str());  // for scripts: the directory to pass to --security
  return kExitOk;
}

}  // namespace

void AddCertsCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<CertsOptions>();
  CLI::App* cmd = app.add_subcommand(
      "certs", "DDS-Security: a lab CA, and identities for cells, services, watchers");
  cmd->require_subcommand(1);
  cmd->footer(
      "Example:\n"
      "  arena certs init lab-pki\n"
      "  arena certs issue lab-pki --role service --name service\n"
      "  arena certs issue lab-pki --role cell --name c1\n"
      "  arena serve --db lab.db --domain 42 --security lab-pki/service\n"
      "  arena cell --id c1 --domain 42 --security lab-pki/c1\n"
      "With --security, only participants holding an identity from this lab's CA are matched; a "
      "cell\n"
      "takes commands only from a 'service' identity, a 'watcher' may read but never command.\n"
      "See SECURITY.md (section 4).");

  CLI::App* init = cmd->add_subcommand("init", "Create a lab CA and its signed governance in DIR");
  init->footer(
      "Example:\n  arena certs init lab-pki --lab \"robot lab 2\" --days 3650\n"
      "Writes ca.key.pem (mode 0600: keep it off the cells' hosts), ca.cert.pem, governance.xml "
      "and\n"
      "governance.p7s (signed). Refuses to overwrite an existing CA.");
  init->add_option("dir", o->dir, "Lab directory (created if missing)")->required();
  init->add_option("--lab", o->lab.lab_name, "Lab name: the O= of every certificate")
      ->capture_default_str();
  init->add_option("--days", o->lab.valid_days, "CA certificate lifetime (days)")
      ->capture_default_str();
  init->add_option("--domains", o->domains, "DDS domain ids the governance covers: MIN-MAX")
      ->capture_default_str();
  init->callback([o, action] { *action = [o] { return RunInit(*o); }; });

  CLI::App* issue =
      cmd->add_subcommand("issue", "Issue an identity and its role's permissions into DIR/NAME");
  issue->footer(
      "Example:\n  arena certs issue lab-pki --role watcher --name alice --days 365\n"
      "Roles: cell (publishes CellAnnounce, TrialStatus, GroundTruth, LiveState; reads\n"
      "TrialCommand, PusherCommand), service (publishes TrialCommand; reads the cells' topics),\n"
      "watcher (reads CellAnnounce, TrialStatus, GroundTruth, LiveState; publishes nothing),\n"
      "controller (publishes PusherCommand; reads CellAnnounce, LiveState).\n"
      "Prints DIR/NAME, the directory for --security.\n"
      "Refuses to overwrite an identity: remove DIR/NAME to re-issue it.");
  issue->add_option("dir", o->dir, "Lab directory made by `arena certs init`")->required();
  issue->add_option("--role", o->role, "cell, service, watcher or controller")->required();
  issue
      ->add_option("--name", o->identity.name,
                   "Identity name ([A-Za-z0-9_.-]; a cell's id is a good choice)")
      ->required();
  issue->add_option("--days", o->identity.valid_days, "Certificate and grant lifetime (days)")
      ->capture_default_str();
  issue->add_option("--domains", o->domains, "DDS domain ids the grant covers: MIN-MAX")
      ->capture_default_str();
  issue->callback([o, action] { *action = [o] { return RunIssue(*o); }; });
}

}  // namespace arena::cli
