// `arena run` picks a quiet DDS domain only among those no other arena
// process on this host has claimed (dds::HostDomainClaim): a run beside a
// test suite took a domain a test had claimed but not joined yet, and the
// two met each other's cells (one cell did a whole campaign; a replayed trial
// got another trial's truth). SERIAL: this test holds every id a run picks
// from, so nothing else may start a run beside it.
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arena/schemas/dds.hpp"
#include "arena_command_test.hpp"

namespace arena::test {
namespace {

class RunDomain : public ArenaCommandTest {};

// With every id `arena run` picks from (100..kMaxDomainId) claimed here, it
// finds no quiet domain and says so, before anything is stored.
TEST_F(RunDomain, ARunNeverTakesAClaimedDomain) {
  std::vector<dds::HostDomainClaim> held;
  for (int d = 100; d <= dds::kMaxDomainId; ++d) {
    if (auto c = dds::HostDomainClaim::TryClaim(d)) {
      held.push_back(std::move(*c));
    }
  }
  ASSERT_GT(held.size(), 0u);
  const auto r = Arena("run " + std::string(ARENA_SOURCE_DIR) +
                       "/examples/campaigns/smoke.json --db " + dir_ + "/run.db --quiet");
  EXPECT_NE(r.rc, 0) << r.out;
  EXPECT_NE(r.err.find("--domain: no quiet DDS domain"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/run.db")) << "a refused run created its store";
}

}  // namespace
}  // namespace arena::test
