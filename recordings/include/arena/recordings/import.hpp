// Recorded trials -> a dataset that `arena cell --backend replay:DATASET`
// serves, plus DATASET/campaign.json (a campaign commanding exactly those
// trials) and the import report. Lab-neutral: an adaptor (push_dataset.hpp)
// reads its lab's files into Recordings; this does the rest.
//
// The truth of these trials is MEASURED: the streams the lab recorded are
// both the observation and the truth (no separate "true" stream exists).
// The dataset's true stream is the observed one, minus what failed its
// check: a trial whose poses failed is marked so that replay refuses to
// serve it, a trial whose force stream failed has no contact forces in its
// truth (poses are still scored, forces never). manifest.json says
// "truth": "measured".
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "arena/db/scene_facts.hpp"
#include "arena/recordings/recording.hpp"

namespace arena::recordings {

struct ImportOptions {
  std::string out_dir;        // the dataset (must not exist, or be empty)
  std::string campaign_name;  // [A-Za-z0-9_.-]{1,64}; "" -> from out_dir's name
  std::string source;         // what was imported (for the manifest), e.g. the input directory
  std::string adaptor;        // e.g. "push-dataset"
  double rate_hz = 250.0;
  // Starting values of what the recordings do not give (calibration fits them).
  double support_mu = 0.25;
  double pusher_mu = 0.25;
  CheckOptions checks;
  std::string arena_version, arena_commit;  // for the manifest
  // Called after each trial is prepared with (done, total).
  std::function<void(std::int64_t, std::int64_t)> progress;
};

// One trial as imported.
struct ImportedTrial {
  std::string name, source;
  std::string shape;
  std::uint64_t seed = 0;  // the trial's seed in the dataset and the campaign
  std::int64_t samples = 0;
  double duration = 0;  // s
  TrialChecks checks;
};

struct ImportReport {
  std::string dir;
  std::vector<ImportedTrial> trials;
  std::string text;  // the report as printed (also DATASET/import_report.txt)
};

// The trial's scene (docs/real_data.md): a prism of the recording's shape at
// its measured start pose in the table frame, resting on a support, no
// fingers, the pusher a sphere following the measured path. JSON text.
std::string SceneJson(const Recording& recording, const Resampled& streams,
                      const ImportOptions& options);
// What the store keeps of that scene (db reads no scene), from the same
// values: a prism, no fingers, a point pusher on the recorded path.
db::SceneFacts SceneFactsOf(const Recording& recording, const Resampled& streams,
                            const ImportOptions& options);

// Checks and writes everything, or nothing: the dataset is built in a
// temporary directory beside out_dir and renamed into place at the end.
// @throws ImportError naming the file and the reason (bad input; nothing
//   written), std::runtime_error when the dataset cannot be written.
ImportReport ImportRecordings(const std::vector<Recording>& recordings,
                              const ImportOptions& options);

}  // namespace arena::recordings
