// What the service watches besides its trials (issue 29), once a second on
// its own thread's loop: the suspenders (suspenders.hpp) evaluated and their
// steps written to the store, `arena resume` noticed, the store folder's
// free space read (statvfs), and the events an operator is told of (store
// table service_events, the log, and `--notify`): a campaign done, a cell
// gone, back or quarantined, a suspension fired or lifted, a failure rate
// above its threshold, a condition set aside.
//
// Store errors: a busy store (another process's lock) skips this pass (the
// same decisions come back on the next: nothing is committed in memory
// before the store has it); the fatal kinds are thrown (the service stops,
// exit 3); any other is logged.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/orchestrator/notifier.hpp"
#include "arena/orchestrator/service.hpp"
#include "arena/orchestrator/suspenders.hpp"

namespace arena::orchestrator {

class ServiceWatch {
 public:
  // `notifier` may be null. free_space: the probe (default statvfs of the store's folder).
  ServiceWatch(db::Store& store, const ServiceOptions& options, Suspenders& suspenders,
               Notifier* notifier);
  // Adopts the store's active suspensions (a restart) and the states events compare against.
  void Start();
  // One pass (see above). @throws db::StoreError of a fatal kind.
  void Poll();

 private:
  void Pass();
  void Emit(const std::string& kind, std::int64_t campaign_id, const std::string& cell_id,
            const std::string& message, nlohmann::json detail = nlohmann::json::object());
  void Flush();
  void Carry(const Suspenders::Action& a);
  std::optional<double> FreeBytes() const;

  db::Store& store_;
  const ServiceOptions& opt_;
  Suspenders& suspenders_;
  Notifier* notifier_;
  std::string folder_;
  bool started_ = false;
  std::map<std::string, db::CellState> cells_;
  std::map<std::int64_t, db::CampaignState> campaigns_;
  std::map<std::int64_t, bool> failure_rate_high_;
  int passes_ = 0;
  std::deque<db::EventRecord> unsent_;  // events a busy store has not taken yet
};

}  // namespace arena::orchestrator
