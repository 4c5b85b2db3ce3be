// A test fixture that runs the built `arena` binary as an operator's shell
// would (`arena ARGS >out 2>err`) in a fresh temporary directory, removed
// after a passing test and kept for a failing one.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

namespace arena::test {

inline std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

struct CommandResult {
  int rc = -1;  // exit status, -1 when killed by a signal
  std::string out, err;
};

class ArenaCommandTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/arena-command-test-XXXXXX";
    dir_ = mkdtemp(tmpl);
  }
  void TearDown() override {
    if (!HasFailure()) std::filesystem::remove_all(dir_);
  }
  // args is shell text: quote what needs quoting.
  CommandResult Arena(const std::string& args) {
    const std::string out = dir_ + "/out", err = dir_ + "/err";
    const int st =
        std::system((std::string(ARENA_BINARY) + " " + args + " >" + out + " 2>" + err).c_str());
    return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, Slurp(out), Slurp(err)};
  }
  std::string dir_;
};

}  // namespace arena::test
