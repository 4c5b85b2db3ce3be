// What the store keeps of a scene (db::SceneFacts) is computed by its caller
// from the parsed scene (issue 27: db reads no scene). Checked here against
// the scene's JSON read independently, field by field, so the stored columns
// and the outcomes' contact sites mean what docs/scene.md says.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/scene_facts.hpp"

namespace arena::orchestrator {
namespace {

using nlohmann::json;

std::string ReadExample(const std::string& name) {
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/examples/scenes/" + name);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

double Norm(const json& v) {
  return std::sqrt(v[0].get<double>() * v[0].get<double>() +
                   v[1].get<double>() * v[1].get<double>() +
                   v[2].get<double>() * v[2].get<double>());
}

int Bit(const std::string& type) {
  return type == "point" ? db::kPointBit : type == "line" ? db::kLineBit : db::kPatchBit;
}

TEST(SceneFacts, AreWhatTheSceneJsonSays) {
  for (const char* name : {"canonical.json", "parallel_jaw.json"}) {
    SCOPED_TRACE(name);
    const std::string text = ReadExample(name);
    ASSERT_FALSE(text.empty());
    const json j = json::parse(text);
    const db::SceneFacts f = SceneFactsOfJson(text);
    EXPECT_EQ(f.object_shape, j["object"]["shape"].get<std::string>());
    EXPECT_EQ(f.object_mass, j["object"]["mass"].get<double>());
    EXPECT_EQ(f.grip_force, j["grip_force"].get<double>());
    EXPECT_EQ(f.duration, j["duration"].get<double>());
    const auto& fingers = j["fingers"];
    ASSERT_EQ(f.finger_count, static_cast<int>(fingers.size()));
    double mu = 0;
    int mask = 0;
    std::string type = fingers[0].value("type", "point");
    for (const auto& finger : fingers) {
      mu += finger["mu"].get<double>();
      mask |= Bit(finger.value("type", "point"));
      if (finger.value("type", "point") != type) type = "mixed";
    }
    EXPECT_EQ(f.finger_type, type);
    EXPECT_DOUBLE_EQ(*f.finger_mu, mu / static_cast<double>(fingers.size()));
    ASSERT_TRUE(j.contains("pusher"));
    const auto& p = j["pusher"];
    mask |= Bit(p.value("type", "point"));
    EXPECT_EQ(f.contact_mask, mask);
    EXPECT_EQ(f.pusher_type, p.value("type", "point"));
    EXPECT_EQ(f.pusher_mu, p["mu"].get<double>());
    EXPECT_DOUBLE_EQ(*f.pusher_speed, Norm(p["motion"]["velocity"]));
    EXPECT_DOUBLE_EQ(*f.pusher_angular_speed, p["motion"].contains("angular_velocity")
                                                  ? Norm(p["motion"]["angular_velocity"])
                                                  : 0.0);
    // Nominal pose: the position, and the quaternion of rpy about fixed x, y, z
    // (R = Rz Ry Rx), here by the half-angle product, up to its sign.
    const auto pos = j["object"]["pose"].value("position", json::array({0, 0, 0}));
    const auto rpy = j["object"]["pose"].value("rpy", json::array({0, 0, 0}));
    for (int i = 0; i < 3; ++i) EXPECT_EQ(f.nominal[i], pos[i].get<double>());
    const double cr = std::cos(rpy[0].get<double>() / 2), sr = std::sin(rpy[0].get<double>() / 2);
    const double cp = std::cos(rpy[1].get<double>() / 2), sp = std::sin(rpy[1].get<double>() / 2);
    const double cy = std::cos(rpy[2].get<double>() / 2), sy = std::sin(rpy[2].get<double>() / 2);
    const double q[4] = {cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                         cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy};
    const double sign = q[0] * f.nominal[3] >= 0 ? 1 : -1;
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(f.nominal[3 + i], sign * q[i], 1e-15) << i;
    // Contacts in scene order: fingers by name, then the pusher; unit normals.
    ASSERT_EQ(f.contacts.size(), fingers.size() + 1);
    for (std::size_t i = 0; i < f.contacts.size(); ++i) {
      SCOPED_TRACE("contact " + std::to_string(i));
      const bool pusher = i == fingers.size();
      const json& c = pusher ? p : fingers[i];
      EXPECT_EQ(f.contacts[i].pusher, pusher);
      EXPECT_EQ(f.contacts[i].name, pusher ? "pusher" : c["name"].get<std::string>());
      EXPECT_TRUE(f.contacts[i].known);
      const double n = Norm(c["normal"]);
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(f.contacts[i].position[k], c["position"][k].get<double>());
        EXPECT_NEAR(f.contacts[i].normal[k], c["normal"][k].get<double>() / n, 1e-15);
      }
    }
  }
}

// The JSON form the CLI hands the export and the importer gives the same
// facts, bit for bit, as the parsed scene the service plans with.
TEST(SceneFacts, OfTheStoredJsonAreThoseOfTheScene) {
  const mechanics::Scene scene = mechanics::ParseScene(ReadExample("canonical.json"));
  const db::SceneFacts a = SceneFactsOf(scene);
  const db::SceneFacts b = SceneFactsOfJson(mechanics::SceneToJson(scene));
  EXPECT_EQ(a.object_shape, b.object_shape);
  EXPECT_EQ(a.object_mass, b.object_mass);
  EXPECT_EQ(a.finger_mu, b.finger_mu);
  EXPECT_EQ(a.pusher_speed, b.pusher_speed);
  EXPECT_EQ(a.contact_mask, b.contact_mask);
  EXPECT_EQ(a.nominal, b.nominal);
  ASSERT_EQ(a.contacts.size(), b.contacts.size());
  for (std::size_t i = 0; i < a.contacts.size(); ++i) {
    EXPECT_EQ(a.contacts[i].name, b.contacts[i].name);
    EXPECT_EQ(a.contacts[i].normal, b.contacts[i].normal);
  }
}

// A pusher on a recorded path or under a controller has no velocity motion:
// no speeds (NULL columns), as its JSON has none.
TEST(SceneFacts, APathOrControllerPusherHasNoSpeed) {
  mechanics::Scene scene = mechanics::ParseScene(ReadExample("canonical.json"));
  ASSERT_TRUE(scene.pusher);
  scene.pusher->controller = mechanics::PusherController{};
  EXPECT_FALSE(SceneFactsOf(scene).pusher_speed);
  EXPECT_FALSE(SceneFactsOf(scene).pusher_angular_speed);
  EXPECT_TRUE(SceneFactsOf(scene).pusher_mu);
}

TEST(SceneFacts, AnUnreadableSceneThrows) {
  EXPECT_ANY_THROW(SceneFactsOfJson("{"));
  EXPECT_ANY_THROW(SceneFactsOfJson(R"({"object": {}})"));
}

}  // namespace
}  // namespace arena::orchestrator
