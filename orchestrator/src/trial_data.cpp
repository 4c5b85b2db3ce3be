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
  std::string truth;

  bool null() override { return Value(); }
  bool boolean(bool) override { return Value(); }
  bool number_integer(number_integer_t) override { return Value(); }
  bool number_unsigned(number_unsigned_t) override { return Value(); }
  bool number_float(number_float_t, const string_t&) override { return Value(); }
  bool binary(binary_t&) override { return Value(); }
  bool string(string_t& value) override {
    if (wanted_) truth = value;
    return Value();
  }
  bool start_object(std::size_t) override { return Open(); }
  bool end_object() override { return Close(); }
  bool start_array(std::size_t) override { return depth_ > 0 && Open(); }  // top level: no object
  bool end_array() override { return Close(); }
  bool key(string_t& key) override {
    wanted_ = depth_ == 1 && key == "truth";
    return true;
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
    return false;
  }

 private:
  bool Value() {
    wanted_ = false;
    return depth_ > 0;  // a bare scalar is not an object
  }
  bool Open() {
    wanted_ = false;
    ++depth_;
    return true;
  }
  bool Close() {
    --depth_;
    return true;
  }
  int depth_ = 0;
  bool wanted_ = false;
};
}  // namespace

std::string StatedTruth(std::string_view detail_json) {
  TruthReader reader;
  if (!nlohmann::json::sax_parse(detail_json.begin(), detail_json.end(), &reader)) return {};
  return reader.truth;
}

}  // namespace arena::orchestrator
