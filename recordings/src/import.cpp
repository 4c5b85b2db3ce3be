// Recordings -> scenes, ground-truth samples, and a dataset written by db's
// own export (import.hpp). The samples go through a private, temporary store
// so that the dataset's files and manifest are exactly what `arena export`
// writes (one writer, one verifier); the store is deleted afterwards.
#include "arena/recordings/import.hpp"

#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arena/db/export.hpp"
#include "arena/db/store.hpp"
#include "arena/mechanics/frames.hpp"

namespace arena::recordings {
namespace {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

constexpr double kGravity = 9.81;

double Round(double v, double unit) { return std::round(v / unit) * unit; }

// Where the pusher meets the object at sample k, in T: the unit normal into
// the object (from the pusher's centre towards the outline's closest point),
// and the gap of the disk (m).
struct Touch {
  double nx = 1, ny = 0;
  double gap = 0;
};
Touch TouchAt(const Recording& r, const Resampled& s, std::size_t k) {
  const double c = std::cos(s.object[k][2]), sn = std::sin(s.object[k][2]);
  const double dx = s.pusher[k][0] - s.object[k][0], dy = s.pusher[k][1] - s.object[k][1];
  const double lx = c * dx + sn * dy, ly = -sn * dx + c * dy;  // pusher centre in the object frame
  const auto q = NearestPoint(r.shape.outline, lx, ly);
  const double d = SignedDistance(r.shape.outline, lx, ly);
  double ux = q[0] - lx, uy = q[1] - ly;
  const double len = std::hypot(ux, uy);
  if (len > 1e-12) {
    ux /= len;
    uy /= len;
  } else {  // centre on the outline: towards the centroid
    const double l = std::hypot(lx, ly);
    ux = l > 0 ? -lx / l : 1;
    uy = l > 0 ? -ly / l : 0;
  }
  if (d < 0) {  // centre inside: the outline is behind it
    ux = -ux;
    uy = -uy;
  }
  Touch t;
  t.nx = c * ux - sn * uy;  // back to T
  t.ny = sn * ux + c * uy;
  t.gap = d - r.pusher_radius;
  return t;
}

// The prism's inertia about its centre of mass: the measured moment about z,
// the outline's area moments and the thickness (uniform density) about x and y.
std::array<double, 3> Inertia(const Shape& s, const std::string& where) {
  double a2 = 0, cx = 0, cy = 0, ixx = 0, iyy = 0;  // about the outline's origin
  const std::size_t n = s.outline.size();
  for (std::size_t i = 0; i < n; ++i) {
    const auto& p = s.outline[i];
    const auto& q = s.outline[(i + 1) % n];
    const double cr = p[0] * q[1] - q[0] * p[1];
    a2 += cr;
    cx += (p[0] + q[0]) * cr;
    cy += (p[1] + q[1]) * cr;
    ixx += cr * (p[0] * p[0] + p[0] * q[0] + q[0] * q[0]);  // integral of x^2, times 12
    iyy += cr * (p[1] * p[1] + p[1] * q[1] + q[1] * q[1]);
  }
  const double area = a2 / 2;
  cx /= 3 * a2;
  cy /= 3 * a2;
  const double x2 = ixx / 12 / area - cx * cx, y2 = iyy / 12 / area - cy * cy;  // per unit area
  const double h2 = s.thickness * s.thickness / 12;
  const std::array<double, 3> out{s.mass * (y2 + h2), s.mass * (x2 + h2), s.moment_of_inertia};
  if (out[2] > out[0] + out[1])
    throw ImportError(where, "shape '" + s.name + "': moment_of_inertia " +
                                 std::to_string(s.moment_of_inertia) +
                                 " kg m^2 is more than a body of this outline and thickness can "
                                 "have (" +
                                 std::to_string(out[0] + out[1]) + ")");
  return out;
}

std::array<double, 4> Quat(double theta) {  // (w, x, y, z) about z
  return {std::cos(theta / 2), 0, 0, std::sin(theta / 2)};
}

// d/dt of channel c by central differences (one-sided at the ends).
double Rate(const std::vector<std::array<double, 3>>& v, const std::vector<double>& t,
            std::size_t k, int c) {
  const std::size_t a = k > 0 ? k - 1 : k, b = k + 1 < v.size() ? k + 1 : k;
  return b > a ? (v[b][c] - v[a][c]) / (t[b] - t[a]) : 0.0;
}

struct Prepared {
  std::string scene_json;
  db::SceneFacts facts;
  std::vector<db::Sample> samples;
  ImportedTrial trial;
  std::string params_json;
};

std::uint64_t SeedOf(const std::string& name) {  // FNV-1a: stable across imports
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char ch : name) h = (h ^ ch) * 1099511628211ull;
  return h & 0x7fffffffffffffffull;
}

Prepared Prepare(const Recording& r, const ImportOptions& o) {
  Prepared p;
  const Resampled s = Resample(r, o.rate_hz);
  p.trial.name = r.name;
  p.trial.source = r.source;
  p.trial.shape = r.shape.name;
  p.trial.checks = CheckTrial(r, s, o.checks);
  p.trial.seed = SeedOf(r.name);
  p.trial.samples = static_cast<std::int64_t>(s.t.size());
  p.trial.duration = s.t.back();
  p.scene_json = SceneJson(r, s, o);
  p.facts = SceneFactsOf(r, s, o);

  const double z = r.shape.thickness / 2;
  const Touch start = TouchAt(r, s, 0);
  const bool force = p.trial.checks.force_usable && !s.force.empty();
  for (std::size_t k = 0; k < s.t.size(); ++k) {
    db::Sample d;
    d.t = s.t[k];
    const auto q = Quat(s.object[k][2]);
    d.object_pose = {s.object[k][0], s.object[k][1], z, q[0], q[1], q[2], q[3]};
    const double vx = Rate(s.object, s.t, k, 0), vy = Rate(s.object, s.t, k, 1),
                 w = Rate(s.object, s.t, k, 2);
    d.object_twist = {vx, vy, 0, 0, 0, w};
    // The pusher's reference point, as in the scene: its centre moved by r along
    // the start normal (the sphere's point that faces the object at the start).
    const double px = s.pusher[k][0] + r.pusher_radius * start.nx;
    const double py = s.pusher[k][1] + r.pusher_radius * start.ny;
    d.pusher_pose = {px, py, z, 1, 0, 0, 0};
    const double pvx = Rate(s.pusher, s.t, k, 0), pvy = Rate(s.pusher, s.t, k, 1);
    d.pusher_twist = {pvx, pvy, 0, 0, 0, 0};
    const Touch at = TouchAt(r, s, k);
    if (force) {
      // The measured force on the object; its torque about the contact
      // point (the sensor's is about the pusher's axis, r away).
      db::ContactWrench c;
      const double fx = s.force[k][0], fy = s.force[k][1];
      const double rx = r.pusher_radius * at.nx, ry = r.pusher_radius * at.ny;
      c.force = {fx, fy, 0};
      c.torque = {0, 0, s.force[k][2] - (rx * fy - ry * fx)};
      // The mode from the kinematics: apart, or sliding when the pusher's
      // centre moves along the outline relative to the object's material point there.
      if (at.gap > 0.0005) {
        c.mode = db::ContactMode::kSeparate;
      } else {
        const double cx = s.pusher[k][0] + rx - s.object[k][0];
        const double cy = s.pusher[k][1] + ry - s.object[k][1];
        const double ox = vx - w * cy, oy = vy + w * cx;  // object's point velocity
        const double relx = pvx - ox, rely = pvy - oy;
        const double tangential = std::abs(-at.ny * relx + at.nx * rely);
        c.mode = tangential > 0.002 ? db::ContactMode::kSlide : db::ContactMode::kStick;
      }
      d.contacts.push_back(c);
    }
    d.observed_valid = true;
    d.observed_object_pose = d.object_pose;
    if (!s.force.empty())  // what the sensor read, converted to the force on the object
      d.observed_pusher_wrench = {s.force[k][0], s.force[k][1], 0, 0, 0, s.force[k][2]};
    p.samples.push_back(std::move(d));
  }
  ojson params = ojson::parse(r.parameters_json);
  if (!params.is_object()) throw ImportError(r.source, "the push parameters are not an object");
  ojson out = {{"trial", r.name},
               {"pose_checked", p.trial.checks.pose_usable ? "ok" : "failed"},
               {"force_checked", p.trial.checks.force_usable ? "ok" : "failed"}};
  for (auto it = params.begin(); it != params.end(); ++it) out[it.key()] = it.value();
  p.params_json = out.dump();
  return p;
}

std::string Num(double v, const char* fmt = "%.3f") {
  if (std::isnan(v)) return "-";
  char b[32];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

std::string ReportText(const std::vector<ImportedTrial>& trials, const std::string& dir) {
  std::string t;
  std::size_t pose_failed = 0, force_failed = 0, clean = 0;
  std::map<std::string, std::size_t> by_check;
  for (const auto& tr : trials) {
    pose_failed += !tr.checks.pose_usable;
    force_failed += !tr.checks.force_usable;
    clean += tr.checks.findings.empty();
    std::set<std::string> seen;
    for (const auto& f : tr.checks.findings)
      if (seen.insert(f.check).second) ++by_check[f.check];
  }
  t += "imported " + std::to_string(trials.size()) + " trials -> " + dir + " (truth: measured)\n";
  t += "  poses scored: " + std::to_string(trials.size() - pose_failed) + ", refused " +
       std::to_string(pose_failed) +
       "; forces scored: " + std::to_string(trials.size() - force_failed) + ", not scored " +
       std::to_string(force_failed) + "; no finding: " + std::to_string(clean) + "\n";
  for (const auto& [check, n] : by_check)
    t += "  " + check + ": " + std::to_string(n) + " trial(s)\n";
  t += "trial                                                         samples  start_gap_mm "
       "onset_s onset_gap_mm  offset_N  pose  force\n";
  for (const auto& tr : trials) {
    char line[512];
    std::snprintf(line, sizeof line, "%-60s %8lld %13s %7s %12s %9s  %-5s %s\n", tr.name.c_str(),
                  static_cast<long long>(tr.samples),
                  Num(tr.checks.start_gap * 1e3, "%.2f").c_str(), Num(tr.checks.onset_t).c_str(),
                  Num(tr.checks.onset_gap * 1e3, "%.2f").c_str(),
                  Num(tr.checks.force_offset, "%.2f").c_str(),
                  tr.checks.pose_usable ? "ok" : "FAIL", tr.checks.force_usable ? "ok" : "FAIL");
    t += line;
    for (const auto& f : tr.checks.findings)
      t += std::string("    ") + (f.fails ? "FAIL " : "note ") + f.check + ": " + f.detail + "\n";
  }
  return t;
}

ojson ReportJson(const std::vector<ImportedTrial>& trials) {
  ojson a = ojson::array();
  const auto num = [](double v) { return std::isnan(v) ? ojson(nullptr) : ojson(v); };
  for (const auto& tr : trials) {
    ojson findings = ojson::array();
    for (const auto& f : tr.checks.findings)
      findings.push_back({{"check", f.check}, {"detail", f.detail}, {"fails", f.fails}});
    a.push_back({{"trial", tr.name},
                 {"source", fs::path(tr.source).filename().string()},
                 {"shape", tr.shape},
                 {"seed", std::to_string(tr.seed)},
                 {"samples", tr.samples},
                 {"duration_s", tr.duration},
                 {"pose_usable", tr.checks.pose_usable},
                 {"force_usable", tr.checks.force_usable},
                 {"start_gap_m", num(tr.checks.start_gap)},
                 {"onset_t_s", num(tr.checks.onset_t)},
                 {"onset_gap_m", num(tr.checks.onset_gap)},
                 {"force_offset_n", num(tr.checks.force_offset)},
                 {"force_drift_n", num(tr.checks.force_drift)},
                 {"object_travel_m", tr.checks.object_travel},
                 {"object_rotation_rad", tr.checks.object_rotation},
                 {"push_angle_rad", tr.checks.push_angle},
                 {"findings", findings}});
  }
  return a;
}

// A private directory beside the dataset for the temporary store; removed
// with everything in it when the import ends, however it ends.
class ScratchDir {
 public:
  explicit ScratchDir(const fs::path& target) {
    const fs::path parent = target.parent_path().empty() ? fs::path(".") : target.parent_path();
    std::error_code ec;
    fs::create_directories(parent, ec);
    std::string tmpl = (parent / ("." + target.filename().string() + ".import-XXXXXX")).string();
    if (::mkdtemp(tmpl.data()) == nullptr)
      throw std::runtime_error("import: cannot create a directory in '" + parent.string() +
                               "' (is it writable?)");
    path_ = tmpl;
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

std::string CampaignName(const ImportOptions& o) {
  std::string name = o.campaign_name;
  if (name.empty()) {
    fs::path p = fs::path(o.out_dir).lexically_normal();
    if (!p.has_filename()) p = p.parent_path();
    for (char ch : p.filename().string())
      name += (std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-' || ch == '.')
                  ? ch
                  : '_';
    if (name.size() > 64) name.resize(64);
    if (name.empty()) name = "recorded";
  }
  for (char ch : name)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-' || ch == '.'))
      throw ImportError("--name", "campaign name '" + name + "' may hold only [A-Za-z0-9_.-]");
  if (name.size() > 64) throw ImportError("--name", "campaign name longer than 64 characters");
  return name;
}

// The workspace of the imported campaign: every recorded start and every
// place a trial's pusher path would carry the object (start + the pusher's
// displacement, the travel check), 5 cm around. Recordings are in the lab's
// table frame, often outside the default +-0.25 m, and `arena submit`/`run`
// check every scene against the campaign's profile. A replay cell computes
// the same extent from the dataset for its own workspace (a campaign's limits
// never widen a cell's).
ojson Workspace(const std::vector<Prepared>& prepared) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(HUGE_VAL), hi = -lo;
  for (const auto& p : prepared) {
    const auto scene = nlohmann::json::parse(p.scene_json);
    const auto& at = scene["object"]["pose"]["position"];
    const Eigen::Vector3d start(at[0].get<double>(), at[1].get<double>(), at[2].get<double>());
    lo = lo.cwiseMin(start);
    hi = hi.cwiseMax(start);
    const auto& path = scene["pusher"]["motion"]["path"]["position"];
    for (const auto& x : path) {
      const Eigen::Vector3d d(x[0].get<double>() - path[0][0].get<double>(),
                              x[1].get<double>() - path[0][1].get<double>(),
                              x[2].get<double>() - path[0][2].get<double>());
      lo = lo.cwiseMin(start + d);
      hi = hi.cwiseMax(start + d);
    }
  }
  lo.array() -= 0.05;
  hi.array() += 0.05;
  return {{"min", {lo.x(), lo.y(), lo.z()}}, {"max", {hi.x(), hi.y(), hi.z()}}};
}

// The campaign that commands exactly these trials: the dataset's own scenes.
ojson ImportedCampaign(const std::string& name, const ImportOptions& o,
                       const std::vector<Prepared>& prepared) {
  return {
      {"name", name},
      {"description", "Every recorded trial of " + (o.source.empty() ? name : o.source) +
                          " (imported by arena import " + o.adaptor +
                          "); run it with --backend replay:DATASET. The truth is measured."},
      {"seed", 0},
      {"scenes", "scenes.jsonl"},
      {"prediction", {{"facets", 8}, {"points", 3}, {"dt", 0.004}, {"reduce", "auto"}}},
      {"defects", {{"workspace", Workspace(prepared)}}},
  };
}

// What the dataset's manifest says beyond db's export: the truth is measured,
// and which trials' streams passed their import checks.
ojson ManifestExtra(const ImportOptions& o, const ojson& per_trial) {
  return {
      {"truth", "measured"},
      {"truth_note",
       "measured: the lab's recorded streams are the observation and the truth (there is no "
       "separate true stream). The true stream is the observed one without what failed its "
       "import check: a trial whose poses failed is not served (replay refuses it); a trial "
       "whose force stream failed has no contact forces in its truth (poses are scored, "
       "forces never). import_report.txt says which and why."},
      {"frames",
       {{"G",
         "the table frame: x, y on the table, z up (gravity along -z); every pose, twist and "
         "wrench is expressed in it; quaternions are (w, x, y, z)"}}},
      {"import",
       {{"adaptor", o.adaptor},
        {"source", o.source},
        {"rate_hz", o.rate_hz},
        {"report", "import_report.json"},
        {"campaign", "campaign.json"},
        {"trials", per_trial}}},
  };
}

// The prepared trials as a campaign of a store, each trial executed with its
// recorded samples; returns the campaign's id.
std::int64_t StorePrepared(db::Store& store, const std::string& name, const ojson& campaign,
                           const std::vector<Prepared>& prepared, const ImportOptions& o) {
  db::NewCampaign nc;
  nc.name = name;
  nc.spec_json = campaign.dump();
  std::vector<db::PlannedTrial> planned;
  for (std::size_t i = 0; i < prepared.size(); ++i) {
    db::PlannedTrial t;
    t.condition = static_cast<int>(i);
    t.seed = prepared[i].trial.seed;
    t.scene_json = prepared[i].scene_json;
    t.facts = prepared[i].facts;
    t.params_json = prepared[i].params_json;
    planned.push_back(std::move(t));
  }
  const std::int64_t campaign_id = store.CreateCampaign(nc, planned);
  const std::string cell = "recorded";
  store.UpsertCell(cell, {"point"});
  for (std::size_t i = 0; i < prepared.size(); ++i) {
    const auto claimed = store.ClaimNextTrial(cell);
    if (!claimed) throw std::runtime_error("import: the temporary store handed out no trial");
    const auto index = static_cast<std::size_t>(store.GetTrial(claimed->trial_id).index);
    const auto& p = prepared[index];
    auto ingest =
        store.BeginIngest(claimed->trial_id, claimed->attempt, planned[index].facts.contacts);
    ingest->Add(p.samples);
    ingest->Finish();
    store.RecordExecution(claimed->trial_id, claimed->attempt, "import:" + o.adaptor, "measured",
                          "{}");
  }
  return campaign_id;
}

// The dataset, written by db's own export from a private store in `scratch`.
void WriteImportDataset(const fs::path& scratch, const fs::path& out, const std::string& name,
                        const ojson& campaign, const std::vector<Prepared>& prepared,
                        const ImportReport& report, const ImportOptions& o) {
  auto store = db::Store::Open((scratch / "import.db").string());
  const std::int64_t campaign_id = StorePrepared(*store, name, campaign, prepared, o);
  ojson per_trial = ojson::array();
  for (const auto& t : store->ListTrials(campaign_id)) {
    const auto& p = prepared[static_cast<std::size_t>(t.index)];
    per_trial.push_back({{"trial_id", t.id},
                         {"trial", p.trial.name},
                         {"pose_usable", p.trial.checks.pose_usable},
                         {"force_usable", p.trial.checks.force_usable}});
  }
  db::ExportOptions eo;
  eo.campaign_id = campaign_id;
  // The export's column names from the facts computed with each scene.
  std::map<std::string, const db::SceneFacts*> facts_of;
  for (const auto& p : prepared) facts_of.emplace(p.scene_json, &p.facts);
  eo.scene_facts = [&facts_of](const std::string& scene_json) { return *facts_of.at(scene_json); };
  eo.format = db::ExportFormat::kHdf5;
  eo.out_dir = out.string();
  eo.arena_version = o.arena_version;
  eo.arena_commit = o.arena_commit;
  eo.extra_files = {{"campaign.json", campaign.dump(2) + "\n"},
                    {"import_report.txt", report.text},
                    {"import_report.json", ReportJson(report.trials).dump(2) + "\n"}};
  eo.manifest_extra_json = ManifestExtra(o, per_trial).dump();
  db::ExportCampaign(*store, eo);
}

}  // namespace

std::string SceneJson(const Recording& r, const Resampled& s, const ImportOptions& o) {
  const double z = r.shape.thickness / 2;
  const auto inertia = Inertia(r.shape, r.source);
  ojson polygon = ojson::array();
  for (const auto& v : r.shape.outline) polygon.push_back({v[0], v[1]});
  const Touch start = TouchAt(r, s, 0);
  const double nx = start.nx, ny = start.ny;
  ojson t = ojson::array(), position = ojson::array();
  for (std::size_t k = 0; k < s.t.size(); ++k) {
    t.push_back(Round(s.t[k], 1e-6));
    position.push_back({Round(s.pusher[k][0] + r.pusher_radius * nx, 1e-7),
                        Round(s.pusher[k][1] + r.pusher_radius * ny, 1e-7), z});
  }
  ojson scene = {
      {"object",
       {{"shape", "prism"},
        {"polygon", polygon},
        {"height", r.shape.thickness},
        {"mass", r.shape.mass},
        {"inertia", {{inertia[0], 0.0, 0.0}, {0.0, inertia[1], 0.0}, {0.0, 0.0, inertia[2]}}},
        {"pose",
         {{"position", {Round(s.object[0][0], 1e-7), Round(s.object[0][1], 1e-7), z}},
          {"rpy", {0.0, 0.0, Round(s.object[0][2], 1e-7)}}}}}},
      {"gravity", {0.0, 0.0, -kGravity}},
      {"duration", Round(s.t.back(), 1e-6)},
      {"grip_force", 0.0},
      {"fingers", ojson::array()},
      {"support", {{"mu", o.support_mu}, {"pressure", "uniform"}}},
      {"pusher",
       {{"type", "point"},
        {"radius", r.pusher_radius},
        {"position", position[0]},
        {"normal", {Round(nx, 1e-9), Round(ny, 1e-9), 0.0}},
        {"mu", o.pusher_mu},
        {"motion", {{"path", {{"t", t}, {"position", position}}}}}}},
      {"model", {{"facets", 8}, {"points", 3}, {"dt", 0.004}, {"reduce", "auto"}}},
  };
  return scene.dump();
}

db::SceneFacts SceneFactsOf(const Recording& r, const Resampled& s, const ImportOptions& o) {
  db::SceneFacts f;
  f.object_shape = "prism";
  f.object_mass = r.shape.mass;
  f.grip_force = 0.0;
  f.duration = Round(s.t.back(), 1e-6);
  f.pusher_type = "point";
  f.pusher_mu = o.pusher_mu;  // a path motion: no speeds
  f.contact_mask = db::kPointBit;
  const double z = r.shape.thickness / 2;
  const Eigen::Vector3d rpy(0.0, 0.0, Round(s.object[0][2], 1e-7));
  const Eigen::Quaterniond q(mechanics::RotationFromRpy(rpy));
  f.nominal = {
      Round(s.object[0][0], 1e-7), Round(s.object[0][1], 1e-7), z, q.w(), q.x(), q.y(), q.z()};
  const Touch start = TouchAt(r, s, 0);
  db::ContactSite pusher;
  pusher.name = "pusher";
  pusher.pusher = true;
  pusher.position = {Round(s.pusher[0][0] + r.pusher_radius * start.nx, 1e-7),
                     Round(s.pusher[0][1] + r.pusher_radius * start.ny, 1e-7), z};
  const std::array<double, 3> n{Round(start.nx, 1e-9), Round(start.ny, 1e-9), 0.0};
  const double norm = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  pusher.known = norm > 0;
  for (int k = 0; k < 3; ++k) pusher.normal[k] = pusher.known ? n[k] / norm : 0.0;
  f.contacts = {pusher};
  return f;
}

ImportReport ImportRecordings(const std::vector<Recording>& recordings, const ImportOptions& o) {
  if (o.out_dir.empty()) throw ImportError("--out", "is empty");
  if (recordings.empty()) throw ImportError(o.source, "no recordings to import");
  fs::path out = fs::path(o.out_dir).lexically_normal();
  if (!out.has_filename()) out = out.parent_path();
  std::error_code ec;
  if (fs::exists(out, ec) && (!fs::is_directory(out, ec) || !fs::is_empty(out, ec)))
    throw ImportError(o.out_dir, "exists and is not an empty directory; choose a new one");
  const std::string name = CampaignName(o);
  std::set<std::string> names;
  for (const auto& r : recordings)
    if (!names.insert(r.name).second)
      throw ImportError(r.source, "a second trial named '" + r.name + "'");

  // Everything is read, checked and built before anything is written.
  std::vector<Prepared> prepared;
  for (const auto& r : recordings) {
    prepared.push_back(Prepare(r, o));
    if (o.progress)
      o.progress(static_cast<std::int64_t>(prepared.size()),
                 static_cast<std::int64_t>(recordings.size()));
  }

  ImportReport report;
  report.dir = o.out_dir;
  for (const auto& p : prepared) report.trials.push_back(p.trial);
  report.text = ReportText(report.trials, o.out_dir);
  const ojson campaign = ImportedCampaign(name, o, prepared);

  ScratchDir scratch(out);
  try {
    WriteImportDataset(scratch.path(), out, name, campaign, prepared, report, o);
  } catch (const db::StoreError& e) {
    throw std::runtime_error(std::string("import: writing the dataset failed: ") + e.what());
  }
  return report;
}

}  // namespace arena::recordings
