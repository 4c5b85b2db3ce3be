// A trial's parameters for --group-by / --holdout-by (cli/src/trial_parameters.hpp):
// its stored parameters first, then the row of its seed in a dataset's
// trials.csv (quoted fields with commas, quotes and newlines); bad tables and
// missing parameters are errors naming the file, trial and parameter.
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "commands.hpp"
#include "trial_parameters.hpp"

namespace arena::cli {
namespace {

std::string Write(const std::string& name, const std::string& text) {
  const auto path = std::filesystem::temp_directory_path() /
                    ("arena_trial_parameters_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(path, std::ios::binary) << text;
  return path.string();
}

db::Trial Trial(std::int64_t id, std::uint64_t seed, const std::string& params) {
  db::Trial t;
  t.id = id;
  t.seed = seed;
  t.params_json = params;
  return t;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const CommandError& e) {
    EXPECT_EQ(e.exit_code(), kExitBadInput);
    return e.what();
  }
  return "";
}

TEST(TrialParameters, StoredFirstThenTheRowOfTheSeed) {
  const std::string csv = Write("good.csv",
                                "trial_id,seed,shape,push_angle_rad,scene_json\r\n"
                                "1,11,hex,0.349,\"{\"\"a\"\": [1, 2],\n \"\"b\"\": 3}\"\r\n"
                                "2,12,rect1,0,\"x\"\n");
  const TrialParameters p(csv, "--trial-parameters");
  EXPECT_EQ(p.Value(Trial(7, 11, R"({"scene_index": 0})"), "shape", "--group-by"), "hex");
  EXPECT_EQ(p.Value(Trial(8, 12, "{}"), "push_angle_rad", "--group-by"), "0");
  // The stored parameter wins; a number reads as JSON writes it.
  EXPECT_EQ(p.Value(Trial(7, 11, R"({"shape": "mine", "k": 2.5})"), "shape", "--group-by"), "mine");
  EXPECT_EQ(p.Value(Trial(7, 11, R"({"k": 2.5})"), "k", "--group-by"), "2.5");
  const std::string missing =
      ErrorOf([&] { p.Value(Trial(9, 99, "{}"), "shape", "--holdout-by"); });
  EXPECT_NE(missing.find("--holdout-by: trial 9 has no parameter 'shape'"), std::string::npos)
      << missing;
  EXPECT_NE(missing.find("seed 99"), std::string::npos) << missing;
  // Without a table the message says where the parameters would come from.
  const TrialParameters none("", "--trial-parameters");
  const std::string hint = ErrorOf([&] { none.Value(Trial(9, 11, "{}"), "shape", "--group-by"); });
  EXPECT_NE(hint.find("give --trial-parameters DATASET/trials.csv"), std::string::npos) << hint;
}

TEST(TrialParameters, BadTablesAreRefusedNamingTheFile) {
  const auto refused = [](const std::string& name, const std::string& text) {
    const std::string path = Write(name, text);
    const std::string why = ErrorOf([&] { TrialParameters(path, "--trial-parameters"); });
    EXPECT_NE(why.find(path), std::string::npos) << why;
    return why;
  };
  EXPECT_NE(refused("noseed.csv", "trial_id,shape\n1,hex\n").find("no 'seed' column"),
            std::string::npos);
  EXPECT_NE(refused("repeat.csv", "seed,shape\n11,hex\n11,rect1\n").find("repeats seed 11"),
            std::string::npos);
  EXPECT_NE(refused("ragged.csv", "seed,shape\n11,hex,extra\n").find("record 2 has 3 fields"),
            std::string::npos);
  EXPECT_NE(refused("quote.csv", "seed,shape\n11,\"hex\n").find("record 2: a quote"),
            std::string::npos);
  const std::string absent =
      ErrorOf([] { TrialParameters("/nonexistent/trials.csv", "--trial-parameters"); });
  EXPECT_NE(absent.find("cannot read '/nonexistent/trials.csv'"), std::string::npos) << absent;
}

}  // namespace
}  // namespace arena::cli
