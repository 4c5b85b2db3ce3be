// A recorded trial's true stream as `arena export` wrote it, read back for
// replay:DATASET: one row per sample, columns named as the export names them
// (db/include/arena/db/export.hpp: t, x..qz, vx..wz, pusher_x.., then per
// contact NAME_fx..NAME_tz and NAME_mode). A missing value (an empty CSV
// field, a JSON null, an HDF5 NaN) is NaN.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace arena::executors {

struct RecordedStream {
  std::vector<std::string> columns;
  std::vector<std::vector<double>> rows;  // rows[i].size() == columns.size()
  // The index of a column, or -1.
  int Column(const std::string& name) const;
};

// A whole file. @throws std::invalid_argument "PATH: cannot read it".
std::string ReadText(const std::string& path);

// Row by row, in bounded memory (a 2 GiB stream is never held whole):
// on_columns once with the column names, then on_row for each row until it
// returns false. @returns the rows passed to on_row.
using ColumnsFn = std::function<void(const std::vector<std::string>&)>;
using RowFn = std::function<bool(const std::vector<double>&)>;

// The export's file formats ("csv", "jsonl", "hdf5"; manifest.json's export_format).
// @throws std::invalid_argument naming the file and what is wrong with it.
RecordedStream ReadCsvStream(const std::string& path);
RecordedStream ReadJsonlStream(const std::string& path);
std::size_t StreamCsv(const std::string& path, const ColumnsFn& on_columns, const RowFn& on_row);
// A JSON-lines stream's columns are the keys of its first line (the export
// writes every key on every line); a later line's other key is refused.
std::size_t StreamJsonl(const std::string& path, const ColumnsFn& on_columns, const RowFn& on_row);

// dataset.h5 of `arena export --format hdf5`: /trials/<trial_id>/true, a 2-D
// float64 dataset (samples x columns) whose attribute "columns" names them.
// Read through the HDF5 C API; every error names the file and the object.
class Hdf5Recording {
 public:
  // Opens the file read-only (a truncated or non-HDF5 file is refused here).
  // @throws std::invalid_argument "PATH: REASON".
  explicit Hdf5Recording(std::string path);
  ~Hdf5Recording();
  Hdf5Recording(const Hdf5Recording&) = delete;
  Hdf5Recording& operator=(const Hdf5Recording&) = delete;

  // Checks the trial's true stream without reading its samples: present,
  // 2-D, float64, with as many column names as columns.
  // @throws std::invalid_argument "PATH: /trials/ID/true: REASON".
  void Check(std::int64_t trial_id) const;
  // @throws std::invalid_argument as Check, or when the samples cannot be read.
  RecordedStream Read(std::int64_t trial_id) const;
  // The samples in slabs of a few thousand rows (bounded memory).
  std::size_t Stream(std::int64_t trial_id, const ColumnsFn& on_columns, const RowFn& on_row) const;

 private:
  RecordedStream Read(std::int64_t trial_id, bool samples) const;
  std::string path_;
  std::int64_t file_ = -1;  // an hid_t (HDF5 stays out of this header)
};

}  // namespace arena::executors
