// arena cells release ID --db F [--reason R]: lifts a cell's quarantine (or a
// `gone` mark) so the service gives it trials again, with an audit row in
// cell_events (who, when, why). A running service reads the cell's state on
// its next announcement or claim, within a second or two.
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "arena/db/store.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "commands.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

std::string Operator() {
  const char* user = std::getenv("USER");
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return std::string(user && *user ? user : "uid " + std::to_string(getuid())) + "@" + host;
}

int Release(const std::string& cell_id, const std::string& db_path, const std::string& reason) {
  try {
    db::StoreOptions o;
    o.scene_facts = orchestrator::SceneFactsOfJson;  // an older store's migration reads scenes
    o.create = false;
    auto store = db::Store::Open(db_path, o);
    const db::CellInfo before = store->GetCell(cell_id);
    if (before.state == db::CellState::kHealthy) {
      std::fprintf(stderr, "cell %s is healthy already; nothing to release\n", cell_id.c_str());
      return kExitOk;
    }
    store->ReleaseCell(cell_id, reason.empty() ? "released by operator" : reason, Operator());
    std::fprintf(stderr, "cell %s: %s -> healthy (was: %s)\n", cell_id.c_str(),
                 db::ToString(before.state), before.quarantine_reason.c_str());
  } catch (const db::StoreError& e) {
    if (e.kind() == db::StoreError::Kind::kNotFound)
      throw CommandError(kExitBadInput, "no cell '" + cell_id + "' in " + db_path +
                                            " (see `arena status --db " + db_path + "`)");
    throw StoreCommandError(e);
  }
  return kExitOk;
}

}  // namespace

void AddCellsCommand(CLI::App& app, Action* action) {
  auto* cells = app.add_subcommand("cells", "Manage the cells a store knows (release)");
  cells->footer(
      "Example:\n  arena cells release c1 --db lab.db --reason \"gripper pads replaced\"\n");
  cells->require_subcommand(1);
  struct O {
    std::string id, db, reason;
  };
  auto o = std::make_shared<O>();
  auto* cmd = cells->add_subcommand(
      "release", "Lift a cell's quarantine so it gets trials again (audited in cell_events)");
  cmd->footer(
      "Example:\n  arena cells release c1 --db lab.db --reason \"gripper pads replaced\"\n");
  cmd->add_option("id", o->id, "Cell id (see `arena status`)")->required();
  cmd->add_option("--db", o->db, "SQLite store")->required();
  cmd->add_option("--reason", o->reason, "Why (stored with the release)");
  cmd->callback([o, action] { *action = [o] { return Release(o->id, o->db, o->reason); }; });
}

}  // namespace arena::cli
