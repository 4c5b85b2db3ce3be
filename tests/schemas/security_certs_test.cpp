// The DDS-Security material on its own: a lab CA and identities from
// `arena certs` and the library, checked the way Fast DDS checks them
// (chain, key, S/MIME signatures, subject names), and every broken or
// missing file named in the error. No DDS traffic here (security_dds_test).
#include <sys/stat.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "arena/schemas/security.hpp"
#include "arena_command_test.hpp"

namespace arena {
namespace {

namespace fs = std::filesystem;

using test::Slurp;
using Result = test::CommandResult;

class SecurityCerts : public test::ArenaCommandTest {
 protected:
  void SetUp() override {
    ArenaCommandTest::SetUp();
    lab_ = dir_ + "/lab";
  }
  // The error message of CheckIdentityDir(dir), "" when it passes.
  static std::string CheckError(const std::string& dir) {
    try {
      dds::CheckIdentityDir(dir);
      return "";
    } catch (const dds::SecurityError& e) {
      return e.what();
    }
  }
  std::string lab_;
};

TEST_F(SecurityCerts, InitMakesACaAndSignedGovernanceAndRefusesToOverwriteIt) {
  const Result init = Arena("certs init " + lab_);
  ASSERT_EQ(init.rc, 0) << init.err;
  struct stat st {};
  ASSERT_EQ(stat((lab_ + "/ca.key.pem").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  const std::string governance =
      dds::VerifySignedDocument(lab_ + "/governance.p7s", lab_ + "/ca.cert.pem");
  EXPECT_NE(governance.find("<allow_unauthenticated_participants>false<"), std::string::npos)
      << governance;
  EXPECT_NE(governance.find("<enable_join_access_control>true<"), std::string::npos);
  EXPECT_NE(governance.find("<data_protection_kind>ENCRYPT<"), std::string::npos);
  EXPECT_NE(governance.find("<enable_write_access_control>true<"), std::string::npos);
  EXPECT_NE(governance.find("<enable_read_access_control>true<"), std::string::npos);
  // The real-time topics' own rules (no submessage MAC, payload encrypted)
  // come before "*": the first matching rule applies.
  const auto any = governance.find("<topic_expression>*<");
  for (const char* topic : {"LiveState", "PusherCommand"}) {
    const auto rule = governance.find(std::string("<topic_expression>") + topic + "<");
    ASSERT_NE(rule, std::string::npos) << topic;
    EXPECT_LT(rule, any) << topic;
    const auto end = governance.find("</topic_rule>", rule);
    const std::string body = governance.substr(rule, end - rule);
    EXPECT_NE(body.find("<metadata_protection_kind>NONE<"), std::string::npos) << body;
    EXPECT_NE(body.find("<data_protection_kind>ENCRYPT<"), std::string::npos) << body;
    EXPECT_NE(body.find("<enable_write_access_control>true<"), std::string::npos) << body;
  }
  EXPECT_NE(governance.find("<metadata_protection_kind>SIGN<", any), std::string::npos);
  EXPECT_EQ(dds::CertificateSubject(lab_ + "/ca.cert.pem"), "CN=arena lab CA,O=arena lab");

  const std::string key_before = Slurp(lab_ + "/ca.key.pem");
  const Result again = Arena("certs init " + lab_);
  EXPECT_EQ(again.rc, 1);
  EXPECT_NE(again.err.find("ca.key.pem"), std::string::npos) << again.err;
  EXPECT_NE(again.err.find("refusing to overwrite"), std::string::npos) << again.err;
  EXPECT_EQ(Slurp(lab_ + "/ca.key.pem"), key_before);
}

TEST_F(SecurityCerts, EachRoleGetsAConsistentIdentityAndItsOwnTopics) {
  dds::LabOptions lab;
  lab.lab_name = "robot lab 2";
  dds::InitLab(lab_, lab);
  for (const auto& [role, name] :
       {std::pair{dds::Role::kCell, "c1"}, std::pair{dds::Role::kService, "svc"},
        std::pair{dds::Role::kWatcher, "alice"}}) {
    dds::IdentityOptions o;
    o.role = role;
    o.name = name;
    o.valid_days = 365;
    const std::string dir = dds::IssueIdentity(lab_, o);
    EXPECT_EQ(dir, lab_ + "/" + name);
    EXPECT_EQ(CheckError(dir), "");
    const std::string subject = dds::CertificateSubject(dir + "/identity.cert.pem");
    EXPECT_EQ(subject, std::string("CN=") + name + ",OU=" + dds::ToString(role) + ",O=robot lab 2");
    struct stat st {};
    ASSERT_EQ(stat((dir + "/identity.key.pem").c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 0777, 0600u) << dir;
    const std::string permissions =
        dds::VerifySignedDocument(dir + "/permissions.p7s", dir + "/ca.cert.pem");
    EXPECT_NE(permissions.find("<subject_name>" + subject + "</subject_name>"), std::string::npos)
        << permissions;
    EXPECT_NE(permissions.find("<default>DENY</default>"), std::string::npos);
    const auto has = [&](const char* kind, const char* topic) {
      return permissions.find(std::string("<") + kind + "><topics><topic>" + topic + "</topic>") !=
             std::string::npos;
    };
    // Only the service publishes commands; only cells publish what the service stores.
    EXPECT_EQ(has("publish", "TrialCommand"), role == dds::Role::kService) << name;
    EXPECT_EQ(has("publish", "GroundTruth"), role == dds::Role::kCell) << name;
    EXPECT_EQ(has("publish", "CellAnnounce"), role == dds::Role::kCell) << name;
    EXPECT_EQ(has("publish", "TrialStatus"), role == dds::Role::kCell) << name;
    EXPECT_EQ(has("subscribe", "TrialCommand"), role == dds::Role::kCell) << name;
    EXPECT_EQ(has("subscribe", "GroundTruth"), role != dds::Role::kCell) << name;
  }
  dds::IdentityOptions twice;
  twice.name = "c1";
  try {
    dds::IssueIdentity(lab_, twice);
    FAIL() << "an existing identity was overwritten";
  } catch (const dds::SecurityError& e) {
    EXPECT_NE(std::string(e.what()).find("exists already"), std::string::npos) << e.what();
  }
}

TEST_F(SecurityCerts, BadOptionsAreNamed) {
  const auto error = [](auto&& call) {
    try {
      call();
      return std::string();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
  };
  dds::LabOptions lab;
  lab.valid_days = 0;
  EXPECT_NE(error([&] { dds::InitLab(lab_, lab); }).find("--days"), std::string::npos);
  lab = {};
  lab.domain_min = 9;
  lab.domain_max = 3;
  EXPECT_NE(error([&] { dds::InitLab(lab_, lab); }).find("--domains"), std::string::npos);
  lab = {};
  lab.lab_name = "evil</O>";
  EXPECT_NE(error([&] { dds::InitLab(lab_, lab); }).find("--lab"), std::string::npos);
  EXPECT_FALSE(fs::exists(lab_ + "/ca.key.pem"));  // nothing written for a bad option

  dds::InitLab(lab_, {});
  dds::IdentityOptions o;
  for (const std::string bad : {"", "../escape", "a/b", "x y", "<x>", ".."}) {
    o.name = bad;
    EXPECT_NE(error([&] { dds::IssueIdentity(lab_, o); }).find("--name"), std::string::npos) << bad;
  }
  EXPECT_EQ(Arena("certs issue " + lab_ + " --role admin --name x").rc, 2);
  const Result no_lab = Arena("certs issue " + dir_ + "/nolab --role cell --name c1");
  EXPECT_EQ(no_lab.rc, 1);
  EXPECT_NE(no_lab.err.find("nolab/ca.key.pem: missing"), std::string::npos) << no_lab.err;
  EXPECT_EQ(Arena("certs issue " + lab_ + " --role cell --name c1 --domains 5-x").rc, 2);
  // Names with '--' (not allowed inside XML comments) still make valid documents.
  o.name = "c--1";
  const std::string dashes = dds::IssueIdentity(lab_, o);
  EXPECT_NE(dds::VerifySignedDocument(dashes + "/permissions.p7s", dashes + "/ca.cert.pem")
                .find("CN=c--1"),
            std::string::npos);
}

TEST_F(SecurityCerts, EveryBrokenFileIsNamed) {
  dds::InitLab(lab_, {});
  const std::string other = dir_ + "/other";
  dds::InitLab(other, {});
  dds::IdentityOptions o;
  o.name = "c1";
  const std::string id = dds::IssueIdentity(lab_, o);
  o.name = "c2";
  dds::IssueIdentity(lab_, o);
  o.name = "rogue";
  const std::string rogue = dds::IssueIdentity(other, o);

  const auto copy = [&](const std::string& name) {
    const std::string to = dir_ + "/" + name;
    fs::copy(id, to, fs::copy_options::recursive);
    return to;
  };
  // One file missing: named, and so are the files the directory must hold.
  for (const std::string file : {"ca.cert.pem", "governance.p7s", "identity.cert.pem",
                                 "identity.key.pem", "permissions.p7s"}) {
    const std::string d = copy("missing-" + file);
    fs::remove(d + "/" + file);
    const std::string e = CheckError(d);
    EXPECT_NE(e.find(d + "/" + file + ": missing"), std::string::npos) << e;
  }
  {  // unreadable (permission bits; root reads anyway, so only checked as non-root)
    const std::string d = copy("unreadable");
    chmod((d + "/identity.key.pem").c_str(), 0);
    if (geteuid() != 0) {
      EXPECT_NE(CheckError(d).find("identity.key.pem: cannot be read"), std::string::npos)
          << CheckError(d);
    }
  }
  {  // a certificate from another lab's CA
    const std::string d = copy("foreign-cert");
    fs::copy_file(rogue + "/identity.cert.pem", d + "/identity.cert.pem",
                  fs::copy_options::overwrite_existing);
    EXPECT_NE(CheckError(d).find("identity.cert.pem: not valid under"), std::string::npos)
        << CheckError(d);
  }
  {  // another identity's key
    const std::string d = copy("wrong-key");
    fs::copy_file(lab_ + "/c2/identity.key.pem", d + "/identity.key.pem",
                  fs::copy_options::overwrite_existing);
    EXPECT_NE(CheckError(d).find("identity.key.pem: does not belong to"), std::string::npos)
        << CheckError(d);
  }
  {  // another identity's permissions: signed, but for another subject
    const std::string d = copy("wrong-grant");
    fs::copy_file(lab_ + "/c2/permissions.p7s", d + "/permissions.p7s",
                  fs::copy_options::overwrite_existing);
    const std::string e = CheckError(d);
    EXPECT_NE(e.find("permissions.p7s: grants 'CN=c2,OU=cell,O=arena lab'"), std::string::npos)
        << e;
  }
  {  // permissions edited after signing (a watcher granting itself TrialCommand)
    const std::string d = copy("tampered");
    std::string text = Slurp(d + "/permissions.p7s");
    const auto at = text.find("<subscribe><topics><topic>TrialCommand");
    ASSERT_NE(at, std::string::npos);
    text.replace(at, 11, "<publish>  ");
    std::ofstream(d + "/permissions.p7s", std::ios::binary | std::ios::trunc) << text;
    EXPECT_NE(CheckError(d).find("permissions.p7s: signature does not verify"), std::string::npos)
        << CheckError(d);
  }
  {  // governance signed by another CA
    const std::string d = copy("foreign-governance");
    fs::copy_file(other + "/governance.p7s", d + "/governance.p7s",
                  fs::copy_options::overwrite_existing);
    EXPECT_NE(CheckError(d).find("governance.p7s: signature does not verify"), std::string::npos)
        << CheckError(d);
  }
  {  // not S/MIME at all
    const std::string d = copy("garbage");
    std::ofstream(d + "/governance.p7s", std::ios::trunc) << "hello";
    EXPECT_NE(CheckError(d).find("governance.p7s: not S/MIME"), std::string::npos) << CheckError(d);
  }
  EXPECT_NE(CheckError(dir_ + "/nowhere").find("not a directory"), std::string::npos);
}

// The processes refuse a broken --security directory before joining DDS:
// exit 2 with the file named.
TEST_F(SecurityCerts, CommandsNameTheMissingFile) {
  dds::InitLab(lab_, {});
  dds::IdentityOptions o;
  o.name = "c1";
  const std::string id = dds::IssueIdentity(lab_, o);
  fs::remove(id + "/identity.key.pem");
  const Result cell = Arena("cell --id c1 --domain 201 --security " + id);
  EXPECT_EQ(cell.rc, 2) << cell.err;
  EXPECT_NE(cell.err.find("--security: " + id + "/identity.key.pem: missing"), std::string::npos)
      << cell.err;
  const Result watch =
      Arena("watch --cell c1 --domain 201 --timeout 1 --security " + dir_ + "/none");
  EXPECT_EQ(watch.rc, 2) << watch.err;
  EXPECT_NE(watch.err.find("not a directory"), std::string::npos) << watch.err;
  const Result serve = Arena("serve --db " + dir_ + "/s.db --domain 201 --security " + id);
  EXPECT_EQ(serve.rc, 2) << serve.err;
  EXPECT_NE(serve.err.find("identity.key.pem: missing"), std::string::npos) << serve.err;
  EXPECT_FALSE(fs::exists(dir_ + "/s.db")) << "a refused --security created the store";
}

}  // namespace
}  // namespace arena
