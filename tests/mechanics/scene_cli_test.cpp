// `arena simulate` on every file of the bad-input scene corpus
// (tests/bad_inputs/scenes/MANIFEST.tsv): a non-zero exit, one JSON object
// with "ok": false and an error that names the manifest's field; and a
// 100 MB scene refused by its size.
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
const fs::path kSourceDir = ARENA_SOURCE_DIR;

struct CliRun {
  int exit_code = -1;
  std::string out;
};

// Runs `arena simulate FILE`, stdout captured, stderr discarded.
CliRun Simulate(const fs::path& file) {
  const std::string command =
      std::string("'") + ARENA_BINARY + "' simulate '" + file.string() + "' 2>/dev/null";
  CliRun run;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return run;
  std::array<char, 4096> buf{};
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) run.out.append(buf.data(), n);
  const int status = ::pclose(pipe);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return run;
}

void ExpectRefused(const CliRun& run, const std::string& expected_field) {
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.exit_code, -1) << "crashed";
  json out;
  ASSERT_NO_THROW(out = json::parse(run.out)) << run.out;
  EXPECT_EQ(out["ok"], false);
  const std::string error = out.value("error", "");
  if (expected_field == "<root>") {
    EXPECT_EQ(error.rfind("scene: ", 0), 0u) << error;
  } else if (expected_field.back() == '*') {
    EXPECT_EQ(error.rfind(expected_field.substr(0, expected_field.size() - 1), 0), 0u) << error;
  } else {
    EXPECT_EQ(error.rfind(expected_field + ": ", 0), 0u) << error;
  }
}

TEST(SceneCli, CanonicalSceneSimulates) {
  const CliRun run = Simulate(kSourceDir / "examples/scenes/canonical.json");
  EXPECT_EQ(run.exit_code, 0) << run.out;
  EXPECT_EQ(json::parse(run.out)["ok"], true);
}

TEST(SceneCli, BadInputCorpusIsRefusedNamingTheField) {
  const fs::path dir = kSourceDir / "tests/bad_inputs/scenes";
  std::ifstream manifest(dir / "MANIFEST.tsv");
  std::string line;
  int checked = 0;
  while (std::getline(manifest, line)) {
    if (line.empty() || line[0] == '#') continue;
    const auto tab = line.find('\t');
    SCOPED_TRACE(line.substr(0, tab));
    ExpectRefused(Simulate(dir / line.substr(0, tab)), line.substr(tab + 1));
    ++checked;
  }
  EXPECT_GE(checked, 40);
}

TEST(SceneCli, HundredMegabyteSceneIsRefusedBySize) {
  const fs::path dir =
      fs::temp_directory_path() / ("arena_scene_cli_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path big = dir / "big.json";
  {
    std::ofstream out(big, std::ios::binary);
    out << "{\"pad\": \"";
    out.seekp(100 * 1000 * 1000 - 2);
    out << "\"}";
  }
  const CliRun run = Simulate(big);
  ExpectRefused(run, "<root>");
  EXPECT_NE(run.out.find("larger than the limit"), std::string::npos) << run.out;
  fs::remove_all(dir);
}

}  // namespace
