// Issue 28: a child's log is bounded. `arena run` starts its cells (and a
// cell its drivers' stderr, executors) as children whose output goes to a
// file; a child printing in a loop used to grow it without end.
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "child_process.hpp"

namespace arena::cli {
namespace {

namespace fs = std::filesystem;

TEST(ChildProcessLog, AChildPrintingInALoopHoldsAtMostTwiceTheCap) {
  char tmpl[] = "/tmp/arena-child-log-XXXXXX";
  const std::string dir = mkdtemp(tmpl);
  const std::string log = dir + "/child.log";
  constexpr std::uintmax_t kCap = 256 << 10;
  {
    // 8 MB of output, 32 times the cap.
    ChildProcess child({"/bin/sh", "-c", "head -c 8000000 /dev/zero | tr '\\0' x; echo END"}, log,
                       kCap);
    for (int i = 0; i < 300 && !child.Poll(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_TRUE(child.Poll().has_value()) << "the child did not finish in 15 s";
  }
  ASSERT_TRUE(fs::exists(log));
  EXPECT_LE(fs::file_size(log), kCap);
  ASSERT_TRUE(fs::exists(log + ".1"));
  EXPECT_LE(fs::file_size(log + ".1"), kCap);
  // The newest output is kept.
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("END"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace arena::cli
