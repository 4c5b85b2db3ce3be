// Dataset export (export.hpp describes the layout).
#include "arena/db/export.hpp"
#include "arena/db/sensitivity.hpp"

#include <fcntl.h>
#include <hdf5.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "arena/db/query.hpp"
#include "sqlite_util.hpp"
#include "store_internal.hpp"

namespace arena::db {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

const char* ToString(ExportFormat f) {
  switch (f) {
    case ExportFormat::kHdf5:
      return "hdf5";
    case ExportFormat::kCsv:
      return "csv";
    case ExportFormat::kJsonl:
      return "jsonl";
  }
  return "?";
}

namespace {

// Writing the dataset failed: the command failed, the store is fine.
[[noreturn]] void IoError(const std::string& msg) {
  throw StoreError(StoreError::Kind::kOutput, msg);
}
[[noreturn]] void Corrupt(const std::string& msg) {
  throw StoreError(StoreError::Kind::kCorrupt, msg);
}

struct Column {
  std::string name;
  std::string unit;
  std::string meaning;
};

// ---------------------------------------------------------------- stream columns

struct StreamShape {
  std::vector<std::string> contact_names;  // scene order: fingers, then pusher
  std::vector<std::string> finger_names;   // for the observed finger wrenches
};

// Column names from the scene's contacts (the caller's: db reads no scene);
// the widths from the samples (the largest count any sample has: a sample
// with fewer values is padded with NaN, a dropped observation has none).
// Positional names when the contacts disagree.
StreamShape ShapeFromContacts(const std::vector<ContactSite>& sites,
                              const std::vector<Sample>& samples) {
  std::vector<std::string> fingers;
  bool pusher = false;
  for (const auto& c : sites) {
    if (c.pusher)
      pusher = true;
    else
      fingers.push_back(c.name);
  }
  std::size_t nc = 0, nfv = 0;
  bool any_valid = false;
  for (const auto& s : samples) {
    nc = std::max(nc, s.contacts.size());
    if (s.observed_valid) nfv = std::max(nfv, s.observed_finger_wrenches.size());
    any_valid = any_valid || s.observed_valid;
  }
  if (samples.empty()) nc = fingers.size() + (pusher ? 1 : 0);  // nothing measured: the scene
  // No observation delivered: the scene's fingers (their columns all missing).
  const std::size_t nf = any_valid ? (nfv + 5) / 6 : fingers.size();
  std::vector<std::string> contacts = fingers;
  if (pusher) contacts.push_back("pusher");
  if (contacts.size() != nc) {  // the cell reported another set: name them by position
    contacts.clear();
    for (std::size_t i = 0; i < nc; ++i) contacts.push_back("contact" + std::to_string(i));
  }
  if (fingers.size() != nf) {
    fingers.clear();
    for (std::size_t i = 0; i < nf; ++i) fingers.push_back("finger" + std::to_string(i));
  }
  StreamShape shape;
  shape.contact_names = contacts;
  shape.finger_names = fingers;
  return shape;
}

void AddPose(std::vector<Column>* c, const std::string& p, const std::string& what) {
  for (const char* a : {"x", "y", "z"})
    c->push_back({p + a, "m", what + " position, gripper frame G"});
  for (const char* a : {"qw", "qx", "qy", "qz"})
    c->push_back({p + a, "1", what + " orientation quaternion (w, x, y, z) in G"});
}
void AddTwist(std::vector<Column>* c, const std::string& p, const std::string& what) {
  for (const char* a : {"vx", "vy", "vz"})
    c->push_back({p + a, "m/s", what + " linear velocity in G"});
  for (const char* a : {"wx", "wy", "wz"})
    c->push_back({p + a, "rad/s", what + " angular velocity in G"});
}
void AddWrench(std::vector<Column>* c, const std::string& p, const std::string& what) {
  for (const char* a : {"fx", "fy", "fz"})
    c->push_back({p + a, "N", what + " force on the object in G"});
  for (const char* a : {"tx", "ty", "tz"})
    c->push_back({p + a, "N m", what + " torque about the contact point in G"});
}

std::vector<Column> TrueColumns(const StreamShape& s) {
  std::vector<Column> c;
  c.push_back({"t", "s", "time since the execute phase started"});
  AddPose(&c, "", "object (true)");
  AddTwist(&c, "", "object (true)");
  AddPose(&c, "pusher_", "pusher (true)");
  AddTwist(&c, "pusher_", "pusher (true)");
  for (const auto& n : s.contact_names) {
    AddWrench(&c, n + "_", "contact '" + n + "' (true)");
    c.push_back({n + "_mode", "1", "contact mode: 0 stick, 1 slide, 2 separate"});
  }
  return c;
}

std::vector<Column> ObservedColumns(const StreamShape& s) {
  std::vector<Column> c;
  c.push_back({"t", "s", "time since the execute phase started"});
  c.push_back({"valid", "1",
               "1 if the sensors delivered this sample, 0 if dropped (then the values are not "
               "measurements)"});
  AddPose(&c, "", "object as seen by motion capture");
  AddWrench(&c, "pusher_", "pusher F/T sensor");
  for (const auto& n : s.finger_names) AddWrench(&c, n + "_", "finger '" + n + "' F/T sensor");
  return c;
}

constexpr double kMissing = std::numeric_limits<double>::quiet_NaN();

void FlattenTrue(const Sample& s, std::size_t contacts, std::vector<double>* row) {
  row->clear();
  row->push_back(s.t);
  row->insert(row->end(), s.object_pose.begin(), s.object_pose.end());
  row->insert(row->end(), s.object_twist.begin(), s.object_twist.end());
  row->insert(row->end(), s.pusher_pose.begin(), s.pusher_pose.end());
  row->insert(row->end(), s.pusher_twist.begin(), s.pusher_twist.end());
  for (std::size_t i = 0; i < contacts; ++i) {
    if (i >= s.contacts.size()) {  // a contact this sample lacks
      row->insert(row->end(), 7, kMissing);
      continue;
    }
    const auto& c = s.contacts[i];
    row->insert(row->end(), c.force.begin(), c.force.end());
    row->insert(row->end(), c.torque.begin(), c.torque.end());
    row->push_back(static_cast<double>(c.mode));
  }
}

// A dropped observation (valid = 0) carries no measurement: its values are
// missing, never zeros that look like one.
void FlattenObserved(const Sample& s, std::size_t finger_values, std::vector<double>* row) {
  row->clear();
  row->push_back(s.t);
  row->push_back(s.observed_valid ? 1 : 0);
  const std::size_t width = 7 + 6 + finger_values;
  if (!s.observed_valid) {
    row->insert(row->end(), width, kMissing);
    return;
  }
  row->insert(row->end(), s.observed_object_pose.begin(), s.observed_object_pose.end());
  row->insert(row->end(), s.observed_pusher_wrench.begin(), s.observed_pusher_wrench.end());
  for (std::size_t i = 0; i < finger_values; ++i)
    row->push_back(i < s.observed_finger_wrenches.size() ? s.observed_finger_wrenches[i]
                                                         : kMissing);
}

// Shortest text that reads back exactly; "" for a missing value (NaN).
std::string Num(double v) {
  if (!std::isfinite(v)) return "";
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest text that reads back exactly
  return std::string(buf, r.ptr);
}

// ---------------------------------------------------------------- files

void SyncFile(const fs::path& p) {
  const int fd = ::open(p.c_str(), O_RDONLY);
  if (fd < 0) IoError("export: cannot reopen '" + p.string() + "' to sync it");
  const int rc = ::fsync(fd);
  ::close(fd);
  if (rc != 0) IoError("export: fsync of '" + p.string() + "' failed");
}

void WriteText(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  if (!out) IoError("export: cannot create '" + p.string() + "'");
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.close();
  if (!out) IoError("export: cannot write '" + p.string() + "' (disk full?)");
}

std::string StreamCsv(const std::vector<Column>& cols,
                      const std::vector<std::vector<double>>& rows) {
  std::string out;
  for (std::size_t i = 0; i < cols.size(); ++i) {
    if (i) out.push_back(',');
    out.append(cols[i].name);
  }
  out.push_back('\n');
  for (const auto& r : rows) {
    for (std::size_t i = 0; i < r.size(); ++i) {
      if (i) out.push_back(',');
      out.append(Num(r[i]));
    }
    out.push_back('\n');
  }
  return out;
}

std::string StreamJsonl(const std::vector<Column>& cols,
                        const std::vector<std::vector<double>>& rows) {
  std::string out;
  for (const auto& r : rows) {
    out.push_back('{');
    for (std::size_t i = 0; i < r.size(); ++i) {
      if (i) out.push_back(',');
      out.push_back('"');
      out.append(cols[i].name);
      out.append("\":");
      const std::string n = Num(r[i]);
      out.append(n.empty() ? "null" : n);
    }
    out.append("}\n");
  }
  return out;
}

// ---------------------------------------------------------------- HDF5

struct H5Handle {
  hid_t id = -1;
  herr_t (*close)(hid_t) = nullptr;
  H5Handle(hid_t i, herr_t (*c)(hid_t), const std::string& what) : id(i), close(c) {
    if (id < 0) IoError("export: HDF5: cannot " + what);
  }
  ~H5Handle() {
    if (id >= 0) close(id);
  }
  H5Handle(const H5Handle&) = delete;
  H5Handle& operator=(const H5Handle&) = delete;
};

void H5Check(herr_t rc, const std::string& what) {
  if (rc < 0) IoError("export: HDF5: cannot " + what);
}

void H5StringArrayAttr(hid_t obj, const char* name, const std::vector<std::string>& values) {
  std::size_t len = 1;
  for (const auto& v : values) len = std::max(len, v.size() + 1);
  std::string buf(len * values.size(), '\0');
  for (std::size_t i = 0; i < values.size(); ++i) buf.replace(i * len, values[i].size(), values[i]);
  H5Handle type(H5Tcopy(H5T_C_S1), H5Tclose, "copy string type");
  H5Check(H5Tset_size(type.id, len), "size string type");
  H5Check(H5Tset_strpad(type.id, H5T_STR_NULLTERM), "pad string type");
  const hsize_t dims[1] = {values.size()};
  H5Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose, "create attribute space");
  H5Handle attr(H5Acreate2(obj, name, type.id, space.id, H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
                std::string("create attribute ") + name);
  H5Check(H5Awrite(attr.id, type.id, buf.data()), std::string("write attribute ") + name);
}

void H5ScalarAttr(hid_t obj, const std::string& name, const Value& v) {
  if (std::holds_alternative<std::monostate>(v)) return;  // missing: no attribute
  H5Handle space(H5Screate(H5S_SCALAR), H5Sclose, "create scalar space");
  if (const auto* i = std::get_if<std::int64_t>(&v)) {
    H5Handle a(H5Acreate2(obj, name.c_str(), H5T_STD_I64LE, space.id, H5P_DEFAULT, H5P_DEFAULT),
               H5Aclose, "create attribute " + name);
    H5Check(H5Awrite(a.id, H5T_NATIVE_INT64, i), "write attribute " + name);
  } else if (const auto* d = std::get_if<double>(&v)) {
    H5Handle a(H5Acreate2(obj, name.c_str(), H5T_IEEE_F64LE, space.id, H5P_DEFAULT, H5P_DEFAULT),
               H5Aclose, "create attribute " + name);
    H5Check(H5Awrite(a.id, H5T_NATIVE_DOUBLE, d), "write attribute " + name);
  } else {
    const auto& s = std::get<std::string>(v);
    H5Handle type(H5Tcopy(H5T_C_S1), H5Tclose, "copy string type");
    H5Check(H5Tset_size(type.id, s.size() + 1), "size string type");
    H5Handle a(H5Acreate2(obj, name.c_str(), type.id, space.id, H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
               "create attribute " + name);
    H5Check(H5Awrite(a.id, type.id, s.c_str()), "write attribute " + name);
  }
}

// A text too long for an HDF5 attribute (64 KiB header limit), e.g. a very
// large scene: a scalar string dataset of the same name instead.
void H5TextDataset(hid_t group, const std::string& name, const std::string& text) {
  H5Handle type(H5Tcopy(H5T_C_S1), H5Tclose, "copy string type");
  H5Check(H5Tset_size(type.id, text.size() + 1), "size string type");
  H5Handle space(H5Screate(H5S_SCALAR), H5Sclose, "create scalar space");
  H5Handle ds(
      H5Dcreate2(group, name.c_str(), type.id, space.id, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
      H5Dclose, "create dataset " + name);
  H5Check(H5Dwrite(ds.id, type.id, H5S_ALL, H5S_ALL, H5P_DEFAULT, text.c_str()),
          "write dataset " + name);
}

void H5Matrix(hid_t group, const char* name, const std::vector<Column>& cols,
              const std::vector<std::vector<double>>& rows) {
  const hsize_t n = rows.size(), k = cols.size();
  std::vector<double> flat;
  flat.reserve(n * k);
  for (const auto& r : rows) flat.insert(flat.end(), r.begin(), r.end());
  const hsize_t dims[2] = {n, k};
  H5Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose, "create dataspace");
  H5Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, "create dataset properties");
  if (n > 0 && k > 0) {
    const hsize_t chunk[2] = {std::min<hsize_t>(n, 1024), k};
    H5Check(H5Pset_chunk(dcpl.id, 2, chunk), "set chunk");
    H5Check(H5Pset_shuffle(dcpl.id), "set shuffle");
    H5Check(H5Pset_deflate(dcpl.id, 4), "set deflate");
  }
  H5Handle ds(H5Dcreate2(group, name, H5T_IEEE_F64LE, space.id, H5P_DEFAULT, dcpl.id, H5P_DEFAULT),
              H5Dclose, std::string("create dataset ") + name);
  if (n > 0 && k > 0) {
    H5Check(H5Dwrite(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, flat.data()),
            std::string("write dataset ") + name);
  }
  std::vector<std::string> names, units;
  for (const auto& c : cols) {
    names.push_back(c.name);
    units.push_back(c.unit);
  }
  H5StringArrayAttr(ds.id, "columns", names);
  H5StringArrayAttr(ds.id, "units", units);
}

// ---------------------------------------------------------------- index

const std::map<std::string, std::pair<std::string, std::string>>& IndexColumnDocs() {
  static const std::map<std::string, std::pair<std::string, std::string>> kDocs = {
      {"trial_id", {"1", "trial id in the store"}},
      {"idx", {"1", "index of the trial within the campaign"}},
      {"condition", {"1", "condition index"}},
      {"replicate", {"1", "replicate of the condition, 0-based"}},
      {"seed", {"1", "per-trial seed (unsigned 64-bit)"}},
      {"state", {"", "trial state at export time"}},
      {"attempt", {"1", "attempt whose ground truth is exported"}},
      {"cell_id", {"", "cell that executed it"}},
      {"outcome", {"", "result reported by the cell (ok, ...)"}},
      {"object_shape", {"", "box or cylinder"}},
      {"object_mass", {"kg", "object mass"}},
      {"grip_force", {"N", "gripping force per finger"}},
      {"finger_type", {"", "point, line, patch or mixed"}},
      {"finger_count", {"1", "number of fingers"}},
      {"finger_mu", {"1", "mean friction coefficient of the fingers"}},
      {"pusher_type", {"", "pusher contact type (empty: no pusher)"}},
      {"pusher_mu", {"1", "pusher friction coefficient"}},
      {"pusher_speed", {"m/s", "|pusher velocity| relative to the gripper"}},
      {"pusher_angular_speed", {"rad/s", "|pusher angular velocity|"}},
      {"duration", {"s", "scene duration"}},
      {"start_position_error",
       {"m", "observed start position after the preceding reset minus nominal"}},
      {"start_angle_error", {"rad", "angle between observed start and nominal orientation"}},
      {"reset_ok", {"1", "1 if the reset after this trial was verified"}},
      {"samples", {"1", "samples in the streams"}},
      {"observed_samples", {"1", "samples the sensors did not drop"}},
      {"duration_s", {"s", "time of the last sample"}},
      {"displacement_m", {"m", "|final - first| true object position"}},
      {"rotation_rad", {"rad", "angle between first and final true orientation"}},
      {"max_contact_force_n", {"N", "largest contact force magnitude"}},
      {"stick_fraction", {"1", "share of contact-samples sticking"}},
      {"slide_fraction", {"1", "share of contact-samples sliding"}},
      {"separate_fraction", {"1", "share of contact-samples separated"}},
      {"model_key", {"", "fidelity label of the prediction"}},
      {"prediction_status", {"", "ok, solver_failure, ..."}},
      {"final_position_error", {"m", "|predicted - true| final object position"}},
      {"final_angle_error", {"rad", "angle between predicted and true final orientation"}},
      {"force_error", {"N", "RMS contact force error"}},
      {"mode_agreement", {"1", "share of contact-samples with the predicted mode"}},
      {"predictor_wall_s", {"s", "predictor wall time"}},
      {"true_file", {"", "file of the true stream (csv/jsonl)"}},
      {"observed_file", {"", "file of the observed stream (csv/jsonl)"}},
      {"predicted_file", {"", "file of the predicted stream (csv/jsonl)"}},
      {"max_pusher_force_n", {"N", "largest pusher contact force magnitude"}},
      {"net_dx", {"m", "object translation, last minus first sample, x in G"}},
      {"net_dy", {"m", "object translation, last minus first sample, y in G"}},
      {"net_dz", {"m", "object translation, last minus first sample, z in G"}},
      {"net_rx", {"rad", "object rotation first -> last sample as rotation vector, x in G"}},
      {"net_ry", {"rad", "object rotation first -> last sample as rotation vector, y in G"}},
      {"net_rz", {"rad", "object rotation first -> last sample as rotation vector, z in G"}},
      {"grasp_kept", {"1", "1 if every finger still touched the object at the last sample"}},
      {"predicted_by", {"", "model setting key of the exported predicted stream"}},
      {"predicted_settings", {"", "model settings (JSON) of the exported predicted stream"}},
      {"predicted_status", {"", "ok, solver_failure, invalid_scene, error"}},
      {"predicted_error", {"", "why there is no predicted stream (empty when ok)"}},
      {"predicted_samples", {"1", "samples in the predicted stream"}},
      {"scene_json", {"", "the trial's full scene (JSON; docs/scene.md)"}},
  };
  return kDocs;
}

// The trial index; the last three columns are for the export's own use.
constexpr const char* kIndexSql =
    "SELECT t.id AS trial_id, t.idx, t.condition, t.replicate, t.seed, t.state, t.attempt,"
    " t.cell_id, t.outcome, t.object_shape, t.object_mass, t.grip_force, t.finger_type,"
    " t.finger_count, t.finger_mu, t.pusher_type, t.pusher_mu, t.pusher_speed,"
    " t.pusher_angular_speed, t.duration, t.start_position_error, t.start_angle_error,"
    " t.reset_ok, s.samples, s.observed_samples, s.duration_s, s.displacement_m,"
    " s.rotation_rad, s.max_contact_force_n, s.stick_fraction, s.slide_fraction,"
    " s.separate_fraction, p.model_key, p.status AS prediction_status,"
    " p.final_position_error, p.final_angle_error, p.force_error, p.mode_agreement,"
    " p.wall_s AS predictor_wall_s, s.max_pusher_force_n, s.net_dx, s.net_dy, s.net_dz,"
    " s.net_rx, s.net_ry, s.net_rz, s.grasp_kept,"
    " t.gt_stream_id, t.scene_json, t.params_json"
    " FROM trials t JOIN gt_summary s ON s.stream_id = t.gt_stream_id"
    " LEFT JOIN predictions p ON p.id ="
    "  (SELECT MIN(id) FROM predictions WHERE trial_id = t.id AND attempt = t.attempt)"
    " WHERE t.campaign_id = ? ORDER BY t.idx";
constexpr std::size_t kSeedCol = 4, kSamplesCol = 23;

constexpr const char* kContactSql =
    "SELECT c.trial_id, c.contact, c.name AS contact_name, c.role, c.stick_fraction,"
    " c.slide_fraction, c.separate_fraction, c.slip_distance_m, c.max_normal_force_n"
    " FROM contact_outcomes c JOIN trials t ON t.gt_stream_id = c.stream_id"
    " WHERE t.campaign_id = ? ORDER BY t.idx, c.contact";

Value ColumnValue(const detail::Stmt& s, int c) {
  switch (sqlite3_column_type(s.get(), c)) {
    case SQLITE_NULL:
      return std::monostate{};
    case SQLITE_INTEGER:
      return static_cast<std::int64_t>(s.Int(c));
    case SQLITE_FLOAT:
      return s.Real(c);
    default:
      return s.Text(c);
  }
}

ojson ColumnsJson(const std::vector<Column>& cols) {
  ojson a = ojson::array();
  for (const auto& c : cols)
    a.push_back({{"name", c.name}, {"unit", c.unit}, {"meaning", c.meaning}});
  return a;
}

std::string IsoNow() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::uint64_t CountLines(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::uint64_t n = 0;
  char buf[1 << 16];
  while (in) {
    in.read(buf, sizeof buf);
    for (std::streamsize i = 0; i < in.gcount(); ++i) n += buf[i] == '\n';
  }
  return n;
}

// A parameter's JSON value as an index value (arrays and objects as JSON text).
Value ParamValue(const ojson& v) {
  if (v.is_number_integer()) return static_cast<std::int64_t>(v.get<std::int64_t>());
  if (v.is_number()) return v.get<double>();
  if (v.is_boolean()) return static_cast<std::int64_t>(v.get<bool>() ? 1 : 0);
  if (v.is_string()) return v.get<std::string>();
  if (v.is_null()) return std::monostate{};
  return v.dump();
}

// The scene on one line (it is a CSV field and an HDF5 attribute).
std::string CompactScene(const std::string& text) {
  try {
    return ojson::parse(text).dump();
  } catch (const nlohmann::json::exception&) {
    std::string out = text;
    for (char& c : out)
      if (c == '\n' || c == '\r') c = ' ';
    return out;
  }
}

// The trial index of a campaign: the columns of kIndexSql, one column per
// parameter the campaign varied (names as in trial_results), the scene.
struct TrialIndex {
  QueryResult table;
  std::vector<std::int64_t> stream_ids;
  std::vector<std::string> scenes;  // as stored (for the stream shapes)
};

TrialIndex ReadIndex(const Store::Impl& impl, std::int64_t campaign_id) {
  TrialIndex out;
  std::vector<ojson> params;
  detail::Stmt s(impl.db, kIndexSql);
  s.Bind(1, campaign_id);
  const int ncol = sqlite3_column_count(s.get()) - 3;  // gt_stream_id, scene, params: internal
  for (int c = 0; c < ncol; ++c) out.table.columns.emplace_back(sqlite3_column_name(s.get(), c));
  while (s.Step()) {
    std::vector<Value> row;
    for (int c = 0; c < ncol; ++c) row.push_back(ColumnValue(s, c));
    // Seeds are uint64 stored bit for bit in int64: export the unsigned value.
    row[kSeedCol] =
        std::to_string(static_cast<std::uint64_t>(std::get<std::int64_t>(row[kSeedCol])));
    out.table.rows.push_back(std::move(row));
    out.stream_ids.push_back(s.Int(ncol));
    out.scenes.push_back(s.Text(ncol + 1));
    try {
      params.push_back(ojson::parse(s.Text(ncol + 2)));
    } catch (const nlohmann::json::exception&) {
      params.push_back(ojson::object());
    }
  }
  // Parameter columns, in the order the campaign lists them; a name that is
  // already a column (grip_force, ...) is that column (read from the scene).
  std::vector<std::string> names;
  std::set<std::string> have(out.table.columns.begin(), out.table.columns.end());
  for (const auto& p : params) {
    if (!p.is_object()) continue;
    for (const auto& item : p.items()) {
      if (have.insert(item.key()).second) names.push_back(item.key());
    }
  }
  for (const auto& n : names) out.table.columns.push_back(n);
  out.table.columns.push_back("scene_json");
  for (std::size_t i = 0; i < out.table.rows.size(); ++i) {
    for (const auto& n : names) {
      out.table.rows[i].push_back(params[i].is_object() && params[i].contains(n)
                                      ? ParamValue(params[i][n])
                                      : Value(std::monostate{}));
    }
    out.table.rows[i].emplace_back(CompactScene(out.scenes[i]));
  }
  return out;
}

// Every format: each trial's full scene as commanded, one JSON line per
// trial, so the dataset can be served as a cell (replay:DIR,
// examples/drivers/replay.py) matched by scene.
std::string ScenesJsonl(const TrialIndex& index) {
  std::string lines;
  for (std::size_t i = 0; i < index.scenes.size(); ++i) {
    ojson scene;
    try {
      scene = ojson::parse(index.scenes[i]);
    } catch (const nlohmann::json::exception&) {
      scene = nullptr;
    }
    lines += ojson({{"trial_id", std::get<std::int64_t>(index.table.rows[i][0])},
                    {"seed", std::get<std::string>(index.table.rows[i][kSeedCol])},
                    {"scene", scene}})
                 .dump() +
             "\n";
  }
  return lines;
}

// Per-contact outcomes of the campaign's exported trials, by trial id.
// Closed loop (issue 19): the runs and applied commands of the attempts whose
// ground truth is exported.
constexpr const char* kClosedLoopRunSql =
    "SELECT r.trial_id, r.attempt, r.controller, r.lockstep, r.target, r.gain, r.tolerance,"
    " r.hold_s, r.reached, r.final_error, r.settle_time_s, r.held, r.loop_p50_ms,"
    " r.loop_p99_ms, r.failure"
    " FROM closed_loop_runs r JOIN trials t ON t.id = r.trial_id AND t.attempt = r.attempt"
    " JOIN gt_summary s ON s.stream_id = t.gt_stream_id"
    " WHERE t.campaign_id = ? ORDER BY t.idx";
constexpr const char* kClosedLoopCommandSql =
    "SELECT c.trial_id, c.attempt, c.sample, c.t, c.vx, c.vy, c.vz, c.applied_vx, c.applied_vy,"
    " c.applied_vz, c.loop_ms"
    " FROM closed_loop_commands c JOIN trials t ON t.id = c.trial_id AND t.attempt = c.attempt"
    " JOIN gt_summary s ON s.stream_id = t.gt_stream_id"
    " WHERE t.campaign_id = ? ORDER BY t.idx, c.sample";
constexpr std::size_t kCommandFirstCol = 2;  // sample: trial_id and attempt come first

// Rows of `sql` (bound to the campaign; column 0 the trial id), and which
// rows belong to which trial.
QueryResult ReadByTrial(const Store::Impl& impl, const char* sql, std::int64_t campaign_id,
                        std::map<std::int64_t, std::vector<std::size_t>>* by_trial);

QueryResult ReadContacts(const Store::Impl& impl, std::int64_t campaign_id,
                         std::map<std::int64_t, std::vector<std::size_t>>* by_trial) {
  return ReadByTrial(impl, kContactSql, campaign_id, by_trial);
}

QueryResult ReadByTrial(const Store::Impl& impl, const char* sql, std::int64_t campaign_id,
                        std::map<std::int64_t, std::vector<std::size_t>>* by_trial) {
  QueryResult out;
  detail::Stmt s(impl.db, sql);
  s.Bind(1, campaign_id);
  for (int c = 0; c < sqlite3_column_count(s.get()); ++c)
    out.columns.emplace_back(sqlite3_column_name(s.get(), c));
  while (s.Step()) {
    std::vector<Value> row;
    for (int c = 0; c < sqlite3_column_count(s.get()); ++c) row.push_back(ColumnValue(s, c));
    (*by_trial)[s.Int(0)].push_back(out.rows.size());
    out.rows.push_back(std::move(row));
  }
  return out;
}

const std::vector<Column>& ContactColumns() {
  static const std::vector<Column> kCols = {
      {"contact", "1", "contact index in scene order (fingers, then the pusher)"},
      {"stick_fraction", "1", "share of the contact's samples sticking"},
      {"slide_fraction", "1", "share of the contact's samples sliding"},
      {"separate_fraction", "1", "share of the contact's samples separated"},
      {"slip_distance_m", "m", "tangential path of the object at the contact relative to it"},
      {"max_normal_force_n", "N", "largest force along the contact normal"}};
  return kCols;
}

const std::vector<Column>& CommandColumns() {
  static const std::vector<Column> kCols = {
      {"sample", "1", "the live sample the command answered; applied from the next model step"},
      {"t", "s", "time of that sample since the trial started"},
      {"vx", "m/s", "commanded pusher velocity, x (gripper frame)"},
      {"vy", "m/s", "commanded pusher velocity, y"},
      {"vz", "m/s", "commanded pusher velocity, z"},
      {"applied_vx", "m/s", "actuated pusher velocity (with the cell's actuation noise), x"},
      {"applied_vy", "m/s", "actuated pusher velocity, y"},
      {"applied_vz", "m/s", "actuated pusher velocity, z"},
      {"loop_ms", "ms",
       "live sample written -> command accepted by the cell; missing: no fresh command, the "
       "last one held"}};
  return kCols;
}

double AsDouble(const Value& v) {
  if (const auto* i = std::get_if<std::int64_t>(&v)) return static_cast<double>(*i);
  if (const auto* d = std::get_if<double>(&v)) return *d;
  return kMissing;
}

// What a killed export (SIGKILL, power loss) left in `parent`: staging
// directories ".NAME.partial-PID-XXXXXX" of a process that no longer runs,
// and ones of the older ".NAME.partial-XXXXXX" form not touched for an hour.
// Removed before the next export there starts; a live export's is kept.
void RemoveDeadStagingDirs(const fs::path& parent) {
  std::error_code ec;
  for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const std::size_t at = name.rfind(".partial-");
    if (name.empty() || name[0] != '.' || at == std::string::npos) continue;
    std::error_code kind;
    if (!it->is_directory(kind) || it->is_symlink(kind)) continue;
    const std::string tail = name.substr(at + 9);  // "PID-XXXXXX" or "XXXXXX"
    const std::size_t dash = tail.find('-');
    bool dead = false;
    if (dash != std::string::npos && dash > 0 && tail.find_first_not_of("0123456789") == dash) {
      const long pid = std::strtol(tail.substr(0, dash).c_str(), nullptr, 10);
      dead = pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
    } else if (dash == std::string::npos) {
      const auto age = fs::file_time_type::clock::now() - fs::last_write_time(it->path(), kind);
      dead = !kind && age > std::chrono::hours(1);
    }
    if (dead) fs::remove_all(it->path(), kind);
  }
}

// A new directory next to the target, on the same file system, that becomes
// the target by one rename(2) at the end; removed with everything in it if
// the export fails before.
class StagingDir {
 public:
  explicit StagingDir(const fs::path& target) {
    const fs::path parent = target.parent_path().empty() ? fs::path(".") : target.parent_path();
    std::error_code ec;
    fs::create_directories(parent, ec);
    RemoveDeadStagingDirs(parent);
    // The pid in the name lets the next export tell a live one's directory
    // from one a killed export left.
    std::string tmpl = (parent / ("." + target.filename().string() + ".partial-" +
                                  std::to_string(::getpid()) + "-XXXXXX"))
                           .string();
    if (::mkdtemp(tmpl.data()) == nullptr) {
      IoError("export: cannot create a directory in '" + parent.string() +
              "': " + std::strerror(errno) + " (is it writable?)");
    }
    path_ = tmpl;
    // mkdtemp makes it private (0700); the dataset gets what mkdir would give it.
    const mode_t mask = ::umask(0);
    ::umask(mask);
    ::chmod(path_.c_str(), 0777 & ~mask);
  }
  ~StagingDir() {
    if (path_.empty()) return;
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  StagingDir(const StagingDir&) = delete;
  StagingDir& operator=(const StagingDir&) = delete;
  const fs::path& path() const { return path_; }

  void MoveTo(const fs::path& target) {
    // rename(2) replaces an empty directory atomically; a non-empty one was refused up front.
    if (::rename(path_.c_str(), target.c_str()) != 0) {
      IoError("export: cannot move the finished dataset to '" + target.string() +
              "': " + std::strerror(errno));
    }
    path_.clear();
    const fs::path parent = target.parent_path().empty() ? fs::path(".") : target.parent_path();
    const int fd = ::open(parent.c_str(), O_RDONLY | O_DIRECTORY);
    if (fd >= 0) {
      ::fsync(fd);
      ::close(fd);
    }
  }

 private:
  fs::path path_;
};

// The files of one export (one format) in the staging directory.
class DatasetWriter {
 public:
  DatasetWriter(fs::path dir, ExportFormat format) : dir_(std::move(dir)), format_(format) {
    if (format_ == ExportFormat::kHdf5) {
      H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors become exceptions, not stderr noise
      h5_ = std::make_unique<H5Handle>(
          H5Fcreate((dir_ / "dataset.h5").c_str(), H5F_ACC_EXCL, H5P_DEFAULT, H5P_DEFAULT),
          H5Fclose, "create dataset.h5");
      H5Handle g(H5Gcreate2(h5_->id, "trials", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
                 "create /trials");
    } else {
      std::error_code ec;
      fs::create_directories(dir_ / "streams", ec);
      if (ec) IoError("export: cannot create streams/: " + ec.message());
    }
  }
  bool files_per_trial() const { return format_ != ExportFormat::kHdf5; }

  // One stream of a trial ("true", "observed", "predicted"): an HDF5 dataset
  // of group `group`, or a file whose name it returns.
  std::string Stream(const std::string& id, const char* which, const std::vector<Column>& cols,
                     const std::vector<std::vector<double>>& rows, hid_t group) {
    if (format_ == ExportFormat::kHdf5) {
      H5Matrix(group, which, cols, rows);
      return "";
    }
    const bool csv = format_ == ExportFormat::kCsv;
    const std::string file = "streams/" + id + "_" + which + (csv ? ".csv" : ".jsonl");
    WriteText(dir_ / file, csv ? StreamCsv(cols, rows) : StreamJsonl(cols, rows));
    return file;
  }

  hid_t file() const { return h5_ ? h5_->id : -1; }

  void Close(std::int64_t campaign_id) {
    if (!h5_) return;
    H5ScalarAttr(h5_->id, "format_version", Value(std::int64_t{kDatasetFormatVersion}));
    H5ScalarAttr(h5_->id, "campaign_id", Value(campaign_id));
    H5Check(H5Fflush(h5_->id, H5F_SCOPE_GLOBAL), "flush dataset.h5");
    h5_.reset();
  }

 private:
  fs::path dir_;
  ExportFormat format_;
  std::unique_ptr<H5Handle> h5_;
};

void WriteJsonLines(const fs::path& p, const QueryResult& table) {
  std::string lines;
  for (const auto& obj : ojson::parse(FormatJson(table))) lines += obj.dump() + "\n";
  WriteText(p, lines);
}

// Checksums of every file in `dir`, in a stable order.
ojson ChecksumFiles(const fs::path& dir, ExportReport* report) {
  std::vector<fs::path> paths;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) paths.push_back(e.path());
  }
  std::sort(paths.begin(), paths.end());
  ojson files = ojson::array();
  for (const auto& p : paths) {
    SyncFile(p);
    ExportedFile f;
    f.path = fs::relative(p, dir).generic_string();
    f.bytes = fs::file_size(p);
    f.sha256 = Sha256File(p.string());
    files.push_back({{"path", f.path}, {"bytes", f.bytes}, {"sha256", f.sha256}});
    report->files.push_back(std::move(f));
  }
  return files;
}

ojson IndexColumnsJson(const std::vector<std::string>& columns,
                       const std::set<std::string>& parameters) {
  ojson out = ojson::array();
  for (const auto& c : columns) {
    const auto it = IndexColumnDocs().find(c);
    if (it != IndexColumnDocs().end()) {
      out.push_back({{"name", c}, {"unit", it->second.first}, {"meaning", it->second.second}});
    } else {
      out.push_back({{"name", c},
                     {"unit", ""},
                     {"meaning", parameters.count(c) ? "varied parameter of the campaign "
                                                       "(as in its \"variations\"; SI units)"
                                                     : ""}});
    }
  }
  return out;
}

// Everything the per-trial loop collects for the manifest.
struct TrialsWritten {
  ojson manifest = ojson::array();
  std::vector<Column> true_cols, obs_cols, predicted_cols;
  double sample_rate = 0;
};

// A trial's contacts from the caller's reader of scenes; a scene it cannot
// read has none (its columns are named by position).
std::vector<ContactSite> SceneContacts(const ExportOptions& o, const std::string& scene_json) {
  try {
    return o.scene_facts(scene_json).contacts;
  } catch (const std::exception&) {
    return {};
  }
}

// Writes one trial's streams (and HDF5 group); appends its index values.
// Rows of a by-trial table that belong to one trial.
struct TrialRows {
  const QueryResult& table;
  const std::vector<std::size_t>& rows;
};

// A closed-loop trial's applied commands: as a matrix (CommandColumns() per
// row) and as the commands its prediction replays.
struct AppliedCommands {
  std::vector<std::vector<double>> matrix;
  std::vector<ClosedLoopCommand> commands;
};

AppliedCommands ReadAppliedCommands(TrialRows rows) {
  AppliedCommands out;
  for (std::size_t r : rows.rows) {
    const auto& c = rows.table.rows[r];
    std::vector<double> m;
    for (std::size_t k = kCommandFirstCol; k < c.size(); ++k) m.push_back(AsDouble(c[k]));
    ClosedLoopCommand cmd;
    cmd.sample = static_cast<int>(std::get<std::int64_t>(c[kCommandFirstCol]));
    cmd.t = m[1];
    for (int k = 0; k < 3; ++k) {
      cmd.commanded[k] = m[2 + k];
      cmd.applied[k] = m[5 + k];
    }
    if (!std::isnan(m[8])) cmd.loop_ms = m[8];
    out.commands.push_back(cmd);
    out.matrix.push_back(std::move(m));
  }
  return out;
}

// The caller's prediction of the trial (ExportOptions::predict*); a
// prediction that throws is a stream with status error and its message.
PredictedStream PredictTrial(const ExportOptions& o, const std::string& scene_json,
                             const std::string& spec_json,
                             const std::vector<ClosedLoopCommand>& applied,
                             const std::vector<Sample>& samples) {
  try {
    return o.predict_from ? o.predict_from(scene_json, spec_json, applied,
                                           samples.empty() ? nullptr : &samples.front())
           : !applied.empty() && o.predict_closed_loop
               ? o.predict_closed_loop(scene_json, spec_json, applied)
               : o.predict(scene_json, spec_json);
  } catch (const std::exception& e) {
    PredictedStream failed;
    failed.status = PredictionStatus::kError;
    failed.error = e.what();
    return failed;
  }
}

// Per-contact outcomes as a matrix (contacts x ContactColumns()).
struct ContactMatrix {
  std::vector<std::vector<double>> matrix;
  std::vector<std::string> names, roles;
};

ContactMatrix ReadContactMatrix(TrialRows rows) {
  ContactMatrix out;
  for (std::size_t r : rows.rows) {
    const auto& c = rows.table.rows[r];
    out.matrix.push_back({AsDouble(c[1]), AsDouble(c[4]), AsDouble(c[5]), AsDouble(c[6]),
                          AsDouble(c[7]), AsDouble(c[8])});
    out.names.push_back(std::get<std::string>(c[2]));
    out.roles.push_back(std::get<std::string>(c[3]));
  }
  return out;
}

// HDF5: the trial's index values as the group's attributes (a large text as
// a dataset), its contact outcomes and applied commands as datasets.
void WriteGroupTables(hid_t gid, const std::vector<std::string>& columns,
                      const std::vector<Value>& irow, const ContactMatrix& contacts,
                      const AppliedCommands& commands) {
  for (std::size_t c = 0; c < columns.size() && c < irow.size(); ++c) {
    const auto* text = std::get_if<std::string>(&irow[c]);
    if (text && text->size() > 60000)
      H5TextDataset(gid, columns[c], *text);
    else
      H5ScalarAttr(gid, columns[c], irow[c]);
  }
  if (!contacts.matrix.empty()) {
    H5Matrix(gid, "contacts", ContactColumns(), contacts.matrix);
    H5Handle ds(H5Dopen2(gid, "contacts", H5P_DEFAULT), H5Dclose, "open contacts");
    H5StringArrayAttr(ds.id, "contact_names", contacts.names);
    H5StringArrayAttr(ds.id, "roles", contacts.roles);
  }
  if (!commands.matrix.empty()) H5Matrix(gid, "commands", CommandColumns(), commands.matrix);
}

// The trial's streams as rows of the true and observed columns.
struct StreamRows {
  std::vector<std::vector<double>> true_rows, obs_rows;
};

StreamRows FlattenStreams(const std::vector<Sample>& samples, const StreamShape& shape) {
  StreamRows out;
  std::vector<double> row;
  const std::size_t nfv = 6 * shape.finger_names.size();
  for (const auto& s : samples) {
    FlattenTrue(s, shape.contact_names.size(), &row);
    out.true_rows.push_back(row);
    FlattenObserved(s, nfv, &row);
    out.obs_rows.push_back(row);
  }
  return out;
}

void WriteTrial(const Store::Impl& impl, const ExportOptions& o, const Campaign& campaign,
                const TrialIndex& index, std::size_t i, std::vector<Value>* irow,
                const std::vector<std::string>& columns, TrialRows contacts, TrialRows commands,
                DatasetWriter* writer, TrialsWritten* out, ExportReport* report) {
  const auto trial_id = std::get<std::int64_t>((*irow)[0]);
  const auto expected = std::get<std::int64_t>((*irow)[kSamplesCol]);
  const auto samples = internal::ReadStreamSamples(impl, index.stream_ids[i], expected, "export");
  const StreamShape shape = ShapeFromContacts(SceneContacts(o, index.scenes[i]), samples);
  const auto true_cols = TrueColumns(shape);
  const auto obs_cols = ObservedColumns(shape);
  if (out->true_cols.empty()) {
    out->true_cols = true_cols;
    out->obs_cols = obs_cols;
  }
  if (out->sample_rate == 0 && samples.size() >= 2 && samples.back().t > samples.front().t) {
    out->sample_rate =
        static_cast<double>(samples.size() - 1) / (samples.back().t - samples.front().t);
  }
  const StreamRows streams = FlattenStreams(samples, shape);
  const AppliedCommands applied = ReadAppliedCommands(commands);
  std::optional<PredictedStream> predicted;
  std::vector<std::vector<double>> pred_rows;
  if (o.predict) {
    predicted = PredictTrial(o, index.scenes[i], campaign.spec_json, applied.commands, samples);
    std::vector<double> row;
    for (const auto& s : predicted->samples) {
      FlattenTrue(s, shape.contact_names.size(), &row);
      pred_rows.push_back(row);
    }
    irow->emplace_back(predicted->predictor);
    irow->emplace_back(predicted->settings_json);
    irow->emplace_back(std::string(ToString(predicted->status)));
    irow->emplace_back(predicted->error);
    irow->emplace_back(static_cast<std::int64_t>(predicted->samples.size()));
    if (out->predicted_cols.empty()) out->predicted_cols = true_cols;
  }

  const std::string id = std::to_string(trial_id);
  ojson tm = {{"trial_id", trial_id},
              {"samples", samples.size()},
              {"true_columns", true_cols.size()},
              {"observed_columns", obs_cols.size()}};
  if (predicted) tm["predicted_samples"] = predicted->samples.size();
  if (!commands.rows.empty()) tm["commands"] = commands.rows.size();
  std::unique_ptr<H5Handle> group;
  if (!writer->files_per_trial()) {
    const std::string gname = "trials/" + id;
    group = std::make_unique<H5Handle>(
        H5Gcreate2(writer->file(), gname.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
        "create group /" + gname);
    tm["group"] = "/" + gname;
  }
  const hid_t gid = group ? group->id : -1;
  const std::string tf = writer->Stream(id, "true", true_cols, streams.true_rows, gid);
  const std::string of = writer->Stream(id, "observed", obs_cols, streams.obs_rows, gid);
  std::string pf;
  if (predicted) pf = writer->Stream(id, "predicted", true_cols, pred_rows, gid);
  if (group) {
    WriteGroupTables(gid, columns, *irow, ReadContactMatrix(contacts), applied);
  } else {
    irow->emplace_back(tf);
    irow->emplace_back(of);
    tm["true_file"] = tf;
    tm["observed_file"] = of;
    if (predicted) {
      irow->emplace_back(pf);
      tm["predicted_file"] = pf;
    }
  }
  tm["true_columns_list"] = ColumnsJson(true_cols);
  tm["observed_columns_list"] = ColumnsJson(obs_cols);
  out->manifest.push_back(std::move(tm));
  report->samples += static_cast<std::int64_t>(samples.size());
}

// The trial parameters of the index: the sampler's columns, and variations
// written into the scene (grip_force, finger_type, ...) that have their own
// scene-derived column; they are parameters all the same.
std::set<std::string> IndexParameters(const Store::Impl& impl, const TrialIndex& index,
                                      const Campaign& campaign) {
  std::set<std::string> parameters;
  const std::size_t base =
      static_cast<std::size_t>(sqlite3_column_count(detail::Stmt(impl.db, kIndexSql).get())) - 3;
  for (std::size_t c = base; c + 1 < index.table.columns.size(); ++c)
    parameters.insert(index.table.columns[c]);
  const auto spec = nlohmann::json::parse(campaign.spec_json, nullptr, false);
  if (spec.is_object() && spec.contains("variations") && spec["variations"].is_object()) {
    for (const auto& [name, value] : spec["variations"].items()) {
      if (std::find(index.table.columns.begin(), index.table.columns.end(), name) !=
          index.table.columns.end())
        parameters.insert(name);
    }
  }
  return parameters;
}

// The columns each index row gets: the stored ones, then (same order as
// WriteTrial) the prediction's and the per-trial files'.
std::vector<std::string> IndexColumns(const ExportOptions& o, const TrialIndex& index,
                                      const DatasetWriter& writer) {
  std::vector<std::string> columns = index.table.columns;
  if (o.predict) {
    for (const char* c : {"predicted_by", "predicted_settings", "predicted_status",
                          "predicted_error", "predicted_samples"})
      columns.emplace_back(c);
  }
  if (writer.files_per_trial()) {
    columns.emplace_back("true_file");
    columns.emplace_back("observed_file");
    if (o.predict) columns.emplace_back("predicted_file");
  }
  return columns;
}

// The tables read in the export's snapshot, beside the index.
struct ByTrialTables {
  QueryResult contacts, runs, commands;
  std::map<std::int64_t, std::vector<std::size_t>> contacts_by_trial, runs_by_trial,
      commands_by_trial;
};

ByTrialTables ReadByTrialTables(const Store::Impl& impl, std::int64_t campaign_id) {
  ByTrialTables t;
  t.contacts = ReadContacts(impl, campaign_id, &t.contacts_by_trial);
  t.runs = ReadByTrial(impl, kClosedLoopRunSql, campaign_id, &t.runs_by_trial);
  t.commands = ReadByTrial(impl, kClosedLoopCommandSql, campaign_id, &t.commands_by_trial);
  return t;
}

// Every trial's streams, in index order; an error names the trial.
void WriteTrials(const Store::Impl& impl, const ExportOptions& o, const Campaign& campaign,
                 TrialIndex* index, const std::vector<std::string>& columns,
                 const ByTrialTables& tables, DatasetWriter* writer, TrialsWritten* written,
                 ExportReport* report) {
  static const std::vector<std::size_t> kNone;
  const auto total = static_cast<std::int64_t>(index->table.rows.size());
  for (std::size_t i = 0; i < index->table.rows.size(); ++i) {
    auto& irow = index->table.rows[i];
    const auto trial_id = std::get<std::int64_t>(irow[0]);
    const auto it = tables.contacts_by_trial.find(trial_id);
    const auto ct = tables.commands_by_trial.find(trial_id);
    try {
      WriteTrial(impl, o, campaign, *index, i, &irow, columns,
                 {tables.contacts, it == tables.contacts_by_trial.end() ? kNone : it->second},
                 {tables.commands, ct == tables.commands_by_trial.end() ? kNone : ct->second},
                 writer, written, report);
    } catch (const StoreError& e) {
      std::string what = e.what();
      if (what.rfind("export: ", 0) == 0) what = what.substr(8);
      throw StoreError(e.kind(), "export: trial " + std::to_string(trial_id) + " (index " +
                                     std::to_string(std::get<std::int64_t>(irow[1])) +
                                     "): " + what);
    }
    if (o.progress) o.progress(static_cast<std::int64_t>(i) + 1, total);
  }
  report->trials = total;
}

// The by-trial tables as CSV (and JSON lines for the jsonl format), the
// scenes, and the campaign's latest sensitivity run (db/sensitivity.hpp).
void WriteTables(const Store& store, const ExportOptions& o, const fs::path& dir,
                 const TrialIndex& index, const ByTrialTables& tables) {
  WriteText(dir / "trials.csv", FormatCsv(index.table));
  WriteText(dir / "contacts.csv", FormatCsv(tables.contacts));
  WriteText(dir / "scenes.jsonl", ScenesJsonl(index));
  WriteSensitivityExport(store, o.campaign_id, dir.string());
  if (!tables.runs.rows.empty()) {
    WriteText(dir / "closed_loop.csv", FormatCsv(tables.runs));
    WriteText(dir / "closed_loop_commands.csv", FormatCsv(tables.commands));
  }
  if (o.format == ExportFormat::kJsonl) {
    WriteJsonLines(dir / "trials.jsonl", index.table);
    WriteJsonLines(dir / "contacts.jsonl", tables.contacts);
    if (!tables.runs.rows.empty()) {
      WriteJsonLines(dir / "closed_loop.jsonl", tables.runs);
      WriteJsonLines(dir / "closed_loop_commands.jsonl", tables.commands);
    }
  }
}

// A producer's own files (ExportOptions::extra_files), inside the dataset only.
void WriteExtraFiles(const ExportOptions& o, const fs::path& dir) {
  for (const auto& [rel, text] : o.extra_files) {
    const fs::path r(rel);
    if (rel.empty() || r.is_absolute() || rel.find("..") != std::string::npos ||
        rel == "manifest.json")
      throw StoreError(
          StoreError::Kind::kBadInput,
          "export: extra file '" + rel + "' must be a relative path inside the dataset");
    std::error_code ec;
    if (fs::exists(dir / r, ec))
      throw StoreError(StoreError::Kind::kBadInput,
                       "export: extra file '" + rel + "' is one the export writes itself");
    if (r.has_parent_path()) fs::create_directories(dir / r.parent_path(), ec);
    WriteText(dir / r, text);
  }
}

ojson ContactColumnsJson() {
  ojson contact_cols = ojson::array();
  contact_cols.push_back({{"name", "trial_id"}, {"unit", "1"}, {"meaning", "trial id"}});
  contact_cols.push_back(
      {{"name", "contact_name"}, {"unit", ""}, {"meaning", "finger name, or pusher"}});
  contact_cols.push_back({{"name", "role"}, {"unit", ""}, {"meaning", "finger or pusher"}});
  for (const auto& c : ContactColumns())
    contact_cols.push_back({{"name", c.name}, {"unit", c.unit}, {"meaning", c.meaning}});
  return contact_cols;
}

// The keys of manifest_extra_json, set after the export's own.
void MergeManifestExtra(const ExportOptions& o, ojson* manifest) {
  if (o.manifest_extra_json.empty()) return;
  ojson extra;
  try {
    extra = ojson::parse(o.manifest_extra_json);
  } catch (const nlohmann::json::exception& e) {
    throw StoreError(StoreError::Kind::kBadInput,
                     std::string("export: manifest_extra_json is not JSON: ") + e.what());
  }
  if (!extra.is_object())
    throw StoreError(StoreError::Kind::kBadInput,
                     "export: manifest_extra_json must be a JSON object");
  for (auto it = extra.begin(); it != extra.end(); ++it) (*manifest)[it.key()] = it.value();
}

void AddClosedLoopManifest(ojson* manifest) {
  ojson cmd_cols = ojson::array();
  cmd_cols.push_back({{"name", "trial_id"}, {"unit", "1"}, {"meaning", "trial id"}});
  cmd_cols.push_back({{"name", "attempt"}, {"unit", "1"}, {"meaning", "the exported attempt"}});
  for (const auto& c : CommandColumns())
    cmd_cols.push_back({{"name", c.name}, {"unit", c.unit}, {"meaning", c.meaning}});
  (*manifest)["columns"]["closed_loop_commands"] = cmd_cols;
  (*manifest)["closed_loop"] =
      "closed_loop.csv: one row per closed-loop trial (controller, its settings and own "
      "outcome; target, final_error and tolerance in the controller's units: rad for "
      "pivot_to_angle, m for sliding_to_position); closed_loop_commands.csv: every pusher "
      "command the cell applied. Predictions of these trials replay the commanded velocities "
      "through the model.";
}

// What manifest.json says beside the files: the campaign, frames, columns,
// parameters, counts.
struct ManifestParts {
  const std::vector<std::string>& columns;
  const std::set<std::string>& parameters;
  const TrialsWritten& written;
  const ExportReport& report;
  ojson files;
  bool closed_loop = false;
};

ojson Manifest(const Store& store, const ExportOptions& o, const Campaign& campaign,
               const ManifestParts& m) {
  ojson spec;
  try {
    spec = ojson::parse(campaign.spec_json);
  } catch (const nlohmann::json::exception&) {
    spec = campaign.spec_json;
  }
  ojson manifest = {
      {"format", "arena-dataset"},
      {"format_version", kDatasetFormatVersion},
      {"export_format", ToString(o.format)},
      {"created_at", IsoNow()},
      {"arena_version", o.arena_version},
      {"arena_commit", o.arena_commit},
      {"store_schema_version", store.FileSchemaVersion()},
      {"campaign",
       {{"id", campaign.id},
        {"name", campaign.name},
        {"state", ToString(campaign.state)},
        {"seed", std::to_string(campaign.seed)},
        {"spec", spec}}},
      {"frames",
       {{"G",
         "gripper frame at the start of the trial; every pose, twist and wrench is "
         "expressed in it; quaternions are (w, x, y, z)"}}},
      {"sample_rate_hz", std::round(m.written.sample_rate * 1000) / 1000},
      {"counts",
       {{"trials", m.report.trials}, {"samples", m.report.samples}, {"files", m.files.size()}}},
      {"columns",
       {{"trials", IndexColumnsJson(m.columns, m.parameters)},
        {"contacts", ContactColumnsJson()},
        {"true", ColumnsJson(m.written.true_cols)},
        {"observed", ColumnsJson(m.written.obs_cols)}}},
      {"parameters", ojson(std::vector<std::string>(m.parameters.begin(), m.parameters.end()))},
      {"predictions",
       o.predict ? "re-run per trial with the campaign's \"prediction\" settings, as the service "
                   "ran it; columns as \"true\" (predicted_by / predicted_settings say which)"
                 : "not exported"},
      {"missing_values",
       "CSV: empty field; JSON: null; HDF5: NaN in datasets, absent attribute in groups. A "
       "dropped observation (valid = 0) has every observed value missing."},
      {"trials", m.written.manifest},
      {"files", m.files},
  };
  if (o.predict) manifest["columns"]["predicted"] = ColumnsJson(m.written.predicted_cols);
  MergeManifestExtra(o, &manifest);
  if (m.closed_loop) AddClosedLoopManifest(&manifest);
  return manifest;
}

// Last and atomically: a complete manifest marks a complete dataset.
void WriteManifest(const fs::path& dir, const ojson& manifest) {
  const fs::path tmp = dir / "manifest.json.tmp";
  WriteText(tmp, manifest.dump(2) + "\n");
  SyncFile(tmp);
  std::error_code ec;
  fs::rename(tmp, dir / "manifest.json", ec);
  if (ec) IoError("export: cannot rename the manifest into place: " + ec.message());
}

// Writes every file of the dataset into `dir` (the staging directory).
ExportReport WriteDataset(const Store& store, const ExportOptions& o, const fs::path& dir) {
  const auto& impl = store.impl();
  detail::Tx snapshot(impl.db, false);  // everything below reads one consistent state
  const Campaign campaign = store.GetCampaign(o.campaign_id);
  TrialIndex index = ReadIndex(impl, o.campaign_id);
  const ByTrialTables tables = ReadByTrialTables(impl, o.campaign_id);
  const std::set<std::string> parameters = IndexParameters(impl, index, campaign);
  DatasetWriter writer(dir, o.format);
  const std::vector<std::string> columns = IndexColumns(o, index, writer);

  ExportReport report;
  TrialsWritten written;
  WriteTrials(impl, o, campaign, &index, columns, tables, &writer, &written, &report);
  snapshot.Commit();
  writer.Close(o.campaign_id);

  index.table.columns = columns;
  WriteTables(store, o, dir, index, tables);
  WriteExtraFiles(o, dir);
  const ojson files = ChecksumFiles(dir, &report);
  WriteManifest(dir,
                Manifest(store, o, campaign,
                         {columns, parameters, written, report, files, !tables.runs.rows.empty()}));
  return report;
}

// Records of a CSV file: line ends outside quoted fields (a scene or a
// reason may hold a quoted newline).
std::uint64_t CountCsvRecords(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::uint64_t n = 0;
  bool quoted = false;
  char buf[1 << 16];
  while (in) {
    in.read(buf, sizeof buf);
    for (std::streamsize i = 0; i < in.gcount(); ++i) {
      if (buf[i] == '"') quoted = !quoted;  // a doubled quote toggles twice
      n += buf[i] == '\n' && !quoted;
    }
  }
  return n;
}

}  // namespace

ExportReport ExportCampaign(const Store& store, const ExportOptions& o) {
  if (o.out_dir.empty()) throw StoreError(StoreError::Kind::kBadInput, "export: --out is empty");
  if (!o.scene_facts) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "export: ExportOptions::scene_facts is not set (db reads no scene)");
  }
  fs::path dir = fs::path(o.out_dir).lexically_normal();
  if (!dir.has_filename()) dir = dir.parent_path();  // "out/" names "out"
  store.GetCampaign(o.campaign_id);                  // kNotFound before anything is created
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec)) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "export: '" + o.out_dir + "' is a file; --out names a new directory");
  }
  if (fs::exists(dir, ec) && !fs::is_empty(dir, ec)) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "export: '" + o.out_dir + "' is not empty; choose a new directory");
  }
  StagingDir staging(dir);
  ExportReport report = WriteDataset(store, o, staging.path());
  const ExportReport verified = VerifyExport(staging.path().string());
  if (verified.trials != report.trials || verified.samples != report.samples) {
    Corrupt("export: verification counted other trials/samples than were written");
  }
  staging.MoveTo(dir);
  report.dir = o.out_dir;
  return report;
}

ExportReport VerifyExport(const std::string& dir_text) {
  const fs::path dir(dir_text);
  std::ifstream in(dir / "manifest.json");
  if (!in) Corrupt("verify: no manifest.json in '" + dir_text + "' (an interrupted export?)");
  ojson m;
  try {
    m = ojson::parse(in);
  } catch (const nlohmann::json::exception& e) {
    Corrupt(std::string("verify: manifest.json is not valid JSON: ") + e.what());
  }
  if (m.value("format", "") != "arena-dataset")
    Corrupt("verify: manifest.json is not an arena dataset");
  if (m.value("format_version", 0) > kDatasetFormatVersion) {
    Corrupt("verify: dataset format version " + std::to_string(m.value("format_version", 0)) +
            " is newer than this arena's");
  }
  ExportReport r;
  r.dir = dir_text;
  std::set<std::string> listed;
  for (const auto& f : m.at("files")) {
    ExportedFile ef;
    ef.path = f.at("path").get<std::string>();
    // A listed path stays inside the dataset (no absolute path, no "..").
    const fs::path rel(ef.path);
    bool outside = ef.path.empty() || rel.is_absolute();
    for (const auto& part : rel.lexically_normal()) outside = outside || part == "..";
    if (outside) Corrupt("verify: '" + ef.path + "' is not a path inside the dataset");
    ef.bytes = f.at("bytes").get<std::uint64_t>();
    ef.sha256 = f.at("sha256").get<std::string>();
    const fs::path p = dir / ef.path;
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) Corrupt("verify: '" + ef.path + "' is missing");
    if (fs::file_size(p) != ef.bytes) Corrupt("verify: '" + ef.path + "' has the wrong size");
    if (Sha256File(p.string()) != ef.sha256) Corrupt("verify: '" + ef.path + "' checksum mismatch");
    listed.insert(ef.path);
    r.files.push_back(ef);
  }
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    // A symlink would let a checksum vouch for a file outside the dataset.
    if (e.is_symlink())
      Corrupt("verify: '" + fs::relative(e.path(), dir).generic_string() +
              "' is a symbolic link (a dataset holds its own files)");
    if (!e.is_regular_file()) continue;
    const auto rel = fs::relative(e.path(), dir).generic_string();
    if (rel != "manifest.json" && !listed.count(rel))
      Corrupt("verify: '" + rel + "' is not in the manifest");
  }
  const std::string format = m.value("export_format", "");
  std::int64_t samples = 0;
  {
    std::set<std::int64_t> ids;
    for (const auto& t : m.at("trials"))
      if (!ids.insert(t.at("trial_id").get<std::int64_t>()).second)
        Corrupt("verify: trial " + t.at("trial_id").dump() + " is listed twice");
  }
  if (format == "hdf5") {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    H5Handle file(H5Fopen((dir / "dataset.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose,
                  "open dataset.h5");
    for (const auto& t : m.at("trials")) {
      for (const char* which : {"true", "observed", "predicted"}) {
        const bool predicted = std::string(which) == "predicted";
        if (predicted && !t.contains("predicted_samples")) continue;
        const std::string name = t.at("group").get<std::string>() + "/" + which;
        H5Handle ds(H5Dopen2(file.id, name.c_str(), H5P_DEFAULT), H5Dclose, "open " + name);
        H5Handle space(H5Dget_space(ds.id), H5Sclose, "get space of " + name);
        hsize_t dims[2] = {0, 0};
        if (H5Sget_simple_extent_ndims(space.id) != 2) Corrupt("verify: " + name + " is not 2-D");
        H5Sget_simple_extent_dims(space.id, dims, nullptr);
        if (dims[0] != t.at(predicted ? "predicted_samples" : "samples").get<std::uint64_t>())
          Corrupt("verify: " + name + " sample count");
      }
      if (t.contains("commands")) {
        const std::string name = t.at("group").get<std::string>() + "/commands";
        H5Handle ds(H5Dopen2(file.id, name.c_str(), H5P_DEFAULT), H5Dclose, "open " + name);
        H5Handle space(H5Dget_space(ds.id), H5Sclose, "get space of " + name);
        hsize_t dims[2] = {0, 0};
        H5Sget_simple_extent_dims(space.id, dims, nullptr);
        if (dims[0] != t.at("commands").get<std::uint64_t>())
          Corrupt("verify: " + name + " command count");
      }
      samples += t.at("samples").get<std::int64_t>();
    }
  } else {
    const bool csv = format == "csv";
    for (const auto& t : m.at("trials")) {
      const auto n = t.at("samples").get<std::uint64_t>();
      for (const char* key : {"true_file", "observed_file", "predicted_file"}) {
        const bool predicted = std::string(key) == "predicted_file";
        if (predicted && !t.contains(key)) continue;
        const auto path = t.at(key).get<std::string>();
        const auto rows = predicted ? t.at("predicted_samples").get<std::uint64_t>() : n;
        if (CountLines(dir / path) != rows + (csv ? 1 : 0))
          Corrupt("verify: '" + path + "' sample count");
      }
      samples += static_cast<std::int64_t>(n);
    }
  }
  r.trials = static_cast<std::int64_t>(m.at("trials").size());
  r.samples = samples;
  if (m.at("counts").at("samples").get<std::int64_t>() != samples ||
      m.at("counts").at("trials").get<std::int64_t>() != r.trials) {
    Corrupt("verify: counts in the manifest do not match the streams");
  }
  if (CountCsvRecords(dir / "trials.csv") != static_cast<std::uint64_t>(r.trials) + 1) {
    Corrupt("verify: trials.csv row count");
  }
  // Closed loop: every applied command of the manifest's trials is there.
  std::uint64_t commands = 0;
  for (const auto& t : m.at("trials")) commands += t.value("commands", std::uint64_t{0});
  if (commands > 0 && CountCsvRecords(dir / "closed_loop_commands.csv") != commands + 1)
    Corrupt("verify: closed_loop_commands.csv row count");
  return r;
}

}  // namespace arena::db
