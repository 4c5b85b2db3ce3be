// The lab CA, identities and permissions (OpenSSL 3 libcrypto); contract and
// file layout in schemas/include/arena/schemas/security.hpp.
#include "arena/schemas/security.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <memory>
#include <sstream>
#include <stdexcept>

#include <openssl/bio.h>
#include <openssl/bn.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>
#include <spdlog/spdlog.h>

#include "arena/schemas/arena.h"

namespace arena::dds {

namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------------------
// OpenSSL handles

template <class T, void (*Free)(T*)>
struct Freer {
  void operator()(T* p) const { Free(p); }
};
using PkeyPtr = std::unique_ptr<EVP_PKEY, Freer<EVP_PKEY, EVP_PKEY_free>>;
using PkeyCtxPtr = std::unique_ptr<EVP_PKEY_CTX, Freer<EVP_PKEY_CTX, EVP_PKEY_CTX_free>>;
using X509Ptr = std::unique_ptr<X509, Freer<X509, X509_free>>;
using StorePtr = std::unique_ptr<X509_STORE, Freer<X509_STORE, X509_STORE_free>>;
using StoreCtxPtr = std::unique_ptr<X509_STORE_CTX, Freer<X509_STORE_CTX, X509_STORE_CTX_free>>;
using BioPtr = std::unique_ptr<BIO, Freer<BIO, BIO_free_all>>;
using Pkcs7Ptr = std::unique_ptr<PKCS7, Freer<PKCS7, PKCS7_free>>;
using BnPtr = std::unique_ptr<BIGNUM, Freer<BIGNUM, BN_free>>;
using ExtPtr = std::unique_ptr<X509_EXTENSION, Freer<X509_EXTENSION, X509_EXTENSION_free>>;

// The oldest queued OpenSSL error as text (and the queue cleared).
std::string OpenSslError() {
  const unsigned long code = ERR_get_error();
  ERR_clear_error();
  if (code == 0) return "unknown OpenSSL error";
  char buf[256];
  ERR_error_string_n(code, buf, sizeof buf);
  return buf;
}

[[noreturn]] void Fail(const std::string& what) {
  throw SecurityError(what + ": " + OpenSslError());
}

std::string BioText(BIO* bio) {
  BUF_MEM* mem = nullptr;
  BIO_get_mem_ptr(bio, &mem);
  return mem == nullptr ? std::string() : std::string(mem->data, mem->length);
}

PkeyPtr GenerateEcKey() {
  PkeyCtxPtr ctx(EVP_PKEY_CTX_new_from_name(nullptr, "EC", nullptr));
  if (!ctx || EVP_PKEY_keygen_init(ctx.get()) <= 0 ||
      EVP_PKEY_CTX_set_group_name(ctx.get(), "P-256") <= 0) {
    Fail("EC P-256 key generation");
  }
  EVP_PKEY* key = nullptr;
  if (EVP_PKEY_generate(ctx.get(), &key) <= 0) Fail("EC P-256 key generation");
  return PkeyPtr(key);
}

void AddExtension(X509* cert, X509* issuer, int nid, const char* value) {
  X509V3_CTX ctx;
  X509V3_set_ctx_nodb(&ctx);
  X509V3_set_ctx(&ctx, issuer, cert, nullptr, nullptr, 0);
  ExtPtr ext(X509V3_EXT_conf_nid(nullptr, &ctx, nid, value));
  if (!ext || X509_add_ext(cert, ext.get(), -1) != 1)
    Fail(std::string("certificate extension ") + value);
}

struct Subject {
  std::string organization, unit, common_name;  // unit may be empty
};

// A certificate for subject_key, signed by issuer_key (issuer == nullptr:
// self-signed). A CA may sign certificates and documents; an identity may
// sign (the authentication handshake) and agree keys.
X509Ptr MakeCertificate(const Subject& subject, EVP_PKEY* subject_key, X509* issuer,
                        EVP_PKEY* issuer_key, int valid_days, bool ca) {
  X509Ptr cert(X509_new());
  if (!cert || X509_set_version(cert.get(), 2) != 1) Fail("X509_new");
  // A random 127-bit serial: unique without keeping a counter file.
  BnPtr serial(BN_new());
  if (!serial || BN_rand(serial.get(), 127, BN_RAND_TOP_ANY, BN_RAND_BOTTOM_ANY) != 1 ||
      BN_to_ASN1_INTEGER(serial.get(), X509_get_serialNumber(cert.get())) == nullptr) {
    Fail("certificate serial number");
  }
  // Valid from 5 minutes ago: hosts whose clocks differ a little still agree.
  if (X509_gmtime_adj(X509_getm_notBefore(cert.get()), -300) == nullptr ||
      X509_time_adj_ex(X509_getm_notAfter(cert.get()), valid_days, 0, nullptr) == nullptr) {
    Fail("certificate validity");
  }
  X509_NAME* name = X509_get_subject_name(cert.get());
  auto add = [&](const char* field, const std::string& value) {
    if (value.empty()) return;
    if (X509_NAME_add_entry_by_txt(name, field, MBSTRING_UTF8,
                                   reinterpret_cast<const unsigned char*>(value.c_str()), -1, -1,
                                   0) != 1) {
      Fail(std::string("certificate subject ") + field);
    }
  };
  add("O", subject.organization);
  add("OU", subject.unit);
  add("CN", subject.common_name);
  X509* signer = issuer == nullptr ? cert.get() : issuer;
  if (X509_set_issuer_name(cert.get(), X509_get_subject_name(signer)) != 1 ||
      X509_set_pubkey(cert.get(), subject_key) != 1) {
    Fail("certificate issuer/key");
  }
  if (ca) {
    AddExtension(cert.get(), signer, NID_basic_constraints, "critical,CA:TRUE");
    // digitalSignature: the CA also signs the governance and permissions
    // documents (S/MIME verification checks the signer's key usage).
    AddExtension(cert.get(), signer, NID_key_usage,
                 "critical,digitalSignature,keyCertSign,cRLSign");
  } else {
    AddExtension(cert.get(), signer, NID_basic_constraints, "critical,CA:FALSE");
    AddExtension(cert.get(), signer, NID_key_usage, "critical,digitalSignature,keyAgreement");
  }
  AddExtension(cert.get(), signer, NID_subject_key_identifier, "hash");
  if (!ca) AddExtension(cert.get(), signer, NID_authority_key_identifier, "keyid:always");
  if (X509_sign(cert.get(), issuer_key, EVP_sha256()) <= 0) Fail("certificate signature");
  return cert;
}

std::string CertPem(X509* cert) {
  BioPtr out(BIO_new(BIO_s_mem()));
  if (!out || PEM_write_bio_X509(out.get(), cert) != 1) Fail("PEM certificate");
  return BioText(out.get());
}

std::string KeyPem(EVP_PKEY* key) {
  BioPtr out(BIO_new(BIO_s_mem()));
  if (!out ||
      PEM_write_bio_PrivateKey(out.get(), key, nullptr, nullptr, 0, nullptr, nullptr) != 1) {
    Fail("PEM private key");
  }
  return BioText(out.get());
}

// The document signed by cert/key as S/MIME with a detached signature and a
// text/plain part: what `openssl smime -sign -text` writes and what Fast
// DDS reads (SMIME_read_PKCS7, PKCS7_verify with PKCS7_TEXT).
std::string SignSmime(const std::string& document, X509* cert, EVP_PKEY* key) {
  const int flags = PKCS7_DETACHED | PKCS7_TEXT;
  BioPtr data(BIO_new_mem_buf(document.data(), static_cast<int>(document.size())));
  if (!data) Fail("S/MIME signature");
  Pkcs7Ptr p7(PKCS7_sign(cert, key, nullptr, data.get(), flags));
  if (!p7) Fail("S/MIME signature");
  BioPtr again(BIO_new_mem_buf(document.data(), static_cast<int>(document.size())));
  BioPtr out(BIO_new(BIO_s_mem()));
  if (!again || !out || SMIME_write_PKCS7(out.get(), p7.get(), again.get(), flags) != 1) {
    Fail("S/MIME output");
  }
  return BioText(out.get());
}

// ---------------------------------------------------------------------------
// Files

std::string Join(const std::string& dir, const char* file) {
  return (fs::path(dir) / file).string();
}

// Creates path with mode; refuses to replace an existing file.
void WriteNewFile(const std::string& path, const std::string& content, mode_t mode) {
  const int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode);
  if (fd < 0) {
    if (errno == EEXIST) throw SecurityError(path + ": exists already; refusing to overwrite it");
    throw SecurityError(path + ": cannot create: " + std::strerror(errno));
  }
  std::size_t done = 0;
  while (done < content.size()) {
    const ssize_t n = write(fd, content.data() + done, content.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string why = std::strerror(errno);
      close(fd);
      throw SecurityError(path + ": cannot write: " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  if (fsync(fd) != 0 || close(fd) != 0)
    throw SecurityError(path + ": cannot write: " + std::strerror(errno));
}

// The file's bytes; SecurityError naming it when missing or unreadable.
std::string ReadRequired(const std::string& path, const std::string& what) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw SecurityError(path + ": missing (" + what + ")");
  if (!fs::is_regular_file(path, ec))
    throw SecurityError(path + ": not a regular file (" + what + ")");
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw SecurityError(path + ": cannot be read: " + std::strerror(errno) + " (" + what + ")");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw SecurityError(path + ": cannot be read (" + what + ")");
  return text.str();
}

X509Ptr ReadCertificate(const std::string& path, const std::string& what) {
  const std::string pem = ReadRequired(path, what);
  BioPtr in(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  X509Ptr cert(in ? PEM_read_bio_X509(in.get(), nullptr, nullptr, nullptr) : nullptr);
  if (!cert) {
    ERR_clear_error();
    throw SecurityError(path + ": not a PEM certificate (" + what + ")");
  }
  return cert;
}

PkeyPtr ReadPrivateKey(const std::string& path, const std::string& what) {
  const std::string pem = ReadRequired(path, what);
  BioPtr in(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  // An empty passphrase callback result: encrypted keys are refused instead
  // of prompting on a terminal (Fast DDS would need the password property).
  PkeyPtr key(in ? PEM_read_bio_PrivateKey(
                       in.get(), nullptr, [](char*, int, int, void*) { return 0; }, nullptr)
                 : nullptr);
  if (!key) {
    ERR_clear_error();
    throw SecurityError(path + ": not an unencrypted PEM private key (" + what + ")");
  }
  return key;
}

std::string NameRfc2253(X509_NAME* name) {
  BioPtr out(BIO_new(BIO_s_mem()));
  if (!out || X509_NAME_print_ex(out.get(), name, 0, XN_FLAG_RFC2253) < 0) Fail("subject name");
  return BioText(out.get());
}

// The value of the first field (e.g. "O") of a name; "" if absent.
std::string NameField(X509_NAME* name, int nid) {
  const int at = X509_NAME_get_index_by_NID(name, nid, -1);
  if (at < 0) return "";
  ASN1_STRING* data = X509_NAME_ENTRY_get_data(X509_NAME_get_entry(name, at));
  unsigned char* utf8 = nullptr;
  const int n = ASN1_STRING_to_UTF8(&utf8, data);
  if (n < 0) return "";
  std::string value(reinterpret_cast<char*>(utf8), static_cast<std::size_t>(n));
  OPENSSL_free(utf8);
  return value;
}

// ---------------------------------------------------------------------------
// Options and documents

void CheckName(const std::string& value, const std::string& field, bool spaces) {
  if (value.empty() || value.size() > 64) {
    throw std::invalid_argument(field + ": must be 1..64 characters, got '" + value + "'");
  }
  for (const char c : value) {
    const bool ok = std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' ||
                    c == '-' || (spaces && c == ' ');
    if (!ok) {
      throw std::invalid_argument(field + ": '" + value +
                                  "' may only hold letters, digits, '_', '.', '-'" +
                                  (spaces ? ", ' '" : ""));
    }
  }
  if (value == "." || value == "..")
    throw std::invalid_argument(field + ": '" + value + "' is not a name");
  if (value.front() == ' ' || value.back() == ' ') {
    throw std::invalid_argument(field + ": '" + value + "' may not start or end with a space");
  }
}

void CheckDays(int days, const std::string& field) {
  if (days < 1 || days > 36500) {
    throw std::invalid_argument(field + ": must be 1..36500 days, got " + std::to_string(days));
  }
}

void CheckDomains(int min, int max, const std::string& field) {
  if (min < 0 || max > kMaxDomainId || min > max) {
    throw std::invalid_argument(field + ": want MIN-MAX within 0.." + std::to_string(kMaxDomainId) +
                                ", got " + std::to_string(min) + "-" + std::to_string(max));
  }
}

std::string IsoUtc(std::time_t t) {
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
  return buf;
}

std::string DomainsXml(int min, int max, const char* indent) {
  std::ostringstream x;
  x << indent << "<domains>\n"
    << indent << "  <id_range><min>" << min << "</min><max>" << max << "</max></id_range>\n"
    << indent << "</domains>\n";
  return x.str();
}

// The real-time topics (LiveState, PusherCommand: 4 000 messages/s each at
// 16 cells x 250 Hz) carry no submessage MAC of their own: every RTPS message
// is already signed with its sending participant's key (rtps_protection_kind
// SIGN; a key every authenticated lab participant holds, so it authenticates
// the lab, not the sender: SECURITY.md), and the payload stays AES-GCM
// encrypted and authenticated with the writer's key, which only its matched
// readers hold. The third crypto operation per message and receiver
// halved the secured control loop's answered samples (bench/README.md);
// access control is the same as on every topic. The first matching rule
// applies, so these come before "*".
std::string RealTimeTopicRules() {
  std::ostringstream x;
  for (const char* topic : {"LiveState", "PusherCommand"}) {
    x << "        <topic_rule>\n"
      << "          <topic_expression>" << topic << "</topic_expression>\n"
      << "          <enable_discovery_protection>true</enable_discovery_protection>\n"
      << "          <enable_liveliness_protection>true</enable_liveliness_protection>\n"
      << "          <enable_read_access_control>true</enable_read_access_control>\n"
      << "          <enable_write_access_control>true</enable_write_access_control>\n"
      << "          <metadata_protection_kind>NONE</metadata_protection_kind>\n"
      << "          <data_protection_kind>ENCRYPT</data_protection_kind>\n"
      << "        </topic_rule>\n";
  }
  return x.str();
}

std::string GovernanceXml(const LabOptions& o) {
  std::ostringstream x;
  x << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<!-- arena lab governance (arena certs init; schemas/include/arena/schemas/security.hpp) "
       "-->\n"
    << "<dds xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\"\n"
    << "     "
       "xsi:noNamespaceSchemaLocation=\"http://www.omg.org/spec/DDS-SECURITY/20170901/"
       "omg_shared_ca_governance.xsd\">\n"
    << "  <domain_access_rules>\n"
    << "    <domain_rule>\n"
    << DomainsXml(o.domain_min, o.domain_max, "      ")
    << "      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>\n"
    << "      <enable_join_access_control>true</enable_join_access_control>\n"
    << "      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>\n"
    << "      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>\n"
    << "      <rtps_protection_kind>SIGN</rtps_protection_kind>\n"
    << "      <topic_access_rules>\n"
    << RealTimeTopicRules() << "        <topic_rule>\n"
    << "          <topic_expression>*</topic_expression>\n"
    << "          <enable_discovery_protection>true</enable_discovery_protection>\n"
    << "          <enable_liveliness_protection>true</enable_liveliness_protection>\n"
    << "          <enable_read_access_control>true</enable_read_access_control>\n"
    << "          <enable_write_access_control>true</enable_write_access_control>\n"
    << "          <metadata_protection_kind>SIGN</metadata_protection_kind>\n"
    << "          <data_protection_kind>ENCRYPT</data_protection_kind>\n"
    << "        </topic_rule>\n"
    << "      </topic_access_rules>\n"
    << "    </domain_rule>\n"
    << "  </domain_access_rules>\n"
    << "</dds>\n";
  return x.str();
}

// One <publish>/<subscribe> per topic: some Fast DDS 2.x parsers keep only
// the last <topic> of a <topics> list.
std::string PermissionsXml(const IdentityOptions& o, const std::string& subject,
                           std::time_t not_before, std::time_t not_after) {
  RoleTopics topics = TopicsOf(o.role);
  // The controller's name bound to its identity: it may publish pusher
  // commands on its own name's topic, which is the only one a cell running
  // its scenes reads (dds.hpp, ControllerTopic).
  if (o.role == Role::kController) topics.publish.push_back(ControllerTopic(o.name));
  std::ostringstream x;
  x << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<!-- arena " << ToString(o.role) << " permissions (arena certs issue) -->\n"
    << "<dds xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\"\n"
    << "     "
       "xsi:noNamespaceSchemaLocation=\"http://www.omg.org/spec/DDS-SECURITY/20170901/"
       "omg_shared_ca_permissions.xsd\">\n"
    << "  <permissions>\n"
    << "    <grant name=\"" << ToString(o.role) << "." << o.name << "\">\n"
    << "      <subject_name>" << subject << "</subject_name>\n"
    << "      <validity>\n"
    << "        <not_before>" << IsoUtc(not_before) << "</not_before>\n"
    << "        <not_after>" << IsoUtc(not_after) << "</not_after>\n"
    << "      </validity>\n"
    << "      <allow_rule>\n"
    << DomainsXml(o.domain_min, o.domain_max, "        ");
  for (const auto& t : topics.publish) {
    x << "        <publish><topics><topic>" << t << "</topic></topics></publish>\n";
  }
  for (const auto& t : topics.subscribe) {
    x << "        <subscribe><topics><topic>" << t << "</topic></topics></subscribe>\n";
  }
  x << "      </allow_rule>\n"
    << "      <default>DENY</default>\n"
    << "    </grant>\n"
    << "  </permissions>\n"
    << "</dds>\n";
  return x.str();
}

// Text between <tag> and </tag>; "" when absent.
std::string XmlElement(const std::string& xml, const std::string& tag) {
  const auto open = xml.find("<" + tag + ">");
  if (open == std::string::npos) return "";
  const auto start = open + tag.size() + 2;
  const auto close = xml.find("</" + tag + ">", start);
  if (close == std::string::npos) return "";
  return xml.substr(start, close - start);
}

// "CN = a, O=b" and "CN=a,O=b" compare equal (Fast DDS compares RFC 2253
// names leniently about spaces around separators).
std::string NormalizeDn(const std::string& dn) {
  std::string out;
  for (std::size_t i = 0; i < dn.size(); ++i) {
    const char c = dn[i];
    if (c == ' ') {
      const char prev = out.empty() ? ',' : out.back();
      std::size_t j = i;
      while (j < dn.size() && dn[j] == ' ') ++j;
      const char next = j < dn.size() ? dn[j] : ',';
      if (prev == ',' || prev == '=' || next == ',' || next == '=') continue;
    }
    out.push_back(c);
  }
  return out;
}

std::time_t ParseIsoUtc(const std::string& text) {
  std::tm tm{};
  std::istringstream in(text);
  in >> std::get_time(&tm, "%Y-%m-%dT%H:%M:%S");
  if (in.fail()) return static_cast<std::time_t>(-1);
  return timegm(&tm);
}

}  // namespace

// ---------------------------------------------------------------------------
// Roles

const char* ToString(Role role) {
  switch (role) {
    case Role::kCell:
      return "cell";
    case Role::kService:
      return "service";
    case Role::kWatcher:
      return "watcher";
    case Role::kController:
      return "controller";
  }
  return "?";
}

Role ParseRole(const std::string& text) {
  if (text == "cell") return Role::kCell;
  if (text == "service") return Role::kService;
  if (text == "watcher") return Role::kWatcher;
  if (text == "controller") return Role::kController;
  throw SecurityError("--role: '" + text + "' is not one of cell, service, watcher, controller");
}

RoleTopics TopicsOf(Role role) {
  const std::string announce = TopicName<msg::CellAnnounce>();
  const std::string command = TopicName<msg::TrialCommand>();
  const std::string status = TopicName<msg::TrialStatus>();
  const std::string truth = TopicName<msg::GroundTruth>();
  const std::string live = TopicName<msg::LiveState>();
  const std::string pusher = TopicName<msg::PusherCommand>();
  switch (role) {
    case Role::kCell:  // pusher commands: of whichever controller its scene names
      return {{announce, status, truth, live}, {command, pusher, ControllerTopic("*")}};
    case Role::kService:
      return {{command}, {announce, status, truth, live}};
    case Role::kWatcher:
      return {{}, {announce, status, truth, live}};
    case Role::kController:  // reads what the cells see, answers with pusher commands on
                             // its own name's topic only (PermissionsXml adds it)
      return {{}, {announce, live}};
  }
  return {};
}

// ---------------------------------------------------------------------------
// Lab and identities

void InitLab(const std::string& dir, const LabOptions& options) {
  CheckName(options.lab_name, "--lab", true);
  CheckDays(options.valid_days, "--days");
  CheckDomains(options.domain_min, options.domain_max, "--domains");
  const std::string key_path = Join(dir, kCaKeyFile), cert_path = Join(dir, kCaCertFile);
  for (const std::string& path : {key_path, cert_path}) {
    std::error_code ec;
    if (fs::exists(path, ec)) {
      throw SecurityError(path +
                          ": this directory holds a lab CA already; refusing to overwrite it "
                          "(issue identities from it with `arena certs issue`)");
    }
  }
  for (const char* file : {kGovernanceXmlFile, kGovernanceFile}) {  // nothing half-made
    std::error_code ec;
    if (fs::exists(Join(dir, file), ec)) {
      throw SecurityError(Join(dir, file) +
                          ": exists already (a lab's remains?); refusing to overwrite it");
    }
  }
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw SecurityError(dir + ": cannot create the directory: " + ec.message());

  PkeyPtr key = GenerateEcKey();
  X509Ptr cert = MakeCertificate({options.lab_name, "", options.lab_name + " CA"}, key.get(),
                                 nullptr, key.get(), options.valid_days, /*ca=*/true);
  const std::string governance = GovernanceXml(options);
  const std::string signed_governance = SignSmime(governance, cert.get(), key.get());
  // The key first, exclusively: two concurrent inits cannot both succeed.
  WriteNewFile(key_path, KeyPem(key.get()), 0600);
  WriteNewFile(cert_path, CertPem(cert.get()), 0644);
  WriteNewFile(Join(dir, kGovernanceXmlFile), governance, 0644);
  WriteNewFile(Join(dir, kGovernanceFile), signed_governance, 0644);
  VerifySignedDocument(Join(dir, kGovernanceFile), cert_path);  // what every participant will check
}

std::string IssueIdentity(const std::string& lab_dir, const IdentityOptions& options) {
  CheckName(options.name, "--name", false);
  CheckDays(options.valid_days, "--days");
  CheckDomains(options.domain_min, options.domain_max, "--domains");
  const std::string lab_what = "a lab directory from `arena certs init`";
  PkeyPtr ca_key = ReadPrivateKey(Join(lab_dir, kCaKeyFile), lab_what);
  X509Ptr ca_cert = ReadCertificate(Join(lab_dir, kCaCertFile), lab_what);
  if (X509_check_private_key(ca_cert.get(), ca_key.get()) != 1) {
    ERR_clear_error();
    throw SecurityError(Join(lab_dir, kCaKeyFile) + ": does not belong to " +
                        Join(lab_dir, kCaCertFile));
  }
  const std::string governance = ReadRequired(Join(lab_dir, kGovernanceFile), lab_what);
  const std::string lab_name =
      NameField(X509_get_subject_name(ca_cert.get()), NID_organizationName);

  const std::string dir = (fs::path(lab_dir) / options.name).string();
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_empty(dir, ec)) {
    throw SecurityError(dir +
                        ": an identity of that name exists already; refusing to overwrite it "
                        "(remove the directory to re-issue it)");
  }
  fs::create_directories(dir, ec);
  if (ec) throw SecurityError(dir + ": cannot create the directory: " + ec.message());
  fs::permissions(dir, fs::perms::owner_all, ec);  // the key's directory: owner only

  PkeyPtr key = GenerateEcKey();
  X509Ptr cert = MakeCertificate({lab_name, ToString(options.role), options.name}, key.get(),
                                 ca_cert.get(), ca_key.get(), options.valid_days, /*ca=*/false);
  const std::string subject = NameRfc2253(X509_get_subject_name(cert.get()));
  const std::time_t now = std::time(nullptr);
  const std::string permissions = PermissionsXml(
      options, subject, now - 300, now + static_cast<std::time_t>(options.valid_days) * 86400);
  const std::string signed_permissions = SignSmime(permissions, ca_cert.get(), ca_key.get());

  WriteNewFile(Join(dir, kIdentityKeyFile), KeyPem(key.get()), 0600);
  WriteNewFile(Join(dir, kIdentityCertFile), CertPem(cert.get()), 0644);
  WriteNewFile(Join(dir, kCaCertFile), CertPem(ca_cert.get()), 0644);
  WriteNewFile(Join(dir, kGovernanceFile), governance, 0644);
  WriteNewFile(Join(dir, kPermissionsXmlFile), permissions, 0644);
  WriteNewFile(Join(dir, kPermissionsFile), signed_permissions, 0644);
  CheckIdentityDir(dir);  // what the participant will check
  return dir;
}

std::string CertificateSubject(const std::string& cert_path) {
  X509Ptr cert = ReadCertificate(cert_path, "a certificate");
  return NameRfc2253(X509_get_subject_name(cert.get()));
}

std::string VerifySignedDocument(const std::string& p7s_path, const std::string& ca_cert_path) {
  const std::string what = "an S/MIME document signed by the lab CA";
  const std::string text = ReadRequired(p7s_path, what);
  X509Ptr ca = ReadCertificate(ca_cert_path, "the lab CA certificate");
  BioPtr in(BIO_new_mem_buf(text.data(), static_cast<int>(text.size())));
  BIO* content = nullptr;
  Pkcs7Ptr p7(in ? SMIME_read_PKCS7(in.get(), &content) : nullptr);
  BioPtr content_owner(content);
  if (!p7) {
    ERR_clear_error();
    throw SecurityError(p7s_path + ": not S/MIME (" + what + ")");
  }
  StorePtr store(X509_STORE_new());
  BioPtr out(BIO_new(BIO_s_mem()));
  if (!store || !out || X509_STORE_add_cert(store.get(), ca.get()) != 1) Fail("certificate store");
  // The check Fast DDS makes: the signer chains to the CA (S/MIME purpose),
  // the content is the signed text.
  if (PKCS7_verify(p7.get(), nullptr, store.get(), content, out.get(), PKCS7_TEXT) != 1) {
    throw SecurityError(p7s_path + ": signature does not verify against " + ca_cert_path + ": " +
                        OpenSslError());
  }
  return BioText(out.get());
}

std::string DeniedEndpoint(const std::string& identity_dir, const std::string& topic,
                           bool publish) {
  std::string role = "?", grant = "?";
  {
    std::ifstream in(Join(identity_dir, kPermissionsXmlFile));
    std::ostringstream text;
    text << in.rdbuf();
    const std::string xml = text.str();
    const auto at = xml.find("<grant name=\"");
    if (at != std::string::npos) {
      const auto begin = at + 13;
      const auto dot = xml.find_first_of(".\"", begin);
      if (dot != std::string::npos) role = xml.substr(begin, dot - begin);
      const auto quote = xml.find('"', begin);
      if (quote != std::string::npos) grant = xml.substr(begin, quote - begin);
    }
  }
  const std::string pusher = TopicName<msg::PusherCommand>();
  if (publish && topic.rfind(pusher + ".", 0) == 0) {  // a controller's own topic
    const std::string wanted = topic.substr(pusher.size() + 1);
    return "--security " + identity_dir + ": this identity (role '" + role + "', grant '" + grant +
           "') may not publish pusher commands as controller '" + wanted +
           "': a controller's name is bound to its identity; issue one for it (arena certs "
           "issue LAB --role controller --name " +
           wanted + ")";
  }
  std::string may;
  for (Role r : {Role::kCell, Role::kService, Role::kWatcher, Role::kController}) {
    const RoleTopics t = TopicsOf(r);
    const auto& list = publish ? t.publish : t.subscribe;
    if (std::find(list.begin(), list.end(), topic) == list.end()) continue;
    if (!may.empty()) may += " or ";
    may += std::string("'") + ToString(r) + "'";
  }
  const std::string verb = publish ? "publish" : "subscribe to";
  return "--security " + identity_dir + ": this identity's role '" + role + "' may not " + verb +
         " " + topic +
         (may.empty() ? std::string()
                      : "; a " + may + " identity may (arena certs issue LAB --role " +
                            may.substr(1, may.find('\'', 1) - 1) + " --name N)");
}

IdentityFiles CheckIdentityDir(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    throw SecurityError(dir +
                        ": not a directory (want an identity directory from `arena certs issue`)");
  }
  const std::string base = fs::absolute(dir, ec).lexically_normal().string();
  IdentityFiles f{Join(base, kCaCertFile), Join(base, kGovernanceFile),
                  Join(base, kIdentityCertFile), Join(base, kIdentityKeyFile),
                  Join(base, kPermissionsFile)};
  const std::string what = "an identity directory from `arena certs issue` holds " +
                           std::string(kCaCertFile) + ", " + kGovernanceFile + ", " +
                           kIdentityCertFile + ", " + kIdentityKeyFile + ", " + kPermissionsFile;
  for (const std::string& path : {f.ca_cert, f.governance, f.cert, f.key, f.permissions}) {
    ReadRequired(path, what);
  }
  X509Ptr ca = ReadCertificate(f.ca_cert, "the lab CA certificate");
  X509Ptr cert = ReadCertificate(f.cert, "this participant's certificate");
  PkeyPtr key = ReadPrivateKey(f.key, "this participant's private key");

  StorePtr store(X509_STORE_new());
  StoreCtxPtr ctx(X509_STORE_CTX_new());
  if (!store || !ctx || X509_STORE_add_cert(store.get(), ca.get()) != 1 ||
      X509_STORE_CTX_init(ctx.get(), store.get(), cert.get(), nullptr) != 1) {
    Fail("certificate store");
  }
  if (X509_verify_cert(ctx.get()) != 1) {
    const int error = X509_STORE_CTX_get_error(ctx.get());
    ERR_clear_error();
    throw SecurityError(f.cert + ": not valid under " + f.ca_cert + ": " +
                        X509_verify_cert_error_string(error));
  }
  if (X509_check_private_key(cert.get(), key.get()) != 1) {
    ERR_clear_error();
    throw SecurityError(f.key + ": does not belong to " + f.cert);
  }
  struct stat st {};
  if (stat(f.key.c_str(), &st) == 0 && (st.st_mode & 077) != 0) {
    spdlog::warn("{}: readable by others (mode {:o}); chmod 600 it", f.key, st.st_mode & 0777);
  }
  VerifySignedDocument(f.governance, f.ca_cert);
  const std::string permissions = VerifySignedDocument(f.permissions, f.ca_cert);
  const std::string subject = NameRfc2253(X509_get_subject_name(cert.get()));
  const std::string granted = XmlElement(permissions, "subject_name");
  if (NormalizeDn(granted) != NormalizeDn(subject)) {
    throw SecurityError(f.permissions + ": grants '" + granted + "', but " + f.cert + " is '" +
                        subject + "'");
  }
  const std::time_t not_after = ParseIsoUtc(XmlElement(permissions, "not_after"));
  if (not_after != static_cast<std::time_t>(-1) && not_after < std::time(nullptr)) {
    throw SecurityError(f.permissions + ": the grant expired on " + IsoUtc(not_after) + " UTC");
  }
  return f;
}

}  // namespace arena::dds
