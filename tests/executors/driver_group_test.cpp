// Issue 28: what an exec: driver starts dies with its cell however the cell
// dies. The driver (a real Python process) starts a child of its own and
// writes its pid; the cell is SIGKILLed (no destructor, no clean stop); the
// driver's child must be gone within seconds (before: an orphan for good).
#include <signal.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "test_support.hpp"

namespace arena::test {
namespace {

namespace fs = std::filesystem;

constexpr const char* kDriver = R"PY(
import json, subprocess, sys
child = subprocess.Popen(["sleep", "300"])
with open(sys.argv[1] + ".tmp", "w") as f:
    f.write(str(child.pid))
import os
os.rename(sys.argv[1] + ".tmp", sys.argv[1])
sys.stdout.write(json.dumps({"type": "hello", "protocol": 1, "name": "group-test",
                             "truth": "robot", "contact_types": ["point"]}) + "\n")
sys.stdout.flush()
for line in sys.stdin:
    pass
)PY";

bool Gone(pid_t pid) {
  const std::string status = ReadFile("/proc/" + std::to_string(pid) + "/status");
  return status.empty() || status.find("State:\tZ") != std::string::npos;
}

TEST(DriverGroup, ADriversChildrenDieWithAKilledCell) {
  char tmpl[] = "/tmp/arena-driver-group-XXXXXX";
  const std::string dir = mkdtemp(tmpl);
  std::ofstream(dir + "/driver.py") << kDriver;
  int survived = 0, kills = 0;
  for (int round = 0; round < 2; ++round) {
    const std::string pid_file = dir + "/child-" + std::to_string(round) + ".pid";
    Child cell({ARENA_BINARY, "cell", "--id", "group" + std::to_string(round), "--domain",
                std::to_string(TestDomain(40 + round)), "--backend",
                "exec:python3 " + dir + "/driver.py " + pid_file},
               dir + "/cell-" + std::to_string(round) + ".log");
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (!fs::exists(pid_file) && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ASSERT_TRUE(fs::exists(pid_file)) << ReadFile(dir + "/cell-" + std::to_string(round) + ".log");
    const pid_t child = std::stoi(ReadFile(pid_file));
    ASSERT_FALSE(Gone(child));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the cell is up
    cell.Signal(round == 0 ? SIGKILL : SIGTERM);                  // a crash, then a clean stop
    ASSERT_TRUE(cell.Wait(std::chrono::seconds(15)).has_value());
    ++kills;
    const auto gone_by = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!Gone(child) && std::chrono::steady_clock::now() < gone_by)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    EXPECT_TRUE(Gone(child)) << "the driver's child " << child << " outlived its cell (round "
                             << round << ")";
    if (!Gone(child)) {
      ++survived;
      kill(child, SIGKILL);
    }
  }
  std::printf("driver group: %d cell stops (SIGKILL, SIGTERM), %d driver children survived\n",
              kills, survived);
  if (!HasFailure()) fs::remove_all(dir);
}

}  // namespace
}  // namespace arena::test
