// replay:DATASET: recorded trials (an `arena export` directory in any format
// the export writes: csv, jsonl, hdf5) served as a cell. A commanded scene is matched to the
// recorded trials by its physical parameters (everything but `model`, numbers to 1e-9 relative); a
// recorded trial with the command's seed is preferred (the same campaign re-run), otherwise
// matching trials are served in turn. A scene the dataset does not hold is REFUSED, with the
// reason.
#include <cmath>
#include <filesystem>
#include <map>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arena/executors/backend.hpp"
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
// A measured recording whose force stream failed its import check has no
// contact columns at all: its samples then carry no contacts (forces unknown,
// never scored), when `forces_optional`.
std::vector<mechanics::TrajectorySample> ToSamples(const RecordedStream& stream,
                                                   const mechanics::Scene& scene,
                                                   bool forces_optional) {
  std::vector<std::string> names;
  std::vector<Eigen::Vector3d> normals;
  for (size_t i = 0; i < scene.fingers.size(); ++i) {
    names.push_back(scene.fingers[i].name.empty() ? "finger" + std::to_string(i)
                                                  : scene.fingers[i].name);
    normals.push_back(scene.fingers[i].normal.normalized());
  }
  if (scene.pusher) {
    names.push_back("pusher");
    normals.push_back(scene.pusher->normal.normalized());
  }
  const auto col = [&](const std::string& name) {
    const int k = stream.Column(name);
    if (k < 0) throw std::invalid_argument("column '" + name + "' missing");
    return static_cast<size_t>(k);
  };
  const auto cols = [&](const std::string& prefix, std::initializer_list<const char*> axes) {
    std::vector<size_t> out;
    for (const char* a : axes) out.push_back(col(prefix + a));
    return out;
  };
  const auto pose = cols("", {"x", "y", "z", "qw", "qx", "qy", "qz"});
  const auto twist = cols("", {"vx", "vy", "vz", "wx", "wy", "wz"});
  const auto pusher = cols("pusher_", {"x", "y", "z"});
  std::vector<std::vector<size_t>> contact;  // fx fy fz tx ty tz mode
  const bool no_forces = forces_optional && stream.Column("pusher_fx") < 0 &&
                         stream.Column("contact0_fx") < 0 &&
                         (scene.fingers.empty() || stream.Column(names[0] + "_fx") < 0);
  if (no_forces) names.clear();
  for (size_t c = 0; c < names.size(); ++c) {
    const std::string prefix =
        (stream.Column(names[c] + "_fx") >= 0 ? names[c] : "contact" + std::to_string(c)) + "_";
    contact.push_back(cols(prefix, {"fx", "fy", "fz", "tx", "ty", "tz", "mode"}));
  }
  const size_t t = col("t");
  std::vector<mechanics::TrajectorySample> out;
  out.reserve(stream.rows.size());
  for (const auto& row : stream.rows) {
    mechanics::TrajectorySample s;
    const auto v3 = [&](const std::vector<size_t>& k, size_t at) {
      return Eigen::Vector3d(row[k[at]], row[k[at + 1]], row[k[at + 2]]);
    };
    s.t = row[t];
    s.position = v3(pose, 0);
    s.orientation = Eigen::Quaterniond(row[pose[3]], row[pose[4]], row[pose[5]], row[pose[6]]);
    s.velocity = v3(twist, 0);
    s.angular_velocity = v3(twist, 3);
    s.pusher_position = v3(pusher, 0);
    for (size_t c = 0; c < names.size(); ++c) {
      const Eigen::Vector3d f = v3(contact[c], 0);
      mechanics::ContactState st;
      st.normal_force = f.dot(normals[c]);
      st.tangential_force = f - st.normal_force * normals[c];
      st.torque = v3(contact[c], 3);
      const double mode = row[contact[c][6]];
      st.mode = mode == 0   ? mechanics::ContactMode::kStick
                : mode == 1 ? mechanics::ContactMode::kSlide
                            : mechanics::ContactMode::kSeparate;
      s.contacts.push_back(st);
      if (scene.pusher && c + 1 == names.size()) s.pusher_force = f;
    }
    out.push_back(std::move(s));
  }
  return out;
}

struct Recorded {
  std::int64_t trial_id = 0;
  std::string seed;
  json scene;
  std::string refused;  // an imported trial whose poses failed their check: why
};

class ReplayBackend final : public Backend {
 public:
  explicit ReplayBackend(const std::string& dir) : dir_(dir) {
    const fs::path root(dir);
    json manifest;
    try {
      manifest = json::parse(ReadText((root / "manifest.json").string()));
    } catch (const json::exception& e) {
      throw std::invalid_argument(dir + "/manifest.json: not JSON: " + e.what());
    }
    format_ = manifest.value("export_format", "");
    if (format_ != "csv" && format_ != "jsonl" && format_ != "hdf5")
      throw std::invalid_argument(dir + "/manifest.json: export_format '" + format_ +
                                  "' is none of the formats arena writes (hdf5, csv, jsonl)");
    if (!fs::exists(root / "scenes.jsonl"))
      throw std::invalid_argument(dir + ": no scenes.jsonl (exported by an older arena?)");
    std::istringstream lines(ReadText((root / "scenes.jsonl").string()));
    std::string line;
    for (int number = 1; std::getline(lines, line); ++number) {
      if (line.empty()) continue;
      const json j = json::parse(line, nullptr, false);
      if (j.is_discarded() || !j.is_object() || !j.contains("trial_id") ||
          !j["trial_id"].is_number_integer())
        throw std::invalid_argument(dir + "/scenes.jsonl: line " + std::to_string(number) +
                                    ": not an object with a trial_id");
      if (!j.contains("scene") || !j["scene"].is_object()) continue;  // a trial without a scene
      Recorded r;
      r.trial_id = j.value("trial_id", std::int64_t{0});
      r.seed = j.contains("seed")
                   ? (j["seed"].is_string() ? j["seed"].get<std::string>() : j["seed"].dump())
                   : "";
      r.scene = Physical(Canonical(j["scene"]));
      trials_.push_back(std::move(r));
    }
    if (trials_.empty()) throw std::invalid_argument(dir + ": holds no trials");
    // An imported recording (arena import): measured truth, and the trials
    // whose poses failed the import's checks are never served (never scored).
    measured_ = manifest.value("truth", "") == "measured";
    if (manifest.contains("import") && manifest["import"].is_object() &&
        manifest["import"].contains("trials") && manifest["import"]["trials"].is_array()) {
      for (const auto& t : manifest["import"]["trials"]) {
        if (!t.is_object() || t.value("pose_usable", true)) continue;
        for (auto& r : trials_)
          if (r.trial_id == t.value("trial_id", std::int64_t{-1}))
            r.refused = "replay: recorded trial " + std::to_string(r.trial_id) + " (" +
                        t.value("trial", std::string("?")) +
                        ") failed its import check of the poses (" + dir +
                        "/import_report.txt): not served, so never scored";
      }
    }
    // Every served trial's stream is there and well formed before the cell
    // comes up: a broken dataset stops `arena cell` with the file and the
    // reason, not a trial in the middle of a campaign.
    if (format_ == "hdf5") {
      h5_ = std::make_unique<Hdf5Recording>((root / "dataset.h5").string());
      for (const auto& r : trials_) h5_->Check(r.trial_id);
    } else {
      for (const auto& r : trials_)
        if (const fs::path p = StreamFile(r.trial_id); !fs::is_regular_file(p))
          throw std::invalid_argument(p.string() + ": missing (trial " +
                                      std::to_string(r.trial_id) + "'s true stream)");
    }
    caps_.name = "replay:" + dir;
    caps_.truth = measured_ ? TruthSource::kMeasured : TruthSource::kRecorded;
    caps_.engine = std::string(measured_ ? "measured" : "recorded") + " dataset " +
                   fs::absolute(root).string() + " (" + std::to_string(trials_.size()) +
                   " trials, " + format_ + ")";
    caps_.emulates_defects = false;
    caps_.settings_json =
        json({{"dataset", fs::absolute(root).string()}, {"trials", trials_.size()}}).dump();
  }

  BackendCapabilities Capabilities() const override { return caps_; }

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
    RecordedStream stream;
    try {
      stream = ReadStream(prepared_->trial_id);
    } catch (const std::exception& e) {
      out.reason = std::string("replay: ") + e.what();
      return out;
    }
    std::vector<mechanics::TrajectorySample> samples;
    try {
      samples = ToSamples(stream, scene, measured_);
    } catch (const std::exception& e) {
      out.reason = "replay: trial " + std::to_string(prepared_->trial_id) + ": " + e.what();
      return out;
    }
    for (const auto& s : samples) {
      if (!sink(s)) {
        out.reason = "replay: stream stopped by the cell";
        return out;
      }
    }
    out.ok = true;
    out.detail_json = json({{"recorded_trial", prepared_->trial_id}, {"dataset", dir_}}).dump();
    return out;
  }

 private:
  fs::path StreamFile(std::int64_t id) const {
    return fs::path(dir_) / "streams" / (std::to_string(id) + "_true." + format_);
  }

  RecordedStream ReadStream(std::int64_t id) const {
    if (format_ == "hdf5") return h5_->Read(id);
    return format_ == "csv" ? ReadCsvStream(StreamFile(id).string())
                            : ReadJsonlStream(StreamFile(id).string());
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
