// Reclaiming the shared-memory files of Fast DDS processes that died without
// closing them (SIGKILL): what `fastdds shm clean` does, without Python.
// Every segment and port has an "_el" lock file that its live owner holds
// with flock(); a lock we can take means the owner is gone.
#include <dirent.h>
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cstring>
#include <string>
#include <vector>

#include "arena/schemas/dds.hpp"

namespace arena::dds {
namespace {

constexpr char kShmDir[] = "/dev/shm/";

bool OwnerGone(const std::string& lock_path) {
  const int fd = ::open(lock_path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) return false;
  const bool free = ::flock(fd, LOCK_EX | LOCK_NB) == 0;
  ::close(fd);  // releases our lock
  return free;
}

bool StartsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

}  // namespace

std::size_t CleanZombieSharedMemory() {
  DIR* dir = ::opendir(kShmDir);
  if (!dir) return 0;
  std::vector<std::string> locks;
  while (dirent* e = ::readdir(dir)) {
    const std::string name = e->d_name;
    if (StartsWith(name, "fastrtps_") && name.size() > 3 &&
        name.compare(name.size() - 3, 3, "_el") == 0)
      locks.push_back(name);
  }
  ::closedir(dir);
  std::size_t removed = 0;
  for (const auto& lock : locks) {
    const std::string base = lock.substr(0, lock.size() - 3);
    if (!OwnerGone(kShmDir + lock)) continue;
    std::vector<std::string> files = {base, lock};
    if (StartsWith(base, "fastrtps_port")) files.push_back("sem." + base + "_mutex");
    for (const auto& f : files) removed += ::unlink((kShmDir + f).c_str()) == 0 ? 1 : 0;
  }
  return removed;
}

}  // namespace arena::dds
