// The MIT push dataset adaptor (push_dataset.hpp): its HDF5 files and shapes
// table in, lab-neutral Recordings out. Everything this dataset's layout
// means is here; the rest of the room knows none of it.
#include "arena/recordings/push_dataset.hpp"

#include <hdf5.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "arena/hdf5/handle.hpp"

namespace arena::recordings {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using H5Object = hdf5::Handle;
using hdf5::Reason;

// One N x 4 float dataset as a Stream (column 0 the time).
Stream ReadStream(hid_t file, const std::string& path, const char* name) {
  if (H5Lexists(file, name, H5P_DEFAULT) <= 0) {
    H5Eclear2(H5E_DEFAULT);
    throw ImportError(path, std::string("no dataset '") + name + "'");
  }
  H5Object ds(H5Dopen2(file, name, H5P_DEFAULT), H5Dclose);
  if (ds.id < 0) throw ImportError(path, std::string(name) + ": not a dataset: " + Reason());
  H5Object type(H5Dget_type(ds.id), H5Tclose);
  if (type.id < 0 || H5Tget_class(type.id) != H5T_FLOAT)
    throw ImportError(path, std::string(name) + ": must hold floats");
  H5Object space(H5Dget_space(ds.id), H5Sclose);
  hsize_t dims[2] = {0, 0};
  if (space.id < 0 || H5Sget_simple_extent_ndims(space.id) != 2)
    throw ImportError(path, std::string(name) + ": must be 2-D (N x 4)");
  H5Sget_simple_extent_dims(space.id, dims, nullptr);
  if (dims[1] != 4)
    throw ImportError(path, std::string(name) + ": has " + std::to_string(dims[1]) +
                                " columns, expected 4 (t and three values)");
  std::vector<double> flat(dims[0] * 4);
  if (dims[0] > 0 &&
      H5Dread(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, flat.data()) < 0)
    throw ImportError(path, std::string(name) + ": cannot read it: " + Reason());
  Stream s;
  s.name = name;
  for (hsize_t r = 0; r < dims[0]; ++r) {
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(flat[r * 4 + c]))
        throw ImportError(path, std::string(name) + ": row " + std::to_string(r) + ", column " +
                                    std::to_string(c) + " is " +
                                    (std::isnan(flat[r * 4 + c]) ? "NaN" : "infinite"));
    s.t.push_back(flat[r * 4]);
    s.values.push_back({flat[r * 4 + 1], flat[r * 4 + 2], flat[r * 4 + 3]});
  }
  return s;
}

double Number(const json& j, const char* key, const std::string& where, const std::string& path) {
  if (!j.contains(key) || !j[key].is_number())
    throw ImportError(path, where + key + ": must be a number");
  const double v = j[key].get<double>();
  if (!(v > 0) || !std::isfinite(v)) throw ImportError(path, where + key + ": must be > 0");
  return v;
}

}  // namespace

ShapesTable ReadShapesTable(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ImportError(path, "cannot read the shapes table");
  json j;
  try {
    j = json::parse(in);
  } catch (const json::exception& e) {
    throw ImportError(path, std::string("not JSON: ") + e.what());
  }
  if (!j.is_object()) throw ImportError(path, "must be a JSON object");
  ShapesTable t;
  t.thickness = Number(j, "thickness", "", path);
  t.pusher_radius = Number(j, "pusher_radius", "", path);
  if (!j.contains("shapes") || !j["shapes"].is_object() || j["shapes"].empty())
    throw ImportError(path, "shapes: must be an object naming at least one shape");
  for (const auto& [name, s] : j["shapes"].items()) {
    const std::string where = "shapes." + name + ".";
    if (!s.is_object()) throw ImportError(path, where + ": must be an object");
    Shape shape;
    shape.name = name;
    shape.thickness = t.thickness;
    shape.mass = Number(s, "mass", where, path);
    shape.moment_of_inertia = Number(s, "moment_of_inertia", where, path);
    if (!s.contains("outline") || !s["outline"].is_array() || s["outline"].size() < 3)
      throw ImportError(path, where + "outline: must list at least 3 [x, y] vertices");
    for (std::size_t k = 0; k < s["outline"].size(); ++k) {
      const auto& v = s["outline"][k];
      if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number() ||
          !std::isfinite(v[0].get<double>()) || !std::isfinite(v[1].get<double>()))
        throw ImportError(path, where + "outline[" + std::to_string(k) + "]: must be [x, y] (m)");
      shape.outline.push_back({v[0].get<double>(), v[1].get<double>()});
    }
    double area2 = 0;  // twice the signed area: > 0 counter-clockwise
    for (std::size_t k = 0; k < shape.outline.size(); ++k) {
      const auto& a = shape.outline[k];
      const auto& b = shape.outline[(k + 1) % shape.outline.size()];
      area2 += a[0] * b[1] - b[0] * a[1];
    }
    if (!(area2 > 0))
      throw ImportError(path, where + "outline: must be counter-clockwise with a positive area");
    t.shapes.emplace(name, std::move(shape));
  }
  return t;
}

PushParameters ParsePushFileName(const std::string& file_name) {
  std::string stem = fs::path(file_name).filename().string();
  if (stem.size() > 3 && stem.substr(stem.size() - 3) == ".h5") stem.resize(stem.size() - 3);
  // key=value pairs joined by '_'; a value may itself hold '_' only if no '=' follows it.
  std::map<std::string, std::string> kv;
  std::size_t at = 0;
  while (at < stem.size()) {
    const std::size_t eq = stem.find('=', at);
    if (eq == std::string::npos) break;
    std::size_t next_eq = stem.find('=', eq + 1);
    std::size_t end = next_eq == std::string::npos ? stem.size() : stem.rfind('_', next_eq);
    if (end == std::string::npos || end < eq) end = stem.size();
    std::string key = stem.substr(at, eq - at);
    const std::size_t us = key.rfind('_');
    if (us != std::string::npos) key = key.substr(us + 1);  // "motion_surface" -> "surface"
    kv[key] = stem.substr(eq + 1, end - eq - 1);
    at = end + 1;
  }
  PushParameters p;
  const auto text = [&](const char* key) {
    const auto it = kv.find(key);
    if (it == kv.end() || it->second.empty())
      throw ImportError(file_name, std::string("the file name has no push parameter '") + key +
                                       "=' (expected motion_surface=S_shape=S_a=A_v=V_i=I_s=S_t=T"
                                       ".h5)");
    return it->second;
  };
  const auto number = [&](const char* key) {
    const std::string v = text(key);
    double d = 0;
    const auto r = std::from_chars(v.data(), v.data() + v.size(), d);
    if (r.ec != std::errc() || r.ptr != v.data() + v.size() || !std::isfinite(d))
      throw ImportError(file_name, std::string("push parameter '") + key + "=" + v +
                                       "' in the file name is not a number");
    return d;
  };
  p.surface = text("surface");
  p.shape = text("shape");
  p.a = number("a");
  p.v = number("v");
  p.i = number("i");
  p.s = number("s");
  p.t = number("t");
  return p;
}

Recording ReadPushFile(const std::string& path, const ShapesTable& shapes) {
  const PushParameters p = ParsePushFileName(path);
  const auto shape = shapes.shapes.find(p.shape);
  if (shape == shapes.shapes.end()) {
    std::string known;
    for (const auto& [name, s] : shapes.shapes) known += (known.empty() ? "" : ", ") + name;
    throw ImportError(path, "unknown shape '" + p.shape + "' (the shapes table has " + known + ")");
  }
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors come back as exceptions, not stderr
  if (const htri_t is = H5Fis_hdf5(path.c_str()); is <= 0)
    throw ImportError(
        path, is < 0 ? "cannot read it as HDF5: " + Reason() : std::string("not an HDF5 file"));
  H5Object file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (file.id < 0) throw ImportError(path, "cannot open it: " + Reason());
  Recording r;
  r.source = path;
  r.name = fs::path(path).stem().string();
  r.shape = shape->second;
  r.pusher_radius = shapes.pusher_radius;
  r.pusher_pose = ReadStream(file.id, path, "tip_pose");
  r.object_pose = ReadStream(file.id, path, "object_pose");
  r.force = ReadStream(file.id, path, "ft_wrench");
  // The sensor reads the reaction on the pusher; the object feels the opposite.
  for (auto& v : r.force.values)
    for (double& x : v) x = -x;
  json params = {{"surface", p.surface},  {"shape", p.shape},
                 {"acceleration", p.a},   {"speed_mm_s", p.v},
                 {"contact_i", p.i},      {"contact_s", p.s},
                 {"push_angle_rad", p.t}, {"file", fs::path(path).filename().string()}};
  r.parameters_json = params.dump();
  r.stated_push_angle = p.t;  // t: from the inward normal to the push (checked on the poses)
  return r;
}

std::vector<Recording> ReadPushDataset(const std::string& dir, const ShapesTable& shapes) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw ImportError(dir, "no such directory");
  std::vector<std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir, ec))
    if (e.is_regular_file() && e.path().extension() == ".h5") files.push_back(e.path().string());
  if (ec) throw ImportError(dir, "cannot list it: " + ec.message());
  if (files.empty()) throw ImportError(dir, "holds no .h5 file");
  std::sort(files.begin(), files.end());
  std::vector<Recording> out;
  for (const auto& f : files) out.push_back(ReadPushFile(f, shapes));
  return out;
}

}  // namespace arena::recordings
