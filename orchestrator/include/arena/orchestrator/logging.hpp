// The service's log: a size-rotated file next to the store plus stderr,
// through spdlog. Rotation bounds the disk it can ever use
// (kLogFileBytes x (kLogFiles + 1)), so months of operation cannot fill it.
#pragma once

#include <cstdint>
#include <string>

namespace arena::orchestrator {

inline constexpr std::size_t kLogFileBytes = 16u << 20;  // one file, 16 MiB
inline constexpr std::size_t kLogFiles = 5;              // rotated files kept

// Installs the default spdlog logger: "<db_path>.log" (rotated) and stderr.
// level: trace, debug, info, warn, error, critical, off.
// @throws std::invalid_argument naming --log-level for an unknown level.
void SetUpServiceLog(const std::string& db_path, const std::string& level, bool to_stderr = true);

// The path of the log file SetUpServiceLog writes for a store.
std::string ServiceLogPath(const std::string& db_path);

// "campaign 3 trial 17 attempt 2": the prefix of every log line about a trial,
// so `grep 'trial 17 '` finds its whole story.
std::string TrialTag(std::int64_t campaign_id, std::int64_t trial_id, int attempt);

}  // namespace arena::orchestrator
