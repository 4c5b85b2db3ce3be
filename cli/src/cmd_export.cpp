// arena export --db FILE --campaign ID --format hdf5|csv|jsonl --out DIR
// A dataset directory (layout in db/include/arena/db/export.hpp), verified
// after writing.
#include <cstdio>
#include <string>

#include "arena/cli/version.hpp"
#include "arena/db/export.hpp"
#include "arena/db/store.hpp"
#include "commands.hpp"
#include "output_guard.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

struct ExportCliOptions {
  std::string db_path;
  std::int64_t campaign = 0;
  std::string format = "hdf5";
  std::string out;
};

int RunExport(const ExportCliOptions& o) {
  RefuseToOverwriteStore(o.out, "--out", o.db_path);
  try {
    db::StoreOptions so;
    so.read_only = true;
    auto store = db::Store::Open(o.db_path, so);
    db::ExportOptions eo;
    eo.campaign_id = o.campaign;
    eo.format = o.format == "csv"     ? db::ExportFormat::kCsv
                : o.format == "jsonl" ? db::ExportFormat::kJsonl
                                      : db::ExportFormat::kHdf5;
    eo.out_dir = o.out;
    eo.arena_version = arena::Version();
    eo.arena_commit = arena::GitCommit();
    const auto r = db::ExportCampaign(*store, eo);
    std::printf(
        "exported campaign %lld: %lld trials, %lld samples, %zu files + manifest.json -> %s "
        "(verified)\n",
        static_cast<long long>(o.campaign), static_cast<long long>(r.trials),
        static_cast<long long>(r.samples), r.files.size(), r.dir.c_str());
    return kExitOk;
  } catch (const db::StoreError& e) {
    throw StoreCommandError(e);
  }
}

}  // namespace

void AddExportCommand(CLI::App& app, Action* action) {
  auto o = std::make_shared<ExportCliOptions>();
  auto* cmd = app.add_subcommand("export", "Export a campaign as a dataset directory");
  cmd->add_option("--db", o->db_path, "Store file")->required();
  cmd->add_option("--campaign", o->campaign, "Campaign id (see 'arena list')")
      ->required()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--format", o->format, "Stream format")
      ->check(CLI::IsMember({"hdf5", "csv", "jsonl"}));
  cmd->add_option("--out", o->out, "New or empty directory to write")->required();
  cmd->footer(
      "Example:\n"
      "  arena export --db lab.db --campaign 1 --format hdf5 --out datasets/c1\n"
      "Writes trials.csv (index), the true and observed streams of every trial with ground truth,\n"
      "and manifest.json last (units, frames, counts, SHA-256 of every file); then verifies it.\n"
      "Reads one snapshot of the store: safe while 'arena serve' runs.\n");
  cmd->callback([o, action] { *action = [o] { return RunExport(*o); }; });
}

}  // namespace arena::cli
