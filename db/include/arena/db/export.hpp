// Dataset export (`arena export`): one directory per campaign that a user
// can take away and read without arena.
//
// Layout of DIR (format version 1):
//   trials.csv               the trial index (every format): parameters, outcome,
//                            start-state error, ground-truth summary, prediction error
//   hdf5:  dataset.h5        /trials/<trial_id>/true, /trials/<trial_id>/observed:
//                            2-D float64 datasets (samples x columns), column names
//                            and units as attributes "columns"/"units"; the trial's
//                            index row as scalar attributes of its group (a missing
//                            value is an absent attribute)
//   csv:   streams/<trial_id>_true.csv, streams/<trial_id>_observed.csv
//   jsonl: trials.jsonl, streams/<trial_id>_true.jsonl, streams/<trial_id>_observed.jsonl
//                            (one JSON object per line, keys = column names)
//   scenes.jsonl             (every format) one line per trial: {"trial_id", "seed",
//                            "scene"}: the scene as commanded (replay:DIR serves it)
//   manifest.json            written last, atomically (temp file + rename): format
//                            version, campaign spec, arena version and commit, units
//                            and frames of every column, sample rate, counts, and the
//                            size and SHA-256 of every other file
// A directory without manifest.json is an interrupted export.
//
// The export reads the store in one snapshot (one read transaction), so it is
// consistent while a service keeps writing; it includes every trial whose
// ground truth is published (state executed or later).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "arena/db/store.hpp"

namespace arena::db {

enum class ExportFormat { kHdf5, kCsv, kJsonl };
const char* ToString(ExportFormat format);

inline constexpr int kDatasetFormatVersion = 1;

struct ExportOptions {
  std::int64_t campaign_id = 0;
  ExportFormat format = ExportFormat::kHdf5;
  std::string out_dir;        // created; must not exist or be empty
  std::string arena_version;  // arena::Version() (lives in cli; passed in)
  std::string arena_commit;   // arena::GitCommit()
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
// @throws StoreError: kNotFound (no campaign), kBadInput (directory not empty),
//   kIo (cannot write), kCorrupt (verification failed).
ExportReport ExportCampaign(const Store& store, const ExportOptions& options);

// Re-reads manifest.json and checks every listed file's size and SHA-256, that
// no file is missing, and the sample counts of the streams.
// @throws StoreError(kCorrupt) naming the first mismatch.
ExportReport VerifyExport(const std::string& dir);

// SHA-256 (FIPS 180-4; our own small implementation, no OpenSSL), lower-case hex.
std::string Sha256Hex(const void* data, std::size_t size);
std::string Sha256File(const std::string& path);

}  // namespace arena::db
