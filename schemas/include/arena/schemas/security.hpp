// DDS-Security for arena: a lab certificate authority, identities for cells,
// services and watchers, and the participant set-up that uses them
// (Fast DDS 2.9 builtin plugins: PKI-DH, Access-Permissions, AES-GCM-GMAC).
//
// Definitions
//   lab        a directory made by InitLab: the lab CA and the signed
//              governance document every participant of the lab shares.
//                ca.key.pem       CA private key (EC P-256, mode 0600): keep it
//                                 off the lab's hosts once identities are issued
//                ca.cert.pem      CA certificate (self-signed): identity CA and
//                                 permissions CA of every participant
//                governance.xml   the rules, readable
//                governance.p7s   the same, signed by the CA (S/MIME, detached)
//   identity   a directory LAB/NAME made by IssueIdentity: all one participant
//              needs, and what `--security DIR` points to.
//                ca.cert.pem, governance.p7s   copies from the lab
//                identity.cert.pem   subject "CN=NAME,OU=ROLE,O=LAB", signed by the CA
//                identity.key.pem    its private key (EC P-256, mode 0600)
//                permissions.xml     the grant for ROLE, readable
//                permissions.p7s     the same, signed by the CA
//   role       what an identity may do on the arena topics (access control):
//                cell     publish CellAnnounce, TrialStatus, GroundTruth;
//                         subscribe TrialCommand
//                service  publish TrialCommand; subscribe CellAnnounce,
//                         TrialStatus, GroundTruth
//                watcher  subscribe CellAnnounce, TrialStatus, GroundTruth;
//                         publish nothing
//                controller N  publish PusherCommand.N only (its name's
//                         own topic, dds::ControllerTopic: the name is bound
//                         to the identity); subscribe CellAnnounce, LiveState
//              (the table in SECURITY.md is complete: cells also publish
//              LiveState and subscribe PusherCommand and PusherCommand.*).
//              Everything not granted is denied (<default>DENY</default>).
//
// Governance (one rule for the lab's domain range)
//   allow_unauthenticated_participants false, enable_join_access_control true:
//   a participant that cannot prove an identity from the lab CA, with valid
//   permissions signed by it, is never matched.
//   rtps_protection SIGN: every RTPS message carries a MAC under the pair's
//   session key, so nobody outside the lab can inject or alter traffic
//   (heartbeats, acknowledgements and gaps included).
//   discovery and liveliness protection ENCRYPT; per topic: read and write
//   access control on, metadata SIGN, data ENCRYPT (AES-GCM payloads).
//
// Invariants
//   1. InitLab never overwrites an existing CA; IssueIdentity never overwrites
//      an existing identity.
//   2. The grant's subject_name is the certificate's subject printed as
//      RFC 2253 by OpenSSL, so the two always match (Fast DDS compares them).
//   3. Private keys are written with mode 0600 from the start (O_EXCL).
//   4. CheckIdentityDir verifies what Fast DDS will verify (every file
//      present and readable, certificate chain and dates, key matches the
//      certificate, both documents signed by the CA, the grant names the
//      certificate's subject) and names the file at fault.
#pragma once

#include <string>
#include <vector>

#include "arena/schemas/dds.hpp"

namespace arena::dds {

// A lab or identity directory is missing, unreadable, inconsistent, or would
// be overwritten. what() names the file and the reason.
class SecurityError : public DdsError {
 public:
  // A missing, unreadable or mismatched identity is the user's input.
  explicit SecurityError(const std::string& what, ErrorCategory category = ErrorCategory::kBadInput)
      : DdsError(what, category) {}
};

enum class Role { kCell, kService, kWatcher, kController };
const char* ToString(Role role);
// "cell", "service", "watcher", "controller". @throws SecurityError naming the choices.
Role ParseRole(const std::string& text);

// The topics a role may publish and subscribe (access control grant).
struct RoleTopics {
  std::vector<std::string> publish;
  std::vector<std::string> subscribe;
};
RoleTopics TopicsOf(Role role);

struct LabOptions {
  std::string lab_name = "arena lab";  // O= of every subject ([A-Za-z0-9 _.-], 1..64)
  int valid_days = 3650;               // CA certificate lifetime (days, 1..36500)
  int domain_min = 0;  // governance applies to domains [min, max] (0..231, dds::kMaxDomainId)
  int domain_max = 231;
};

struct IdentityOptions {
  Role role = Role::kCell;
  std::string name;      // [A-Za-z0-9_.-], 1..64; also the directory name and, for a
                         // controller, the controller name it may publish as
  int valid_days = 730;  // certificate and grant lifetime (days, 1..36500)
  int domain_min = 0;    // the grant covers domains [min, max] (0..231, dds::kMaxDomainId)
  int domain_max = 231;
};

// File names inside a lab and an identity directory.
inline constexpr const char* kCaKeyFile = "ca.key.pem";
inline constexpr const char* kCaCertFile = "ca.cert.pem";
inline constexpr const char* kGovernanceXmlFile = "governance.xml";
inline constexpr const char* kGovernanceFile = "governance.p7s";
inline constexpr const char* kIdentityCertFile = "identity.cert.pem";
inline constexpr const char* kIdentityKeyFile = "identity.key.pem";
inline constexpr const char* kPermissionsXmlFile = "permissions.xml";
inline constexpr const char* kPermissionsFile = "permissions.p7s";

// Creates the lab CA and the signed governance document in dir (created if
// missing). @throws SecurityError when dir already holds a CA or a file
// cannot be written; std::invalid_argument for a bad option (named).
void InitLab(const std::string& dir, const LabOptions& options);

// Issues an identity and its role's permissions into lab_dir/NAME.
// @returns that directory. @throws SecurityError when the lab is incomplete
// or NAME exists; std::invalid_argument for a bad option (named).
std::string IssueIdentity(const std::string& lab_dir, const IdentityOptions& options);

// Absolute paths of the files one participant needs.
struct IdentityFiles {
  std::string ca_cert, governance, cert, key, permissions;
};

// Why an identity may not have a DataWriter (publish) or DataReader of
// `topic`: the role its grant names, and the roles that may ("--security
// lab/w: this identity's role 'watcher' may not publish TrialCommand; a
// 'service' identity may (arena certs issue LAB --role service --name N)").
std::string DeniedEndpoint(const std::string& identity_dir, const std::string& topic, bool publish);

// Checks an identity directory (invariant 4). @throws SecurityError naming
// the file at fault.
IdentityFiles CheckIdentityDir(const std::string& dir);

// The content of an S/MIME signed document (governance.p7s,
// permissions.p7s) if it verifies against the CA certificate file.
// @throws SecurityError naming the file otherwise.
std::string VerifySignedDocument(const std::string& p7s_path, const std::string& ca_cert_path);

// The certificate's subject, RFC 2253 ("CN=c1,OU=cell,O=arena lab").
// @throws SecurityError when the file is not a PEM certificate.
std::string CertificateSubject(const std::string& cert_path);

}  // namespace arena::dds
