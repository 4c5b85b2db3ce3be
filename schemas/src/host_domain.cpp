// A host-wide claim on a DDS domain id (HostDomainClaim in dds.hpp).
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <string>
#include <utility>

#include "arena/schemas/dds.hpp"

namespace arena::dds {

std::string HostDomainClaim::LockPath(int domain_id) {
  return "/tmp/arena-domain-" + std::to_string(domain_id) + ".lock";
}

std::optional<HostDomainClaim> HostDomainClaim::TryClaim(int domain_id) {
  const std::string path = LockPath(domain_id);
  // 0666: the lock file outlives this process and any user's run may claim
  // the domain next (the umask may narrow it; then only its owner can).
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0) return std::nullopt;
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    ::close(fd);
    return std::nullopt;
  }
  return HostDomainClaim(domain_id, fd);
}

HostDomainClaim::HostDomainClaim(HostDomainClaim&& other) noexcept
    : domain_id_(other.domain_id_), fd_(std::exchange(other.fd_, -1)) {}

HostDomainClaim& HostDomainClaim::operator=(HostDomainClaim&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    domain_id_ = other.domain_id_;
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}

HostDomainClaim::~HostDomainClaim() {
  if (fd_ >= 0) ::close(fd_);  // closing the descriptor drops the lock
}

}  // namespace arena::dds
