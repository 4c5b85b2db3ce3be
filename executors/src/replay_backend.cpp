// replay:DATASET: recorded trials (an `arena export` directory in any format
// the export writes: csv, jsonl, hdf5) served as a cell. A commanded scene is matched to the
// recorded trials by its physical parameters (everything but `model`, numbers to 1e-9 relative); a
// recorded trial with the command's seed is preferred (the same campaign re-run), otherwise
// matching trials are served in turn. A scene the dataset does not hold is REFUSED, with the
// reason.
#include <sys/stat.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arena/executors/backend.hpp"
#include "arena/mechanics/pusher_motion.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "recorded_stream.hpp"

namespace arena::executors {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

bool Same(const json& a, const json& b) {
  if (a.is_number() && b.is_number()) {
    const double x = a.get<double>(), y = b.get<double>();
    return std::abs(x - y) <= 1e-9 * (1 + std::abs(x) + std::abs(y));
  }
  if (a.is_object() && b.is_object()) {
    if (a.size() != b.size()) return false;
    for (auto it = a.begin(); it != a.end(); ++it) {
      auto jt = b.find(it.key());
      if (jt == b.end() || !Same(*it, *jt)) return false;
    }
    return true;
  }
  if (a.is_array() && b.is_array()) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i)
      if (!Same(a[i], b[i])) return false;
    return true;
  }
  return a == b;
}

json Physical(json scene) {
  if (scene.is_object()) scene.erase("model");
  return scene;
}

// A recorded scene as the service writes a commanded one (SceneToJson of the
// parsed scene), so that a scene written by another program (arena import)
// matches whatever defaults and spelling it used. A scene this arena cannot
// parse stays as it is (and matches only the same text).
json Canonical(const json& scene) {
  try {
    return json::parse(mechanics::SceneToJson(mechanics::ParseScene(scene.dump())));
  } catch (const std::exception&) {
    return scene;
  }
}

// The recorded rows as the true samples of `scene`: contacts in scene order
// (fingers, then the pusher), named as the export names them (a finger's
// name, "pusher"; "contactK" by position when the recording had another set).
// One row at a time: a stream is never held whole.
// A measured recording whose forces were not measured or failed their
// import check (`forces_measured` false, from the manifest) is served
// without contacts, whatever columns the stream has: its truth says so
// (Backend::PreparedTruth) and no force of it is ever scored.
class RowToSample {
 public:
  RowToSample(const std::vector<std::string>& columns, const mechanics::Scene& scene,
              bool forces_measured)
      : columns_(columns) {
    for (size_t i = 0; i < scene.fingers.size(); ++i) {
      names_.push_back(scene.fingers[i].name.empty() ? "finger" + std::to_string(i)
                                                     : scene.fingers[i].name);
      normals_.push_back(scene.fingers[i].normal.normalized());
    }
    if (scene.pusher) {
      names_.push_back("pusher");
      normals_.push_back(scene.pusher->normal.normalized());
    }
    pusher_ = scene.pusher.has_value();
    pose_ = Cols("", {"x", "y", "z", "qw", "qx", "qy", "qz"});
    twist_ = Cols("", {"vx", "vy", "vz", "wx", "wy", "wz"});
    pusher_pos_ = Cols("pusher_", {"x", "y", "z"});
    if (!forces_measured) names_.clear();
    for (size_t c = 0; c < names_.size(); ++c) {
      const std::string prefix =
          (Find(names_[c] + "_fx") >= 0 ? names_[c] : "contact" + std::to_string(c)) + "_";
      contact_.push_back(Cols(prefix, {"fx", "fy", "fz", "tx", "ty", "tz", "mode"}));
    }
    t_ = Col("t");
  }

  // @throws std::invalid_argument for a value no sample can hold (a contact
  //   mode other than 0 stick, 1 slide, 2 separate).
  mechanics::TrajectorySample Convert(const std::vector<double>& row, std::size_t number) const {
    mechanics::TrajectorySample s;
    const auto v3 = [&](const std::vector<size_t>& k, size_t at) {
      return Eigen::Vector3d(row[k[at]], row[k[at + 1]], row[k[at + 2]]);
    };
    s.t = row[t_];
    s.position = v3(pose_, 0);
    s.orientation = Eigen::Quaterniond(row[pose_[3]], row[pose_[4]], row[pose_[5]], row[pose_[6]]);
    s.velocity = v3(twist_, 0);
    s.angular_velocity = v3(twist_, 3);
    s.pusher_position = v3(pusher_pos_, 0);
    for (size_t c = 0; c < names_.size(); ++c) {
      const Eigen::Vector3d f = v3(contact_[c], 0);
      mechanics::ContactState st;
      st.normal_force = f.dot(normals_[c]);
      st.tangential_force = f - st.normal_force * normals_[c];
      st.torque = v3(contact_[c], 3);
      const double mode = row[contact_[c][6]];
      if (mode != 0 && mode != 1 && mode != 2)
        throw std::invalid_argument("row " + std::to_string(number) + ": " +
                                    columns_[contact_[c][6]] + " = " + std::to_string(mode) +
                                    " is no contact mode (0 stick, 1 slide, 2 separate)");
      st.mode = mode == 0   ? mechanics::ContactMode::kStick
                : mode == 1 ? mechanics::ContactMode::kSlide
                            : mechanics::ContactMode::kSeparate;
      s.contacts.push_back(st);
      if (pusher_ && c + 1 == names_.size()) s.pusher_force = f;
    }
    return s;
  }

 private:
  int Find(const std::string& name) const {
    for (size_t i = 0; i < columns_.size(); ++i)
      if (columns_[i] == name) return static_cast<int>(i);
    return -1;
  }
  size_t Col(const std::string& name) const {
    const int k = Find(name);
    if (k < 0) throw std::invalid_argument("column '" + name + "' missing");
    return static_cast<size_t>(k);
  }
  std::vector<size_t> Cols(const std::string& prefix, std::initializer_list<const char*> axes) {
    std::vector<size_t> out;
    for (const char* a : axes) out.push_back(Col(prefix + a));
    return out;
  }

  std::vector<std::string> columns_;
  std::vector<std::string> names_;
  std::vector<Eigen::Vector3d> normals_;
  bool pusher_ = false;
  std::vector<size_t> pose_, twist_, pusher_pos_;
  std::vector<std::vector<size_t>> contact_;
  size_t t_ = 0;
};

// A file's size and modification time when the cell verified the dataset:
// an edit after that (a stream moved 5 cm, cut short) is refused at serve time.
struct FileStamp {
  std::uintmax_t bytes = 0;
  std::int64_t mtime_ns = 0;
  bool operator==(const FileStamp& o) const { return bytes == o.bytes && mtime_ns == o.mtime_ns; }
};

FileStamp Stamp(const fs::path& p) {
  struct stat st {};
  if (::stat(p.c_str(), &st) != 0) return {};
  return {static_cast<std::uintmax_t>(st.st_size),
          static_cast<std::int64_t>(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec};
}

// A path the manifest names, relative and inside the dataset.
fs::path Inside(const fs::path& root, const std::string& rel, const std::string& what) {
  const fs::path p(rel);
  if (rel.empty() || p.is_absolute())
    throw std::invalid_argument(root.string() + "/manifest.json: " + what + " '" + rel +
                                "' is not a path inside the dataset");
  for (const auto& part : p.lexically_normal())
    if (part == "..")
      throw std::invalid_argument(root.string() + "/manifest.json: " + what + " '" + rel +
                                  "' leads outside the dataset");
  return root / p.lexically_normal();
}

struct Recorded {
  std::int64_t trial_id = 0;
  std::string seed;
  json scene;
  std::string refused;        // an imported trial whose poses failed their check: why
  TrialTruth truth;           // an imported trial whose forces failed their check: says so
  std::uint64_t samples = 0;  // the manifest's count
  fs::path stream;            // csv/jsonl: its true stream file
  FileStamp stamp;            // of that file (hdf5: of dataset.h5) when verified
};

class ReplayBackend final : public Backend {
 public:
  explicit ReplayBackend(const std::string& dir) : dir_(dir) {
    const fs::path root(dir);
    const json manifest = ReadManifest(root);
    RefuseSymlinks(root);
    ReadScenes(root, ListedTrials(manifest));
    if (trials_.empty()) throw std::invalid_argument(dir + ": holds no trials");
    // An imported recording (arena import): measured truth, and the trials
    // whose poses failed the import's checks are never served (never scored).
    measured_ = manifest.value("truth", "") == "measured";
    ApplyImportChecks(manifest);
    CheckStreams(root);
    caps_.workspace = RecordedWorkspace();
    caps_.name = "replay:" + dir;
    caps_.truth = measured_ ? TruthSource::kMeasured : TruthSource::kRecorded;
    caps_.engine = std::string(measured_ ? "measured" : "recorded") + " dataset " +
                   fs::absolute(root).string() + " (" + std::to_string(trials_.size()) +
                   " trials, " + format_ + ")";
    caps_.emulates_defects = false;
    caps_.settings_json =
        json({{"dataset", fs::absolute(root).string()}, {"trials", trials_.size()}}).dump();
  }

 private:
  // manifest.json, with a format arena writes and the scenes beside it.
  json ReadManifest(const fs::path& root) {
    json manifest;
    try {
      manifest = json::parse(ReadText((root / "manifest.json").string()));
    } catch (const json::exception& e) {
      throw std::invalid_argument(dir_ + "/manifest.json: not JSON: " + e.what());
    }
    format_ = manifest.value("export_format", "");
    if (format_ != "csv" && format_ != "jsonl" && format_ != "hdf5")
      throw std::invalid_argument(dir_ + "/manifest.json: export_format '" + format_ +
                                  "' is none of the formats arena writes (hdf5, csv, jsonl)");
    if (!fs::exists(root / "scenes.jsonl"))
      throw std::invalid_argument(dir_ + ": no scenes.jsonl (exported by an older arena?)");
    return manifest;
  }

  // Nothing in the dataset may point elsewhere: a symlink would serve a
  // file the manifest's checks never saw.
  static void RefuseSymlinks(const fs::path& root) {
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(root, ec);
         !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
      if (it->is_symlink())
        throw std::invalid_argument(it->path().string() +
                                    ": a symbolic link in the dataset (refused: replay serves "
                                    "only the dataset's own files)");
    }
  }

  // The manifest's trials: ids unique, each with its sample count (and, for
  // csv/jsonl, its true stream file inside the dataset).
  std::map<std::int64_t, const json*> ListedTrials(const json& manifest) const {
    std::map<std::int64_t, const json*> listed;
    if (!manifest.contains("trials") || !manifest["trials"].is_array())
      throw std::invalid_argument(dir_ + "/manifest.json: no trials list");
    for (const auto& t : manifest["trials"]) {
      if (!t.is_object() || !t.contains("trial_id") || !t["trial_id"].is_number_integer() ||
          !t.contains("samples") || !t["samples"].is_number_unsigned())
        throw std::invalid_argument(dir_ + "/manifest.json: a trial without trial_id and samples");
      if (!listed.emplace(t["trial_id"].get<std::int64_t>(), &t).second)
        throw std::invalid_argument(dir_ + "/manifest.json: trial " + t["trial_id"].dump() +
                                    " is listed twice");
    }
    return listed;
  }

  // scenes.jsonl: each recorded trial once, each listed in the manifest.
  void ReadScenes(const fs::path& root, const std::map<std::int64_t, const json*>& listed) {
    std::istringstream lines(ReadText((root / "scenes.jsonl").string()));
    std::string line;
    std::set<std::int64_t> seen;
    for (int number = 1; std::getline(lines, line); ++number) {
      if (line.empty()) continue;
      const json j = json::parse(line, nullptr, false);
      if (j.is_discarded() || !j.is_object() || !j.contains("trial_id") ||
          !j["trial_id"].is_number_integer())
        throw std::invalid_argument(dir_ + "/scenes.jsonl: line " + std::to_string(number) +
                                    ": not an object with a trial_id");
      const auto id = j["trial_id"].get<std::int64_t>();
      if (!seen.insert(id).second)
        throw std::invalid_argument(dir_ + "/scenes.jsonl: line " + std::to_string(number) +
                                    ": trial " + std::to_string(id) +
                                    " again (each recorded trial once)");
      if (!j.contains("scene") || !j["scene"].is_object()) continue;  // a trial without a scene
      const auto m = listed.find(id);
      if (m == listed.end())
        throw std::invalid_argument(dir_ + "/scenes.jsonl: line " + std::to_string(number) +
                                    ": trial " + std::to_string(id) + " is not in the manifest");
      Recorded r;
      r.trial_id = id;
      r.seed = j.contains("seed")
                   ? (j["seed"].is_string() ? j["seed"].get<std::string>() : j["seed"].dump())
                   : "";
      r.scene = Physical(Canonical(j["scene"]));
      r.samples = (*m->second)["samples"].get<std::uint64_t>();
      if (format_ != "hdf5") {
        const json& file = (*m->second).contains("true_file") ? (*m->second)["true_file"] : json();
        r.stream =
            file.is_string() ? Inside(root, file.get<std::string>(), "true_file") : StreamFile(id);
      }
      trials_.push_back(std::move(r));
    }
  }

  // The import's checks (manifest "import"): a trial whose poses failed is
  // refused, one whose forces failed has no measured forces.
  void ApplyImportChecks(const json& manifest) {
    if (!manifest.contains("import") || !manifest["import"].is_object() ||
        !manifest["import"].contains("trials") || !manifest["import"]["trials"].is_array())
      return;
    for (const auto& t : manifest["import"]["trials"]) {
      if (!t.is_object()) continue;
      for (auto& r : trials_) {
        if (r.trial_id != t.value("trial_id", std::int64_t{-1})) continue;
        const std::string name = t.value("trial", std::string("?"));
        if (!t.value("pose_usable", true))
          r.refused = "replay: recorded trial " + std::to_string(r.trial_id) + " (" + name +
                      ") failed its import check of the poses (" + dir_ +
                      "/import_report.txt): not served, so never scored";
        if (!t.value("force_usable", true)) {
          r.truth.forces_measured = false;
          r.truth.forces_note = "recorded trial " + std::to_string(r.trial_id) + " (" + name +
                                "): its force stream failed its import check (" + dir_ +
                                "/import_report.txt)";
        }
      }
    }
  }

  // Every served trial's stream is there and well formed before the cell
  // comes up: a broken dataset stops `arena cell` with the file and the
  // reason, not a trial in the middle of a campaign.
  void CheckStreams(const fs::path& root) {
    if (format_ == "hdf5") {
      h5_ = std::make_unique<Hdf5Recording>((root / "dataset.h5").string());
      for (auto& r : trials_) {
        h5_->Check(r.trial_id);
        r.stamp = Stamp(root / "dataset.h5");
      }
      return;
    }
    for (auto& r : trials_) {
      if (!fs::is_regular_file(r.stream))
        throw std::invalid_argument(r.stream.string() + ": missing (trial " +
                                    std::to_string(r.trial_id) + "'s true stream)");
      r.stamp = Stamp(r.stream);
    }
  }

 public:
  BackendCapabilities Capabilities() const override { return caps_; }
  TrialTruth PreparedTruth() const override { return prepared_ ? prepared_->truth : TrialTruth{}; }

  // A recording needs no reset: each recorded trial starts where it was
  // recorded (the cell places nothing for a backend that does not emulate).
  // The cell's simulated planner would check a target against the
  // workspace: the nominal target after the last trial lies outside a lab
  // frame's workspace, and failed a reset that moves nothing.
  std::optional<BackendResetOutcome> Reset(const BackendResetRequest& request,
                                           const TrialContext&) override {
    BackendResetOutcome out;
    out.ok = true;
    out.achieved = request.target;
    out.attempts = 0;
    return out;
  }

  std::string Prepare(const mechanics::Scene&, const TrialContext& trial) override {
    prepared_ = nullptr;
    const json want = Physical(json::parse(trial.scene_json, nullptr, false));
    std::vector<const Recorded*> hits;
    for (const auto& r : trials_)
      if (Same(r.scene, want)) hits.push_back(&r);
    if (hits.empty())
      return "replay: dataset " + dir_ + " holds no trial with this scene (" +
             std::to_string(trials_.size()) + " recorded trials compared by scene parameters)";
    for (const auto* r : hits)
      if (r->seed == std::to_string(trial.seed)) prepared_ = r;
    if (!prepared_) {
      int& n = served_[want.dump()];
      prepared_ = hits[static_cast<size_t>(n++) % hits.size()];
    }
    if (!prepared_->refused.empty()) {
      const std::string why = prepared_->refused;
      prepared_ = nullptr;
      return why;
    }
    return "";
  }

  ExecuteOutcome Execute(const mechanics::Scene& scene, const TrialContext&,
                         const SampleSink& sink) override {
    ExecuteOutcome out;
    if (!prepared_) {
      out.reason = "replay: execute without a prepared trial";
      return out;
    }
    const Recorded& r = *prepared_;
    const std::string trial = "replay: trial " + std::to_string(r.trial_id) + ": ";
    const fs::path file = format_ == "hdf5" ? fs::path(dir_) / "dataset.h5" : r.stream;
    if (!(Stamp(file) == r.stamp)) {
      out.reason = trial + file.string() +
                   " changed since the cell verified the dataset (restart the cell to verify it "
                   "again)";
      return out;
    }
    // Row by row into the sink: memory stays bounded whatever the file's size.
    std::optional<RowToSample> convert;
    bool stopped = false;
    std::size_t rows = 0;
    try {
      const ColumnsFn on_columns = [&](const std::vector<std::string>& c) {
        convert.emplace(c, scene, r.truth.forces_measured);
      };
      const RowFn on_row = [&](const std::vector<double>& row) {
        if (++rows > r.samples) return false;  // longer than recorded: refused below
        if (!sink(convert->Convert(row, rows))) {
          stopped = true;
          return false;
        }
        return true;
      };
      if (format_ == "hdf5")
        h5_->Stream(r.trial_id, on_columns, on_row);
      else if (format_ == "csv")
        StreamCsv(r.stream.string(), on_columns, on_row);
      else
        StreamJsonl(r.stream.string(), on_columns, on_row);
    } catch (const std::exception& e) {
      out.reason = trial + e.what();
      return out;
    }
    if (stopped) {
      out.reason = "replay: stream stopped by the cell";
      return out;
    }
    if (rows != r.samples) {
      out.reason =
          trial +
          (rows > r.samples ? std::string("the stream has more rows than the ")
                            : "the stream has " + std::to_string(rows) + " rows, not the ") +
          std::to_string(r.samples) + " the manifest recorded";
      return out;
    }
    out.ok = true;
    out.detail_json = json({{"recorded_trial", prepared_->trial_id}, {"dataset", dir_}}).dump();
    return out;
  }

 private:
  // Where the recorded trials happened: every start and every place the
  // cell's travel check puts the object along its pusher's motion (start +
  // the pusher's displacement), 5 cm around. A recording is in its lab's
  // frame, often outside a cell's default workspace; replay moves nothing,
  // so the dataset's own extent is the workspace (nullopt: no scene parses).
  std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> RecordedWorkspace() const {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(HUGE_VAL), hi = -lo;
    for (const auto& r : trials_) {
      mechanics::Scene scene;
      try {
        scene = mechanics::ParseScene(r.scene.dump());
      } catch (const std::exception&) {
        continue;  // refused at Prepare (no scene of this arena matches it)
      }
      const Eigen::Vector3d start = scene.object.pose.position;
      lo = lo.cwiseMin(start);
      hi = hi.cwiseMax(start);
      if (!scene.pusher) continue;
      std::vector<double> times = {scene.duration};
      if (scene.pusher->path)
        times.insert(times.end(), scene.pusher->path->t.begin(), scene.pusher->path->t.end());
      const Eigen::Vector3d p0 = mechanics::PusherPoseAt(*scene.pusher, 0).position;
      for (double t : times) {
        const Eigen::Vector3d at =
            start +
            (mechanics::PusherPoseAt(*scene.pusher, std::min(t, scene.duration)).position - p0);
        lo = lo.cwiseMin(at);
        hi = hi.cwiseMax(at);
      }
    }
    if (!(lo.array() <= hi.array()).all()) return std::nullopt;
    return std::make_pair(Eigen::Vector3d(lo.array() - 0.05), Eigen::Vector3d(hi.array() + 0.05));
  }

  fs::path StreamFile(std::int64_t id) const {
    return fs::path(dir_) / "streams" / (std::to_string(id) + "_true." + format_);
  }

  std::string dir_;
  std::string format_;
  std::vector<Recorded> trials_;
  std::unique_ptr<Hdf5Recording> h5_;  // format hdf5: dataset.h5, open while the cell runs
  bool measured_ = false;              // manifest "truth": "measured" (arena import)
  std::map<std::string, int> served_;
  const Recorded* prepared_ = nullptr;
  BackendCapabilities caps_;
};

}  // namespace

std::unique_ptr<Backend> MakeReplayBackend(const std::string& dir) {
  return std::make_unique<ReplayBackend>(dir);
}

}  // namespace arena::executors
