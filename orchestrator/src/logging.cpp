#include "arena/orchestrator/logging.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <memory>
#include <stdexcept>
#include <vector>

#include <spdlog/sinks/rotating_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

namespace arena::orchestrator {

std::string ServiceLogPath(const std::string& db_path) { return db_path + ".log"; }

namespace {
// The log usually shares its disk with the store: when the store fills the
// disk, the lines saying so must still fit. Blocks reserved past the end of
// the file (FALLOC_FL_KEEP_SIZE) are used by later appends without new
// allocation, so the first kLogReserveBytes of the log survive a full disk.
constexpr off_t kLogReserveBytes = 1 << 20;
void ReserveLogSpace(const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) return;  // the sink below reports an unwritable log
  const off_t end = ::lseek(fd, 0, SEEK_END);
  if (end >= 0) (void)::fallocate(fd, FALLOC_FL_KEEP_SIZE, end, kLogReserveBytes);  // best effort
  ::close(fd);
}
}  // namespace

void SetUpServiceLog(const std::string& db_path, const std::string& level, bool to_stderr) {
  const auto lvl = spdlog::level::from_str(level);
  // from_str maps any unknown word to "off": refuse instead of going silent.
  if (lvl == spdlog::level::off && level != "off") {
    throw std::invalid_argument(
        "--log-level: must be trace, debug, info, warn, error, critical or off, got '" + level +
        "'");
  }
  ReserveLogSpace(ServiceLogPath(db_path));
  std::vector<spdlog::sink_ptr> sinks;
  sinks.push_back(std::make_shared<spdlog::sinks::rotating_file_sink_mt>(ServiceLogPath(db_path),
                                                                         kLogFileBytes, kLogFiles));
  if (to_stderr) sinks.push_back(std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
  auto logger = std::make_shared<spdlog::logger>("arena", sinks.begin(), sinks.end());
  logger->set_level(lvl);
  logger->set_pattern("%Y-%m-%dT%H:%M:%S.%e %^%l%$ %v");
  logger->flush_on(spdlog::level::warn);
  spdlog::set_default_logger(logger);
  spdlog::flush_every(std::chrono::seconds(1));
}

std::string TrialTag(std::int64_t campaign_id, std::int64_t trial_id, int attempt) {
  return "campaign " + std::to_string(campaign_id) + " trial " + std::to_string(trial_id) +
         " attempt " + std::to_string(attempt);
}

}  // namespace arena::orchestrator
