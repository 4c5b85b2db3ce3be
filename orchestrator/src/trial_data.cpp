#include "arena/orchestrator/trial_data.hpp"

#include <stdexcept>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/schemas/arena.h"
#include "arena/schemas/ground_truth.hpp"

namespace arena::orchestrator {

// The cell's words (schemas) and the store's (db) for a truth without forces.
static_assert(std::string_view(dds::kTruthMeasuredNoForces) ==
              std::string_view(db::kTruthMeasuredNoForces));

namespace {
db::ContactMode ToStore(mechanics::ContactMode m) {
  switch (m) {
    case mechanics::ContactMode::kStick:
      return db::ContactMode::kStick;
    case mechanics::ContactMode::kSlide:
      return db::ContactMode::kSlide;
    case mechanics::ContactMode::kSeparate:
      return db::ContactMode::kSeparate;
  }
  return db::ContactMode::kSeparate;
}
void CheckCount(size_t contacts, size_t normals) {
  if (contacts != normals) {
    throw std::invalid_argument("sample has " + std::to_string(contacts) + " contacts, the scene " +
                                std::to_string(normals));
  }
}
}  // namespace

db::Sample ToStoreSample(const msg::GroundTruthSample& in,
                         const std::vector<Eigen::Vector3d>& normals,
                         mechanics::TrajectorySample* truth_out, bool contactless_ok) {
  dds::PusherState pusher;
  dds::Observation observed;
  mechanics::TrajectorySample truth = dds::DecodeSample(in, &pusher, &observed);
  if (!(contactless_ok && truth.contacts.empty()))
    CheckCount(truth.contacts.size(), normals.size());
  db::Sample s;
  s.t = truth.t;
  const auto& q = truth.orientation;
  s.object_pose = {
      truth.position.x(), truth.position.y(), truth.position.z(), q.w(), q.x(), q.y(), q.z()};
  s.object_twist = {truth.velocity.x(),         truth.velocity.y(),
                    truth.velocity.z(),         truth.angular_velocity.x(),
                    truth.angular_velocity.y(), truth.angular_velocity.z()};
  const auto& pq = pusher.orientation;
  s.pusher_pose = {pusher.position.x(),
                   pusher.position.y(),
                   pusher.position.z(),
                   pq.w(),
                   pq.x(),
                   pq.y(),
                   pq.z()};
  s.pusher_twist = {pusher.velocity.x(),         pusher.velocity.y(),
                    pusher.velocity.z(),         pusher.angular_velocity.x(),
                    pusher.angular_velocity.y(), pusher.angular_velocity.z()};
  s.contacts.resize(truth.contacts.size());
  for (size_t i = 0; i < truth.contacts.size(); ++i) {
    const auto& c = truth.contacts[i];
    const Eigen::Vector3d force = c.normal_force * normals[i] + c.tangential_force;
    s.contacts[i].force = {force.x(), force.y(), force.z()};
    s.contacts[i].torque = {c.torque.x(), c.torque.y(), c.torque.z()};
    s.contacts[i].mode = ToStore(c.mode);
  }
  s.observed_valid = observed.valid;
  if (observed.valid) {
    const auto& oq = observed.orientation;
    s.observed_object_pose = {observed.position.x(),
                              observed.position.y(),
                              observed.position.z(),
                              oq.w(),
                              oq.x(),
                              oq.y(),
                              oq.z()};
    for (int k = 0; k < 6; ++k) s.observed_pusher_wrench[k] = observed.pusher_wrench[k];
    for (const auto& w : observed.finger_wrenches)
      for (int k = 0; k < 6; ++k) s.observed_finger_wrenches.push_back(w[k]);
  } else {
    // A dropped sample keeps the trial's shape (zeros for every finger value
    // the cell sent), so the export's columns stay the same for all samples.
    s.observed_finger_wrenches.assign(in.observed_finger_wrenches().size() / 6 * 6, 0.0);
  }
  if (truth_out) *truth_out = std::move(truth);
  return s;
}

std::vector<db::ContactSite> ContactSitesOf(const mechanics::Scene& scene) {
  auto site = [](const mechanics::ContactSpec& c, bool pusher) {
    db::ContactSite s;
    s.name = pusher ? "pusher" : c.name;
    s.pusher = pusher;
    const Eigen::Vector3d n = c.normal.normalized();
    s.known = c.position.allFinite() && n.allFinite() && c.normal.norm() > 0;
    for (int i = 0; i < 3; ++i) {
      s.position[i] = c.position[i];
      s.normal[i] = s.known ? n[i] : 0.0;
    }
    return s;
  };
  std::vector<db::ContactSite> sites;
  for (const auto& f : scene.fingers) sites.push_back(site(f, false));
  if (scene.pusher) sites.push_back(site(*scene.pusher, true));
  return sites;
}

namespace {
// SAX events: only the depth and whether the value is the top-level "truth"
// are tracked; nothing is built. The whole text is read (a malformed detail
// states no truth, as when it was parsed whole).
class TruthReader : public nlohmann::json_sax<nlohmann::json> {
 public:
  std::string truth, backend;

  bool null() override { return Value(); }
  bool boolean(bool) override { return Value(); }
  bool number_integer(number_integer_t) override { return Value(); }
  bool number_unsigned(number_unsigned_t) override { return Value(); }
  bool number_float(number_float_t, const string_t&) override { return Value(); }
  bool binary(binary_t&) override { return Value(); }
  bool string(string_t& value) override {
    if (wanted_ == Wanted::kTruth) truth = value;
    if (wanted_ == Wanted::kBackend) backend = value;
    return Value();
  }
  bool start_object(std::size_t) override { return Open(); }
  bool end_object() override { return Close(); }
  bool start_array(std::size_t) override { return depth_ > 0 && Open(); }  // top level: no object
  bool end_array() override { return Close(); }
  bool key(string_t& key) override {
    wanted_ = Wanted::kNone;
    if (depth_ != 1) return true;
    // A repeated key: the last one counts, as in a parsed document.
    if (key == "truth") {
      wanted_ = Wanted::kTruth;
      truth.clear();
    } else if (key == "backend") {
      wanted_ = Wanted::kBackend;
      backend.clear();
    }
    return true;
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
    return false;
  }

 private:
  enum class Wanted { kNone, kTruth, kBackend };
  bool Value() {
    wanted_ = Wanted::kNone;
    return depth_ > 0;  // a bare scalar is not an object
  }
  bool Open() {
    wanted_ = Wanted::kNone;
    ++depth_;
    return true;
  }
  bool Close() {
    --depth_;
    return true;
  }
  int depth_ = 0;
  Wanted wanted_ = Wanted::kNone;
};

// The end of the JSON value that starts at `at` in well-formed text: a
// string (escapes skipped), an object or array (nesting counted, strings
// inside skipped), or a scalar (up to the next delimiter).
std::size_t ValueEnd(std::string_view text, std::size_t at) {
  const auto string_end = [&](std::size_t i) {  // i at the opening quote
    for (++i; i < text.size(); ++i) {
      if (text[i] == '\\')
        ++i;
      else if (text[i] == '"')
        return i + 1;
    }
    return text.size();
  };
  if (at >= text.size()) return at;
  if (text[at] == '"') return string_end(at);
  if (text[at] == '{' || text[at] == '[') {
    int depth = 0;
    for (std::size_t i = at; i < text.size();) {
      const char c = text[i];
      if (c == '"') {
        i = string_end(i);
        continue;
      }
      if (c == '{' || c == '[') ++depth;
      if ((c == '}' || c == ']') && --depth == 0) return i + 1;
      ++i;
    }
    return text.size();
  }
  std::size_t i = at;
  while (i < text.size() && std::string_view(",}] \t\r\n").find(text[i]) == std::string_view::npos)
    ++i;
  return i;
}

std::size_t SkipSpace(std::string_view text, std::size_t i) {
  while (i < text.size() &&
         (text[i] == ' ' || text[i] == '\t' || text[i] == '\r' || text[i] == '\n'))
    ++i;
  return i;
}

// The text of the last top-level member `key` of a well-formed JSON object.
std::optional<std::string_view> TopLevelValueText(std::string_view object, std::string_view key) {
  std::optional<std::string_view> found;
  std::size_t i = SkipSpace(object, 0);
  if (i >= object.size() || object[i] != '{') return found;
  i = SkipSpace(object, i + 1);
  while (i < object.size() && object[i] == '"') {
    const std::size_t key_end = ValueEnd(object, i);
    const std::string_view raw_key = object.substr(i + 1, key_end - i - 2);
    // Keys with escapes are decoded before they are compared.
    const bool match =
        raw_key.find('\\') == std::string_view::npos
            ? raw_key == key
            : nlohmann::json::parse(object.substr(i, key_end - i)).get<std::string>() == key;
    i = SkipSpace(object, key_end);
    if (i >= object.size() || object[i] != ':') break;
    const std::size_t value_at = SkipSpace(object, i + 1);
    const std::size_t value_end = ValueEnd(object, value_at);
    if (match) found = object.substr(value_at, value_end - value_at);
    i = SkipSpace(object, value_end);
    if (i >= object.size() || object[i] != ',') break;
    i = SkipSpace(object, i + 1);
  }
  return found;
}
}  // namespace

std::optional<ExecutionDetail> ReadExecutionDetail(std::string_view detail_json) {
  TruthReader reader;
  if (!nlohmann::json::sax_parse(detail_json.begin(), detail_json.end(), &reader)) return {};
  ExecutionDetail d{std::move(reader.backend), std::move(reader.truth), std::nullopt};
  if (const auto defects = TopLevelValueText(detail_json, "defects_applied"))
    d.defects_applied = std::string(*defects);
  return d;
}

}  // namespace arena::orchestrator
