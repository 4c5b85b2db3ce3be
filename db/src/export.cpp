// Dataset export (export.hpp describes the layout).
#include "arena/db/export.hpp"

#include <fcntl.h>
#include <hdf5.h>
#include <unistd.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
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

[[noreturn]] void IoError(const std::string& msg) { throw StoreError(StoreError::Kind::kIo, msg); }
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

StreamShape ShapeFromScene(const std::string& scene_json, const Sample* first) {
  StreamShape shape;
  std::vector<std::string> fingers;
  bool pusher = false;
  try {
    const auto scene = nlohmann::json::parse(scene_json);
    if (scene.contains("fingers") && scene["fingers"].is_array()) {
      for (std::size_t i = 0; i < scene["fingers"].size(); ++i) {
        const auto& f = scene["fingers"][i];
        fingers.push_back(f.contains("name") && f["name"].is_string()
                              ? f["name"].get<std::string>()
                              : "finger" + std::to_string(i));
      }
    }
    pusher = scene.contains("pusher") && scene["pusher"].is_object();
  } catch (const nlohmann::json::exception&) {
  }
  const std::size_t nc = first ? first->contacts.size() : 0;
  const std::size_t nf = first ? first->observed_finger_wrenches.size() / 6 : 0;
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

void FlattenTrue(const Sample& s, std::size_t contacts, std::vector<double>* row) {
  row->clear();
  row->push_back(s.t);
  row->insert(row->end(), s.object_pose.begin(), s.object_pose.end());
  row->insert(row->end(), s.object_twist.begin(), s.object_twist.end());
  row->insert(row->end(), s.pusher_pose.begin(), s.pusher_pose.end());
  row->insert(row->end(), s.pusher_twist.begin(), s.pusher_twist.end());
  if (s.contacts.size() != contacts)
    Corrupt("export: a sample's contact count changes within the trial");
  for (const auto& c : s.contacts) {
    row->insert(row->end(), c.force.begin(), c.force.end());
    row->insert(row->end(), c.torque.begin(), c.torque.end());
    row->push_back(static_cast<double>(c.mode));
  }
}

void FlattenObserved(const Sample& s, std::size_t finger_values, std::vector<double>* row) {
  row->clear();
  row->push_back(s.t);
  row->push_back(s.observed_valid ? 1 : 0);
  row->insert(row->end(), s.observed_object_pose.begin(), s.observed_object_pose.end());
  row->insert(row->end(), s.observed_pusher_wrench.begin(), s.observed_pusher_wrench.end());
  if (s.observed_finger_wrenches.size() != finger_values) {
    Corrupt("export: a sample's finger wrench count changes within the trial");
  }
  row->insert(row->end(), s.observed_finger_wrenches.begin(), s.observed_finger_wrenches.end());
}

std::string Num(double v) {
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
      out.append(Num(r[i]));
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
  };
  return kDocs;
}

constexpr const char* kIndexSql =
    "SELECT t.id AS trial_id, t.idx, t.condition, t.replicate, t.seed, t.state, t.attempt, "
    "t.cell_id,"
    " t.outcome, t.object_shape, t.object_mass, t.grip_force, t.finger_type, t.finger_count, "
    "t.finger_mu,"
    " t.pusher_type, t.pusher_mu, t.pusher_speed, t.pusher_angular_speed, t.duration,"
    " t.start_position_error, t.start_angle_error, t.reset_ok, s.samples, s.observed_samples,"
    " s.duration_s, s.displacement_m, s.rotation_rad, s.max_contact_force_n, s.stick_fraction,"
    " s.slide_fraction, s.separate_fraction, p.model_key, p.status AS prediction_status,"
    " p.final_position_error, p.final_angle_error, p.force_error, p.mode_agreement,"
    " p.wall_s AS predictor_wall_s, t.gt_stream_id, t.scene_json"
    " FROM trials t JOIN gt_summary s ON s.stream_id = t.gt_stream_id"
    " LEFT JOIN predictions p ON p.id ="
    "  (SELECT MIN(id) FROM predictions WHERE trial_id = t.id AND attempt = t.attempt)"
    " WHERE t.campaign_id = ? ORDER BY t.idx";

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

}  // namespace

ExportReport ExportCampaign(const Store& store, const ExportOptions& o) {
  const fs::path dir(o.out_dir);
  if (o.out_dir.empty()) throw StoreError(StoreError::Kind::kBadInput, "export: --out is empty");
  store.GetCampaign(o.campaign_id);  // kNotFound before anything is created
  std::error_code ec;
  if (fs::exists(dir) && !fs::is_empty(dir, ec)) {
    throw StoreError(StoreError::Kind::kBadInput,
                     "export: '" + o.out_dir + "' is not empty; choose a new directory");
  }
  fs::create_directories(dir / "streams", ec);
  if (ec) IoError("export: cannot create '" + o.out_dir + "': " + ec.message());
  if (o.format == ExportFormat::kHdf5) fs::remove(dir / "streams", ec);

  const auto& impl = store.impl();
  detail::Tx snapshot(impl.db, false);  // everything below reads one consistent state
  const Campaign campaign = store.GetCampaign(o.campaign_id);

  QueryResult index;
  std::vector<std::int64_t> stream_ids;
  std::vector<std::string> scenes;
  {
    detail::Stmt s(impl.db, kIndexSql);
    s.Bind(1, o.campaign_id);
    const int ncol = sqlite3_column_count(s.get()) - 2;  // gt_stream_id, scene_json are internal
    for (int c = 0; c < ncol; ++c) index.columns.emplace_back(sqlite3_column_name(s.get(), c));
    while (s.Step()) {
      std::vector<Value> row;
      for (int c = 0; c < ncol; ++c) row.push_back(ColumnValue(s, c));
      // Seeds are uint64 stored bit for bit in int64: export the unsigned value.
      const auto seed = static_cast<std::uint64_t>(std::get<std::int64_t>(row[4]));
      row[4] = std::to_string(seed);
      index.rows.push_back(std::move(row));
      stream_ids.push_back(s.Int(ncol));
      scenes.push_back(s.Text(ncol + 1));
    }
  }
  const bool files_per_trial = o.format != ExportFormat::kHdf5;
  if (files_per_trial) {
    index.columns.push_back("true_file");
    index.columns.push_back("observed_file");
  }
  const std::size_t samples_col = 23;  // index of "samples" in kIndexSql
  ExportReport report;
  report.dir = dir.string();
  ojson trials_manifest = ojson::array();
  std::vector<Column> true_cols_first, obs_cols_first;
  double sample_rate = 0;

  std::unique_ptr<H5Handle> h5;
  if (o.format == ExportFormat::kHdf5) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors become exceptions, not stderr noise
    h5 = std::make_unique<H5Handle>(
        H5Fcreate((dir / "dataset.h5").c_str(), H5F_ACC_EXCL, H5P_DEFAULT, H5P_DEFAULT), H5Fclose,
        "create " + (dir / "dataset.h5").string());
    H5Handle g(H5Gcreate2(h5->id, "trials", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
               "create /trials");
  }

  std::vector<double> row;
  for (std::size_t i = 0; i < index.rows.size(); ++i) {
    auto& irow = index.rows[i];
    const auto trial_id = std::get<std::int64_t>(irow[0]);
    const auto expected = std::get<std::int64_t>(irow[samples_col]);
    const auto samples = internal::ReadStreamSamples(impl, stream_ids[i], expected, "export");
    const StreamShape shape = ShapeFromScene(scenes[i], samples.empty() ? nullptr : &samples[0]);
    const auto true_cols = TrueColumns(shape);
    const auto obs_cols = ObservedColumns(shape);
    if (i == 0) {
      true_cols_first = true_cols;
      obs_cols_first = obs_cols;
    }
    if (sample_rate == 0 && samples.size() >= 2 && samples.back().t > samples.front().t) {
      sample_rate =
          static_cast<double>(samples.size() - 1) / (samples.back().t - samples.front().t);
    }
    std::vector<std::vector<double>> true_rows, obs_rows;
    true_rows.reserve(samples.size());
    obs_rows.reserve(samples.size());
    const std::size_t nfv = samples.empty() ? 0 : samples[0].observed_finger_wrenches.size();
    for (const auto& s : samples) {
      FlattenTrue(s, shape.contact_names.size(), &row);
      true_rows.push_back(row);
      FlattenObserved(s, nfv, &row);
      obs_rows.push_back(row);
    }
    ojson tm = {{"trial_id", trial_id},
                {"samples", samples.size()},
                {"true_columns", true_cols.size()},
                {"observed_columns", obs_cols.size()}};
    const std::string id = std::to_string(trial_id);
    if (o.format == ExportFormat::kHdf5) {
      const std::string gname = "trials/" + id;
      H5Handle g(H5Gcreate2(h5->id, gname.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
                 "create group /" + gname);
      for (std::size_t c = 0; c < index.columns.size(); ++c)
        H5ScalarAttr(g.id, index.columns[c], irow[c]);
      H5Matrix(g.id, "true", true_cols, true_rows);
      H5Matrix(g.id, "observed", obs_cols, obs_rows);
      tm["group"] = "/" + gname;
    } else {
      const std::string ext = o.format == ExportFormat::kCsv ? ".csv" : ".jsonl";
      const std::string tf = "streams/" + id + "_true" + ext,
                        of = "streams/" + id + "_observed" + ext;
      if (o.format == ExportFormat::kCsv) {
        WriteText(dir / tf, StreamCsv(true_cols, true_rows));
        WriteText(dir / of, StreamCsv(obs_cols, obs_rows));
      } else {
        WriteText(dir / tf, StreamJsonl(true_cols, true_rows));
        WriteText(dir / of, StreamJsonl(obs_cols, obs_rows));
      }
      irow.emplace_back(tf);
      irow.emplace_back(of);
      tm["true_file"] = tf;
      tm["observed_file"] = of;
    }
    tm["true_columns_list"] = ColumnsJson(true_cols);
    tm["observed_columns_list"] = ColumnsJson(obs_cols);
    trials_manifest.push_back(std::move(tm));
    report.samples += static_cast<std::int64_t>(samples.size());
  }
  report.trials = static_cast<std::int64_t>(index.rows.size());
  snapshot.Commit();

  if (h5) {
    H5ScalarAttr(h5->id, "format_version", Value(std::int64_t{kDatasetFormatVersion}));
    H5ScalarAttr(h5->id, "campaign_id", Value(o.campaign_id));
    H5Check(H5Fflush(h5->id, H5F_SCOPE_GLOBAL), "flush dataset.h5");
    h5.reset();
  }
  WriteText(dir / "trials.csv", FormatCsv(index));
  // Every format: each trial's full scene as commanded, so the dataset can be
  // served as a cell (replay:DIR, examples/drivers/replay.py) matched by scene.
  {
    std::string lines;
    for (std::size_t i = 0; i < scenes.size(); ++i) {
      ojson scene;
      try {
        scene = ojson::parse(scenes[i]);
      } catch (const nlohmann::json::exception&) {
        scene = nullptr;
      }
      lines += ojson({{"trial_id", std::get<std::int64_t>(index.rows[i][0])},
                      {"seed", std::get<std::string>(index.rows[i][4])},
                      {"scene", scene}})
                   .dump() +
               "\n";
    }
    WriteText(dir / "scenes.jsonl", lines);
  }
  if (o.format == ExportFormat::kJsonl) {
    std::string lines;
    const std::string arr = FormatJson(index);
    for (const auto& obj : ojson::parse(arr)) lines += obj.dump() + "\n";
    WriteText(dir / "trials.jsonl", lines);
  }

  // Checksums of every file, in a stable order.
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
    report.files.push_back(std::move(f));
  }

  ojson spec;
  try {
    spec = ojson::parse(campaign.spec_json);
  } catch (const nlohmann::json::exception&) {
    spec = campaign.spec_json;
  }
  ojson index_cols = ojson::array();
  for (const auto& c : index.columns) {
    const auto it = IndexColumnDocs().find(c);
    index_cols.push_back({{"name", c},
                          {"unit", it == IndexColumnDocs().end() ? "" : it->second.first},
                          {"meaning", it == IndexColumnDocs().end() ? "" : it->second.second}});
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
      {"sample_rate_hz", std::round(sample_rate * 1000) / 1000},
      {"counts", {{"trials", report.trials}, {"samples", report.samples}, {"files", files.size()}}},
      {"columns",
       {{"trials", index_cols},
        {"true", ColumnsJson(true_cols_first)},
        {"observed", ColumnsJson(obs_cols_first)}}},
      {"missing_values", "CSV: empty field; JSON: null; HDF5: attribute absent"},
      {"trials", trials_manifest},
      {"files", files},
  };
  // Last and atomically: a complete manifest marks a complete dataset.
  const fs::path tmp = dir / "manifest.json.tmp";
  WriteText(tmp, manifest.dump(2) + "\n");
  SyncFile(tmp);
  fs::rename(tmp, dir / "manifest.json", ec);
  if (ec) IoError("export: cannot rename the manifest into place: " + ec.message());
  {
    const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
    if (fd >= 0) {
      ::fsync(fd);
      ::close(fd);
    }
  }
  const ExportReport verified = VerifyExport(dir.string());
  if (verified.trials != report.trials || verified.samples != report.samples) {
    Corrupt("export: verification counted other trials/samples than were written");
  }
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
    if (!e.is_regular_file()) continue;
    const auto rel = fs::relative(e.path(), dir).generic_string();
    if (rel != "manifest.json" && !listed.count(rel))
      Corrupt("verify: '" + rel + "' is not in the manifest");
  }
  const std::string format = m.value("export_format", "");
  std::int64_t samples = 0;
  if (format == "hdf5") {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    H5Handle file(H5Fopen((dir / "dataset.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose,
                  "open dataset.h5");
    for (const auto& t : m.at("trials")) {
      for (const char* which : {"true", "observed"}) {
        const std::string name = t.at("group").get<std::string>() + "/" + which;
        H5Handle ds(H5Dopen2(file.id, name.c_str(), H5P_DEFAULT), H5Dclose, "open " + name);
        H5Handle space(H5Dget_space(ds.id), H5Sclose, "get space of " + name);
        hsize_t dims[2] = {0, 0};
        if (H5Sget_simple_extent_ndims(space.id) != 2) Corrupt("verify: " + name + " is not 2-D");
        H5Sget_simple_extent_dims(space.id, dims, nullptr);
        if (dims[0] != t.at("samples").get<std::uint64_t>())
          Corrupt("verify: " + name + " sample count");
      }
      samples += t.at("samples").get<std::int64_t>();
    }
  } else {
    const bool csv = format == "csv";
    for (const auto& t : m.at("trials")) {
      const auto n = t.at("samples").get<std::uint64_t>();
      for (const char* key : {"true_file", "observed_file"}) {
        const auto path = t.at(key).get<std::string>();
        if (CountLines(dir / path) != n + (csv ? 1 : 0))
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
  if (CountLines(dir / "trials.csv") != static_cast<std::uint64_t>(r.trials) + 1) {
    Corrupt("verify: trials.csv row count");
  }
  return r;
}

}  // namespace arena::db
