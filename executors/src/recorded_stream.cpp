// Reading a recorded true stream back from an `arena export` directory, in
// each format the export writes (replay_backend.cpp serves them).
#include "recorded_stream.hpp"

#include <hdf5.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arena/hdf5/handle.hpp"

namespace arena::executors {
namespace {

using H5Object = hdf5::Handle;
using hdf5::Reason;

constexpr double kMissing = std::numeric_limits<double>::quiet_NaN();

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (char ch : line) {
    if (ch == '"') {
      quoted = !quoted;
    } else if (ch == ',' && !quoted) {
      out.push_back(cur);
      cur.clear();
    } else if (ch != '\r') {
      cur += ch;
    }
  }
  out.push_back(cur);
  return out;
}

// ---------------------------------------------------------------- HDF5

// HDF5 reports errors on its own stack; printing it to stderr is off, per
// thread (the library keeps one stack per thread).
void QuietHdf5() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

std::string TypeName(hid_t type) {
  switch (H5Tget_class(type)) {
    case H5T_INTEGER:
      return std::to_string(8 * H5Tget_size(type)) + "-bit integers";
    case H5T_FLOAT:
      return std::to_string(8 * H5Tget_size(type)) + "-bit floats";
    case H5T_STRING:
      return "strings";
    case H5T_COMPOUND:
      return "a compound type";
    default:
      return "another type";
  }
}

}  // namespace

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument(path + ": cannot read it");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

int RecordedStream::Column(const std::string& name) const {
  for (size_t i = 0; i < columns.size(); ++i)
    if (columns[i] == name) return static_cast<int>(i);
  return -1;
}

namespace {
std::vector<double> ParseCsvRow(const std::string& path, int number, const std::string& line,
                                const std::vector<std::string>& columns) {
  const auto cells = SplitCsv(line);
  if (cells.size() != columns.size())
    throw std::invalid_argument(path + ": line " + std::to_string(number) + ": " +
                                std::to_string(cells.size()) + " fields, the header has " +
                                std::to_string(columns.size()));
  std::vector<double> row(cells.size(), kMissing);
  for (size_t k = 0; k < cells.size(); ++k) {
    if (cells[k].empty()) continue;  // a missing value
    const char* end = cells[k].data() + cells[k].size();
    const auto r = std::from_chars(cells[k].data(), end, row[k]);
    if (r.ec != std::errc() || r.ptr != end)
      throw std::invalid_argument(path + ": line " + std::to_string(number) + ", column '" +
                                  columns[k] + "': not a number: '" + cells[k] + "'");
  }
  return row;
}
}  // namespace

std::size_t StreamCsv(const std::string& path, const ColumnsFn& on_columns, const RowFn& on_row) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument(path + ": cannot read it");
  std::string line;
  if (!std::getline(in, line)) throw std::invalid_argument(path + ": empty (no header line)");
  const std::vector<std::string> columns = SplitCsv(line);
  on_columns(columns);
  std::size_t rows = 0;
  for (int number = 2; std::getline(in, line); ++number) {
    if (line.empty() || line == "\r") continue;
    ++rows;
    if (!on_row(ParseCsvRow(path, number, line, columns))) break;
  }
  return rows;
}

std::size_t StreamJsonl(const std::string& path, const ColumnsFn& on_columns, const RowFn& on_row) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument(path + ": cannot read it");
  std::vector<std::string> columns;
  std::map<std::string, size_t> index;
  std::string line;
  std::size_t rows = 0;
  for (int number = 1; std::getline(in, line); ++number) {
    if (line.empty()) continue;
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded() || !j.is_object())
      throw std::invalid_argument(path + ": line " + std::to_string(number) +
                                  ": not a JSON object");
    if (rows == 0) {
      for (auto it = j.begin(); it != j.end(); ++it) {
        index.emplace(it.key(), columns.size());
        columns.push_back(it.key());
      }
      on_columns(columns);
    }
    std::vector<double> row(columns.size(), kMissing);
    for (auto it = j.begin(); it != j.end(); ++it) {
      const auto at = index.find(it.key());
      if (at == index.end())
        throw std::invalid_argument(path + ": line " + std::to_string(number) + ": key '" +
                                    it.key() + "' is not among the first line's");
      if (it->is_number())
        row[at->second] = it->get<double>();
      else if (!it->is_null())
        throw std::invalid_argument(path + ": line " + std::to_string(number) + ", '" + it.key() +
                                    "': not a number");
    }
    ++rows;
    if (!on_row(row)) break;
  }
  if (rows == 0) on_columns(columns);
  return rows;
}

RecordedStream ReadCsvStream(const std::string& path) {
  RecordedStream out;
  StreamCsv(
      path, [&](const std::vector<std::string>& c) { out.columns = c; },
      [&](const std::vector<double>& r) {
        out.rows.push_back(r);
        return true;
      });
  return out;
}

RecordedStream ReadJsonlStream(const std::string& path) {
  RecordedStream out;
  StreamJsonl(
      path, [&](const std::vector<std::string>& c) { out.columns = c; },
      [&](const std::vector<double>& r) {
        out.rows.push_back(r);
        return true;
      });
  return out;
}

Hdf5Recording::Hdf5Recording(std::string path) : path_(std::move(path)) {
  QuietHdf5();
  if (const htri_t is = H5Fis_hdf5(path_.c_str()); is <= 0) {
    const std::string why = is < 0 ? Reason() : "no HDF5 signature";
    std::ifstream probe(path_);
    throw std::invalid_argument(path_ + ": " +
                                (probe ? "not an HDF5 file (" + why + ")"
                                       : std::string("missing (the export's dataset.h5)")));
  }
  file_ = H5Fopen(path_.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file_ < 0) throw std::invalid_argument(path_ + ": cannot open it: " + Reason());
  if (H5Lexists(file_, "trials", H5P_DEFAULT) <= 0) {
    H5Eclear2(H5E_DEFAULT);
    throw std::invalid_argument(path_ + ": no /trials group (not an arena export?)");
  }
}

Hdf5Recording::~Hdf5Recording() {
  if (file_ >= 0) H5Fclose(file_);
}

void Hdf5Recording::Check(std::int64_t trial_id) const { (void)Read(trial_id, false); }

RecordedStream Hdf5Recording::Read(std::int64_t trial_id) const { return Read(trial_id, true); }

RecordedStream Hdf5Recording::Read(std::int64_t trial_id, bool samples) const {
  QuietHdf5();
  const std::string group = "trials/" + std::to_string(trial_id);
  const std::string name = group + "/true";
  const std::string where = path_ + ": /" + name + ": ";
  // H5Lexists fails (not false) when a parent is missing: check each link.
  for (const std::string& link : {group, name}) {
    if (H5Lexists(file_, link.c_str(), H5P_DEFAULT) <= 0) {
      H5Eclear2(H5E_DEFAULT);
      throw std::invalid_argument(where + "missing (the trial's true stream)");
    }
  }
  H5Object ds(H5Dopen2(file_, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (ds.id < 0) throw std::invalid_argument(where + "not a dataset: " + Reason());
  H5Object type(H5Dget_type(ds.id), H5Tclose);
  if (type.id < 0) throw std::invalid_argument(where + "unreadable type: " + Reason());
  if (H5Tget_class(type.id) != H5T_FLOAT || H5Tget_size(type.id) != 8)
    throw std::invalid_argument(where + "holds " + TypeName(type.id) + ", expected 64-bit floats");
  H5Object space(H5Dget_space(ds.id), H5Sclose);
  if (space.id < 0 || H5Sget_simple_extent_ndims(space.id) != 2)
    throw std::invalid_argument(where + "must be 2-D (samples x columns)");
  hsize_t dims[2] = {0, 0};
  H5Sget_simple_extent_dims(space.id, dims, nullptr);

  // The column names: a 1-D fixed-length string attribute, one per column.
  if (H5Aexists(ds.id, "columns") <= 0) {
    H5Eclear2(H5E_DEFAULT);
    throw std::invalid_argument(where + "no \"columns\" attribute (the column names)");
  }
  H5Object attr(H5Aopen(ds.id, "columns", H5P_DEFAULT), H5Aclose);
  H5Object atype(attr.id < 0 ? -1 : H5Aget_type(attr.id), H5Tclose);
  H5Object aspace(attr.id < 0 ? -1 : H5Aget_space(attr.id), H5Sclose);
  if (atype.id < 0 || aspace.id < 0 || H5Tget_class(atype.id) != H5T_STRING)
    throw std::invalid_argument(where + "attribute \"columns\" must hold strings");
  const hssize_t names = H5Sget_simple_extent_npoints(aspace.id);
  if (names < 0 || static_cast<hsize_t>(names) != dims[1])
    throw std::invalid_argument(where + "attribute \"columns\" names " + std::to_string(names) +
                                " columns, the dataset has " + std::to_string(dims[1]));
  RecordedStream out;
  if (H5Tis_variable_str(atype.id) > 0) {  // arena writes fixed-length; h5py variable-length
    H5Object text(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(text.id, H5T_VARIABLE);
    H5Tset_cset(text.id, H5Tget_cset(atype.id));
    std::vector<char*> p(static_cast<size_t>(names), nullptr);
    if (H5Aread(attr.id, text.id, p.data()) < 0)
      throw std::invalid_argument(where + "cannot read attribute \"columns\": " + Reason());
    for (char* name : p) out.columns.emplace_back(name ? name : "");
    H5Dvlen_reclaim(text.id, aspace.id, H5P_DEFAULT, p.data());
  } else {
    const size_t width = H5Tget_size(atype.id);
    std::string buffer(width * static_cast<size_t>(names), '\0');
    if (H5Aread(attr.id, atype.id, buffer.data()) < 0)
      throw std::invalid_argument(where + "cannot read attribute \"columns\": " + Reason());
    for (hssize_t k = 0; k < names; ++k) {
      const char* p = buffer.data() + static_cast<size_t>(k) * width;
      out.columns.emplace_back(p, strnlen(p, width));
    }
  }
  if (!samples || dims[0] == 0) return out;
  Stream(trial_id, nullptr, [&](const std::vector<double>& r) {
    out.rows.push_back(r);
    return true;
  });
  return out;
}

std::size_t Hdf5Recording::Stream(std::int64_t trial_id, const ColumnsFn& on_columns,
                                  const RowFn& on_row) const {
  const RecordedStream head = Read(trial_id, false);
  if (on_columns) on_columns(head.columns);
  QuietHdf5();
  const std::string name = "trials/" + std::to_string(trial_id) + "/true";
  const std::string where = path_ + ": /" + name + ": ";
  H5Object ds(H5Dopen2(file_, name.c_str(), H5P_DEFAULT), H5Dclose);
  H5Object space(ds.id < 0 ? -1 : H5Dget_space(ds.id), H5Sclose);
  if (space.id < 0) throw std::invalid_argument(where + "cannot open it: " + Reason());
  hsize_t dims[2] = {0, 0};
  H5Sget_simple_extent_dims(space.id, dims, nullptr);
  const hsize_t slab = std::max<hsize_t>(
      1, std::min<hsize_t>(dims[0], (1u << 20) / 8 / std::max<hsize_t>(1, dims[1])));
  std::vector<double> flat(static_cast<size_t>(slab * dims[1]));
  std::vector<double> row(static_cast<size_t>(dims[1]));
  std::size_t rows = 0;
  for (hsize_t first = 0; first < dims[0]; first += slab) {
    const hsize_t count[2] = {std::min(slab, dims[0] - first), dims[1]};
    const hsize_t start[2] = {first, 0};
    H5Object file_space(H5Scopy(space.id), H5Sclose);
    H5Object mem(H5Screate_simple(2, count, nullptr), H5Sclose);
    if (file_space.id < 0 || mem.id < 0 ||
        H5Sselect_hyperslab(file_space.id, H5S_SELECT_SET, start, nullptr, count, nullptr) < 0 ||
        H5Dread(ds.id, H5T_NATIVE_DOUBLE, mem.id, file_space.id, H5P_DEFAULT, flat.data()) < 0)
      throw std::invalid_argument(where + "cannot read its samples: " + Reason());
    for (hsize_t i = 0; i < count[0]; ++i) {
      std::copy(flat.begin() + static_cast<std::ptrdiff_t>(i * dims[1]),
                flat.begin() + static_cast<std::ptrdiff_t>((i + 1) * dims[1]), row.begin());
      ++rows;
      if (!on_row(row)) return rows;
    }
  }
  return rows;
}

}  // namespace arena::executors
