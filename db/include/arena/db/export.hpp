// Dataset export (`arena export`): one directory per campaign that a user
// can take away and read without arena.
//
// Layout of DIR (format version 2; version 1 had no parameters, scene,
// predictions or contact outcomes; its files and columns are all still there):
//   trials.csv               the trial index (every format): parameters (one column
//                            per varied parameter of the campaign), outcome, start-state
//                            error, ground-truth summary and object outcome, stored
//                            prediction error, the re-run prediction's predictor and
//                            setting, and the full scene JSON (scene_json)
//   sensitivity.csv          only when the campaign has a sensitivity run: its latest run,
//                            one row per condition (db/sensitivity.hpp)
//   contacts.csv             one row per (trial, contact): stick/slide/separate
//                            fractions, slip distance, largest normal force
//   hdf5:  dataset.h5        /trials/<trial_id>/true, /observed, /predicted, /contacts:
//                            2-D float64 datasets (rows x columns), column names
//                            and units as attributes "columns"/"units"; the trial's
//                            index row (scene_json included) as scalar attributes of
//                            its group (a missing value is an absent attribute; a text
//                            over 60,000 bytes, e.g. a huge scene, is a string dataset
//                            of that name instead: HDF5 attributes stop at 64 KiB)
//   csv:   streams/<trial_id>_true.csv, _observed.csv, _predicted.csv
//   jsonl: trials.jsonl, contacts.jsonl, streams/<trial_id>_true.jsonl, _observed.jsonl,
//          _predicted.jsonl (one JSON object per line, keys = column names)
//   closed_loop.csv          only when the campaign has closed-loop trials (issue 19): one row
//                            per exported attempt: controller, lockstep, target, gain, tolerance,
//                            hold time, the controller's outcome (reached, final error, settle
//                            time), held samples, loop latency p50/p99, failure
//   closed_loop_commands.csv one row per pusher command the cell applied: the sample it answered
//                            (applied from the next step), t, commanded and actuated velocity
//                            (m/s, gripper frame), loop latency (empty: held); jsonl also
//                            closed_loop.jsonl, closed_loop_commands.jsonl; hdf5 also
//                            /trials/<trial_id>/commands (same columns but trial and attempt)
//   scenes.jsonl             (every format) one line per trial: {"trial_id", "seed",
//                            "scene"}: the scene as commanded (replay:DIR serves it)
//   manifest.json            format version, campaign spec, arena version and commit, units
//                            and frames of every column, sample rate, counts, and the
//                            size and SHA-256 of every other file
// A value that is not there (a dropped observation: valid = 0; a contact a
// sample lacks) is NaN in HDF5, an empty field in CSV and null in JSON.
//
// The dataset is written into a temporary directory next to DIR (same file
// system), verified there, and renamed to DIR at the end: DIR appears whole
// or not at all, and a failed export leaves nothing behind (so it can be
// retried as it was). An error names the trial at fault.
//
// The export reads the store in one snapshot (one read transaction), so it is
// consistent while a service keeps writing; it includes every trial whose
// ground truth is published (state executed or later).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "arena/db/store.hpp"

namespace arena::db {

enum class ExportFormat { kHdf5, kCsv, kJsonl };
const char* ToString(ExportFormat format);

inline constexpr int kDatasetFormatVersion = 2;

// A trial's predicted trajectory and contact forces, beside the truth. db
// does not run the model (it knows nothing of mechanics): the caller passes
// a predictor (ExportOptions::predict).
struct PredictedStream {
  PredictionStatus status = PredictionStatus::kOk;
  std::string predictor;             // the model setting's key, e.g. g4_k3_dt0.008_auto
  std::string settings_json = "{}";  // the settings that made it
  std::string error;                 // why there is no prediction ("" when ok)
  // Same layout as the truth: t, object pose and twist, pusher pose and
  // twist, contacts (force on the object in G, torque, mode); observed_* unused.
  std::vector<Sample> samples;
};

struct ExportOptions {
  std::int64_t campaign_id = 0;
  ExportFormat format = ExportFormat::kHdf5;
  std::string out_dir;        // created; must not exist or be empty
  std::string arena_version;  // arena::Version() (lives in cli; passed in)
  std::string arena_commit;   // arena::GitCommit()
  // The prediction of one trial from its scene and the campaign's spec
  // (both JSON); empty: no predicted streams.
  std::function<PredictedStream(const std::string& scene_json, const std::string& spec_json)>
      predict;
  // Closed loop (issue 19): the prediction of a closed-loop trial, which
  // replays the pusher commands its cell applied (in sample order); empty:
  // `predict` is called for those trials too.
  std::function<PredictedStream(const std::string& scene_json, const std::string& spec_json,
                                const std::vector<ClosedLoopCommand>& commands)>
      predict_closed_loop;
  // When set (with `predict`), used instead of both: the prediction also
  // given the first sample of the trial's stream, the start pose its cell
  // measured, which the service's prediction started from (issue 26);
  // `commands` empty for an open-loop trial.
  std::function<PredictedStream(const std::string& scene_json, const std::string& spec_json,
                                const std::vector<ClosedLoopCommand>& commands,
                                const Sample* first_sample)>
      predict_from;
  // The facts of a stored scene (its contacts name the stream columns);
  // required: db reads no scene.
  SceneFactsFn scene_facts;
  // Called after each trial with (trials written, trials to write).
  std::function<void(std::int64_t, std::int64_t)> progress;
  // Files a producer adds to the dataset (path relative to it, '/' separated, no
  // "..": e.g. an importer's campaign.json and import report): written before
  // the checksums, so the manifest lists them like every other file.
  std::vector<std::pair<std::string, std::string>> extra_files;
  // A JSON object whose keys are set in manifest.json after export's own (an
  // importer's "truth": "measured", its "frames"); "" adds nothing.
  std::string manifest_extra_json;
};

struct ExportedFile {
  std::string path;  // relative to the dataset directory, '/' separated
  std::uint64_t bytes = 0;
  std::string sha256;  // lower-case hex
};

struct ExportReport {
  std::string dir;
  std::int64_t trials = 0;
  std::int64_t samples = 0;
  std::vector<ExportedFile> files;  // every file but manifest.json
};

// Writes the dataset, then verifies it (VerifyExport).
// @throws StoreError: kNotFound (no campaign), kBadInput (directory not empty
//   or a file), kOutput (cannot write the dataset), kCorrupt (unreadable
//   ground truth in the store, or verification failed); nothing is left in
//   or beside out_dir then.
ExportReport ExportCampaign(const Store& store, const ExportOptions& options);

// Re-reads manifest.json and checks every listed file's size and SHA-256, that
// no file is missing, and the sample counts of the streams.
// @throws StoreError(kCorrupt) naming the first mismatch.
ExportReport VerifyExport(const std::string& dir);

// SHA-256 through OpenSSL's EVP digest, lower-case hex.
std::string Sha256Hex(const void* data, std::size_t size);
std::string Sha256File(const std::string& path);

}  // namespace arena::db
