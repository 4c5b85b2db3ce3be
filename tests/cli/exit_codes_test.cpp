// One error base (issue 27): every room's typed error carries a category,
// main() maps it to the exit code once, and README.md's exit-code table says
// the same as the code.
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arena/assessment/calibration.hpp"
#include "arena/assessment/noise.hpp"
#include "arena/db/store.hpp"
#include "arena/errors/error.hpp"
#include "arena/executors/controller.hpp"
#include "arena/executors/defects.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/submit.hpp"
#include "arena/recordings/recording.hpp"
#include "arena/schemas/dds.hpp"
#include "arena/schemas/security.hpp"
#include "arena/simulators/simulator.hpp"
#include "arena_command_test.hpp"

namespace arena {
namespace {

// code -> the row's "meaning" cell, from the table under "Exit codes".
std::map<int, std::string> ReadmeExitCodes() {
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/README.md");
  std::stringstream text;
  text << in.rdbuf();
  const std::string readme = text.str();
  const auto start = readme.find("Exit codes (every command):");
  EXPECT_NE(start, std::string::npos) << "README.md has no exit-code table";
  std::map<int, std::string> rows;
  std::istringstream lines(readme.substr(start == std::string::npos ? 0 : start));
  const std::regex row(R"(^\| (\d+) \| ([^|]*) \|)");
  std::string line;
  bool in_table = false;
  while (std::getline(lines, line)) {
    std::smatch m;
    if (std::regex_search(line, m, row)) {
      rows[std::stoi(m[1])] = m[2];
      in_table = true;
    } else if (in_table && line.rfind("|", 0) != 0) {
      break;  // the table ended
    }
  }
  return rows;
}

TEST(ExitCodes, TheReadmeTableListsEveryCategoryAndNothingElse) {
  const auto rows = ReadmeExitCodes();
  std::set<int> documented;
  for (const auto& [code, meaning] : rows) documented.insert(code);
  std::set<int> coded = {0};  // success
  for (ErrorCategory c : kErrorCategories) coded.insert(ExitCode(c));
  EXPECT_EQ(documented, coded);
  for (ErrorCategory c : kErrorCategories) {
    const auto it = rows.find(ExitCode(c));
    ASSERT_NE(it, rows.end()) << ToString(c);
    EXPECT_NE(it->second.find(ToString(c)), std::string::npos)
        << "README row " << it->first << " (" << it->second << ") does not say '" << ToString(c)
        << "'";
    EXPECT_EQ(CategoryForExitCode(ExitCode(c)), c);
  }
}

TEST(ExitCodes, EveryRoomsErrorCarriesItsCategory) {
  using C = ErrorCategory;
  EXPECT_EQ(mechanics::SceneError("mu", "bad").category(), C::kBadInput);
  EXPECT_EQ(orchestrator::CampaignError("trials", "bad").category(), C::kBadInput);
  EXPECT_EQ(orchestrator::SubmitInterrupted().category(), C::kInterrupted);
  EXPECT_EQ(assessment::CalibrationError("--params: bad").category(), C::kBadInput);
  EXPECT_EQ(assessment::NoiseError("mu_scale_std", "bad").category(), C::kBadInput);
  EXPECT_EQ(recordings::ImportError("f.h5", "bad").category(), C::kBadInput);
  EXPECT_EQ(simulators::SimulatorError("mujoco.timestep", "bad").category(), C::kBadInput);
  EXPECT_EQ(executors::DefectError("speed", "bad").category(), C::kBadInput);
  EXPECT_EQ(executors::ControllerNameConflict("taken").category(), C::kBadInput);
  EXPECT_EQ(dds::DdsError("dds: create_participant failed").category(), C::kCommunication);
  EXPECT_EQ(dds::SecurityError("--security: no key").category(), C::kBadInput);
  using K = db::StoreError::Kind;
  for (K k : {K::kBadInput, K::kNotFound, K::kIllegalTransition, K::kStaleAttempt})
    EXPECT_EQ(db::StoreError(k, "x").category(), C::kBadInput);
  for (K k : {K::kReadOnly, K::kBusy, K::kTooNew, K::kCorrupt, K::kFull, K::kIo})
    EXPECT_EQ(db::StoreError(k, "x").category(), C::kStore);
  EXPECT_EQ(db::StoreError(K::kOutput, "x").category(), C::kFailure);
  // An option DDS refuses is the user's input, not a failure to communicate.
  try {
    (void)dds::ParsePeers("host:99999");
    ADD_FAILURE() << "a bad port was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), C::kBadInput) << e.what();
  }
}

using BadDomain = test::ArenaCommandTest;

// The same bad --domain is bad input (2) from every command that joins DDS.
TEST_F(BadDomain, ExitsTwoFromEveryCommandThatJoinsDds) {
  for (const std::string& args : std::vector<std::string>{
           "cell --id c1 --domain 999", "controller --name pivot_to_angle --domain 999",
           "serve --db " + dir_ + "/s.db --domain 999", "watch 1 --domain 999 --timeout 1",
           "run " + std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/smoke.json --db " + dir_ +
               "/r.db --domain 999"}) {
    const auto r = Arena(args);
    EXPECT_EQ(r.rc, 2) << "arena " << args << "\n" << r.err;
    EXPECT_NE(r.err.find("--domain"), std::string::npos) << "arena " << args << "\n" << r.err;
  }
}

}  // namespace
}  // namespace arena
