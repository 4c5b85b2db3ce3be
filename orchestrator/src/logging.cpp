#include "arena/orchestrator/logging.hpp"

#include <memory>
#include <stdexcept>
#include <vector>

#include <spdlog/sinks/rotating_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

namespace arena::orchestrator {

std::string ServiceLogPath(const std::string& db_path) { return db_path + ".log"; }

void SetUpServiceLog(const std::string& db_path, const std::string& level, bool to_stderr) {
  const auto lvl = spdlog::level::from_str(level);
  // from_str maps any unknown word to "off": refuse instead of going silent.
  if (lvl == spdlog::level::off && level != "off") {
    throw std::invalid_argument(
        "--log-level: must be trace, debug, info, warn, error, critical or off, got '" + level +
        "'");
  }
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
