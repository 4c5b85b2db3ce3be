// replay:DATASET: recorded trials (an `arena export` directory, csv or jsonl)
// served as a cell. A commanded scene is matched to the recorded trials by
// its physical parameters (everything but `model`, numbers to 1e-9
// relative); a recorded trial with the command's seed is preferred (the same
// campaign re-run), otherwise matching trials are served in turn. A scene
// the dataset does not hold is REFUSED, with the reason.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arena/executors/backend.hpp"

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

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw std::invalid_argument("cannot read " + p.string());
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

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

struct Recorded {
  std::int64_t trial_id = 0;
  std::string seed;
  json scene;
};

class ReplayBackend final : public Backend {
 public:
  explicit ReplayBackend(const std::string& dir) : dir_(dir) {
    const fs::path root(dir);
    json manifest;
    try {
      manifest = json::parse(Slurp(root / "manifest.json"));
    } catch (const json::exception& e) {
      throw std::invalid_argument(dir + "/manifest.json: not JSON: " + e.what());
    }
    format_ = manifest.value("export_format", "");
    if (format_ != "csv" && format_ != "jsonl")
      throw std::invalid_argument(dir + ": export format '" + format_ +
                                  "' is not served yet (export with --format csv or jsonl)");
    if (!fs::exists(root / "scenes.jsonl"))
      throw std::invalid_argument(dir + ": no scenes.jsonl (exported by an older arena?)");
    std::istringstream lines(Slurp(root / "scenes.jsonl"));
    std::string line;
    while (std::getline(lines, line)) {
      if (line.empty()) continue;
      const json j = json::parse(line, nullptr, false);
      if (j.is_discarded() || !j.is_object() || !j.contains("scene") || j["scene"].is_null())
        continue;
      Recorded r;
      r.trial_id = j.value("trial_id", std::int64_t{0});
      r.seed = j.contains("seed")
                   ? (j["seed"].is_string() ? j["seed"].get<std::string>() : j["seed"].dump())
                   : "";
      r.scene = Physical(j["scene"]);
      trials_.push_back(std::move(r));
    }
    if (trials_.empty()) throw std::invalid_argument(dir + ": holds no trials");
    caps_.name = "replay:" + dir;
    caps_.truth = TruthSource::kRecorded;
    caps_.engine = "recorded dataset " + fs::absolute(root).string() + " (" +
                   std::to_string(trials_.size()) + " trials, " + format_ + ")";
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
    return "";
  }

  ExecuteOutcome Execute(const mechanics::Scene& scene, const TrialContext&,
                         const SampleSink& sink) override {
    ExecuteOutcome out;
    if (!prepared_) {
      out.reason = "replay: execute without a prepared trial";
      return out;
    }
    std::vector<std::map<std::string, double>> rows;
    try {
      rows = ReadStream(prepared_->trial_id);
    } catch (const std::exception& e) {
      out.reason = std::string("replay: ") + e.what();
      return out;
    }
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
    for (const auto& row : rows) {
      mechanics::TrajectorySample s;
      try {
        const auto at = [&](const std::string& k) {
          auto it = row.find(k);
          if (it == row.end()) throw std::invalid_argument("column '" + k + "' missing");
          return it->second;
        };
        s.t = at("t");
        s.position = {at("x"), at("y"), at("z")};
        s.orientation = Eigen::Quaterniond(at("qw"), at("qx"), at("qy"), at("qz"));
        s.velocity = {at("vx"), at("vy"), at("vz")};
        s.angular_velocity = {at("wx"), at("wy"), at("wz")};
        s.pusher_position = {at("pusher_x"), at("pusher_y"), at("pusher_z")};
        for (size_t c = 0; c < names.size(); ++c) {
          const std::string& n = names[c];
          const Eigen::Vector3d f(at(n + "_fx"), at(n + "_fy"), at(n + "_fz"));
          mechanics::ContactState st;
          st.normal_force = f.dot(normals[c]);
          st.tangential_force = f - st.normal_force * normals[c];
          st.torque = {at(n + "_tx"), at(n + "_ty"), at(n + "_tz")};
          const int mode = static_cast<int>(at(n + "_mode"));
          st.mode = mode == 0   ? mechanics::ContactMode::kStick
                    : mode == 1 ? mechanics::ContactMode::kSlide
                                : mechanics::ContactMode::kSeparate;
          s.contacts.push_back(st);
          if (scene.pusher && c + 1 == names.size()) s.pusher_force = f;
        }
      } catch (const std::exception& e) {
        out.reason = "replay: trial " + std::to_string(prepared_->trial_id) + ": " + e.what();
        return out;
      }
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
  std::vector<std::map<std::string, double>> ReadStream(std::int64_t id) const {
    const fs::path root(dir_);
    std::vector<std::map<std::string, double>> rows;
    if (format_ == "csv") {
      std::istringstream in(Slurp(root / "streams" / (std::to_string(id) + "_true.csv")));
      std::string line;
      if (!std::getline(in, line)) throw std::invalid_argument("empty stream");
      const auto header = SplitCsv(line);
      while (std::getline(in, line)) {
        if (line.empty()) continue;
        const auto cells = SplitCsv(line);
        std::map<std::string, double> row;
        for (size_t k = 0; k < header.size() && k < cells.size(); ++k)
          row[header[k]] = cells[k].empty() ? NAN : std::stod(cells[k]);
        rows.push_back(std::move(row));
      }
    } else {
      std::istringstream in(Slurp(root / "streams" / (std::to_string(id) + "_true.jsonl")));
      std::string line;
      while (std::getline(in, line)) {
        if (line.empty()) continue;
        const json j = json::parse(line);
        std::map<std::string, double> row;
        for (auto it = j.begin(); it != j.end(); ++it)
          row[it.key()] = it->is_number() ? it->get<double>() : NAN;
        rows.push_back(std::move(row));
      }
    }
    return rows;
  }

  std::string dir_;
  std::string format_;
  std::vector<Recorded> trials_;
  std::map<std::string, int> served_;
  const Recorded* prepared_ = nullptr;
  BackendCapabilities caps_;
};

}  // namespace

std::unique_ptr<Backend> MakeReplayBackend(const std::string& dir) {
  return std::make_unique<ReplayBackend>(dir);
}

}  // namespace arena::executors
