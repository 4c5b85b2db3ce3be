// A host-wide claim on a DDS domain id (dds::HostDomainClaim): one holder at
// a time across processes and within one, released when the claim ends or
// its process dies. (`arena run` honouring claims: tests/cli/run_domain_test.cpp.)
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "arena/schemas/dds.hpp"

namespace arena::test {
namespace {

// The first free id at or above `from` (other tests may hold some).
dds::HostDomainClaim FreeClaim(int from) {
  for (int d = from; d <= dds::kMaxDomainId; ++d) {
    if (auto c = dds::HostDomainClaim::TryClaim(d)) return std::move(*c);
  }
  ADD_FAILURE() << "no free domain id at or above " << from;
  std::abort();
}

// Whether a child process can claim `domain` (0: it could, 1: it could not).
int ChildClaims(int domain) {
  const pid_t pid = fork();
  if (pid == 0) _exit(dds::HostDomainClaim::TryClaim(domain) ? 0 : 1);
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(HostDomainClaim, OneHolderAcrossProcessesAndWithinOne) {
  std::optional<dds::HostDomainClaim> claim = FreeClaim(40);
  const int domain = claim->domain_id();
  EXPECT_TRUE(std::filesystem::exists(dds::HostDomainClaim::LockPath(domain)));
  EXPECT_FALSE(dds::HostDomainClaim::TryClaim(domain)) << "a second claim in the same process";
  EXPECT_EQ(ChildClaims(domain), 1) << "another process claimed a held domain";
  claim.reset();
  EXPECT_EQ(ChildClaims(domain), 0) << "the domain stayed held after its claim ended";
  // A moved claim still holds; the moved-from one releases nothing.
  auto first = dds::HostDomainClaim::TryClaim(domain);
  ASSERT_TRUE(first);
  dds::HostDomainClaim moved = std::move(*first);
  first.reset();
  EXPECT_EQ(ChildClaims(domain), 1);
}

TEST(HostDomainClaim, DiesWithItsProcess) {
  const int domain = FreeClaim(60).domain_id();  // released at once
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const pid_t holder = fork();
  if (holder == 0) {
    auto c = dds::HostDomainClaim::TryClaim(domain);
    const char ok = c ? '1' : '0';
    (void)!write(ready[1], &ok, 1);
    pause();  // killed below
    _exit(0);
  }
  char ok = 0;
  ASSERT_EQ(read(ready[0], &ok, 1), 1);
  ASSERT_EQ(ok, '1');
  EXPECT_FALSE(dds::HostDomainClaim::TryClaim(domain));
  kill(holder, SIGKILL);
  waitpid(holder, nullptr, 0);
  EXPECT_TRUE(dds::HostDomainClaim::TryClaim(domain)) << "a killed holder's claim outlived it";
  close(ready[0]);
  close(ready[1]);
}

}  // namespace
}  // namespace arena::test
