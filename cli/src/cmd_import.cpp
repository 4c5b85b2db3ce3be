// arena import push-dataset DIR --shapes FILE --out DATASET: recorded pushes
// (the MIT push dataset's HDF5 files) -> a dataset `replay:DATASET` serves,
// DATASET/campaign.json commanding exactly those trials, and the import
// report (docs/real_data.md). The adaptor reads the lab's layout; the
// recordings room does the rest, lab-neutral.
#include <cstdio>
#include <string>

#include "arena/cli/version.hpp"
#include "arena/recordings/import.hpp"
#include "arena/recordings/push_dataset.hpp"
#include "commands.hpp"

namespace arena::cli {
namespace {

struct ImportCliOptions {
  std::string dir;
  std::string shapes;
  std::string out;
  std::string name;
  double support_mu = 0.25;
  double pusher_mu = 0.25;
};

int RunPushImport(const ImportCliOptions& o) {
  try {
    const recordings::ShapesTable shapes = recordings::ReadShapesTable(o.shapes);
    const auto recorded = recordings::ReadPushDataset(o.dir, shapes);
    recordings::ImportOptions io;
    io.out_dir = o.out;
    io.campaign_name = o.name;
    io.source = o.dir;
    io.adaptor = "push-dataset";
    io.support_mu = o.support_mu;
    io.pusher_mu = o.pusher_mu;
    io.arena_version = arena::Version();
    io.arena_commit = arena::GitCommit();
    const auto report = recordings::ImportRecordings(recorded, io);
    std::fputs(report.text.c_str(), stdout);
    std::printf(
        "wrote %s: dataset.h5, scenes.jsonl, campaign.json, import_report.{txt,json}, "
        "manifest.json (verified)\n",
        o.out.c_str());
    return kExitOk;
  } catch (const recordings::ImportError& e) {
    throw CommandError(kExitBadInput, std::string("import: ") + e.what() + " (nothing written)");
  } catch (const Error& e) {  // a scene or an output (store) error keeps its category
    throw CommandError(e.exit_code(), std::string(e.what()) + " (nothing written)");
  } catch (const std::runtime_error& e) {
    throw CommandError(kExitFailure, std::string(e.what()) + " (nothing written)");
  }
}

}  // namespace

void AddImportCommand(CLI::App& app, Action* action) {
  auto* cmd = app.add_subcommand("import", "Import recorded experiments as a replayable dataset");
  cmd->require_subcommand(1);
  cmd->footer(
      "Example:\n"
      "  arena import push-dataset data/mit-push/abs --shapes data/mit-push/shapes.json \\\n"
      "      --out datasets/mit-abs\n"
      "One adaptor per recording layout (docs/real_data.md); `arena import push-dataset --help`\n"
      "for the MIT push dataset's.\n");
  auto o = std::make_shared<ImportCliOptions>();
  auto* push = cmd->add_subcommand(
      "push-dataset", "The MIT push dataset's HDF5 files (tip_pose, object_pose, ft_wrench)");
  push->add_option("DIR", o->dir, "Directory of .h5 files (searched recursively)")->required();
  push->add_option("--shapes", o->shapes, "Shapes table (JSON; docs/real_data.md)")->required();
  push->add_option("--out", o->out, "New dataset directory")->required();
  push->add_option("--name", o->name, "Campaign name (default: from --out)");
  push->add_option("--support-mu", o->support_mu,
                   "Table friction written into the scenes (a starting value: calibrate fits it)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  push->add_option("--pusher-mu", o->pusher_mu,
                   "Pusher friction written into the scenes (a starting value)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  push->footer(
      "Example:\n"
      "  arena import push-dataset data/mit-push/abs --shapes data/mit-push/shapes.json \\\n"
      "      --out datasets/mit-abs\n"
      "  arena run datasets/mit-abs/campaign.json --backend replay:datasets/mit-abs\n"
      "Puts each file's streams on one 250 Hz clock, checks every trial (the pusher touching\n"
      "the outline when the object starts to move, frozen or offset force streams, out-of-order\n"
      "stamps, a pusher starting inside the outline), prints the report and writes the dataset\n"
      "whole or not at all. Bad input (a truncated file, a missing dataset, NaN, an unknown\n"
      "shape, a file name without parameters) names the file: exit 2, nothing written.\n");
  push->callback([o, action] { *action = [o] { return RunPushImport(*o); }; });
}

}  // namespace arena::cli
