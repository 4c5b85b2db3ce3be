// Scene JSON: round trip, every validation rule names its field, and the
// bad-input corpus (tests/bad_inputs/scenes/MANIFEST.tsv) is refused at the
// field the manifest names.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/mechanics/scene_json.hpp"

namespace arena::mechanics {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

const fs::path kSourceDir = ARENA_SOURCE_DIR;

json Canonical() { return json::parse(ReadText(kSourceDir / "examples/scenes/canonical.json")); }

// The field a bad scene is refused at ("" when it is accepted).
std::string RefusedAt(const std::string& text, std::string* message = nullptr) {
  try {
    ParseScene(text);
  } catch (const SceneError& e) {
    if (message) *message = e.what();
    return e.field();
  }
  return "";
}

void ExpectSameScene(const Scene& a, const Scene& b) {
  EXPECT_EQ(a.object.shape, b.object.shape);
  EXPECT_EQ(a.object.size, b.object.size);
  EXPECT_EQ(a.object.radius, b.object.radius);
  EXPECT_EQ(a.object.height, b.object.height);
  EXPECT_EQ(a.object.mass, b.object.mass);
  ASSERT_EQ(a.object.inertia.has_value(), b.object.inertia.has_value());
  if (a.object.inertia) {
    EXPECT_EQ(*a.object.inertia, *b.object.inertia);
  }
  EXPECT_EQ(a.object.pose.position, b.object.pose.position);
  EXPECT_EQ(a.object.pose.rpy, b.object.pose.rpy);
  EXPECT_EQ(a.gravity, b.gravity);
  EXPECT_EQ(a.duration, b.duration);
  EXPECT_EQ(a.grip_force, b.grip_force);
  ASSERT_EQ(a.fingers.size(), b.fingers.size());
  auto same_contact = [](const ContactSpec& x, const ContactSpec& y) {
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.type, y.type);
    EXPECT_EQ(x.position, y.position);
    EXPECT_EQ(x.normal, y.normal);
    if (x.type == ContactType::kLine) {
      EXPECT_EQ(x.axis, y.axis);
      EXPECT_EQ(x.length, y.length);
    }
    if (x.type == ContactType::kPatch) {
      EXPECT_EQ(x.radius, y.radius);
    }
    EXPECT_EQ(x.mu, y.mu);
  };
  for (size_t i = 0; i < a.fingers.size(); ++i) same_contact(a.fingers[i], b.fingers[i]);
  ASSERT_EQ(a.pusher.has_value(), b.pusher.has_value());
  if (a.pusher) {
    same_contact(*a.pusher, *b.pusher);
    EXPECT_EQ(a.pusher->motion.velocity, b.pusher->motion.velocity);
    EXPECT_EQ(a.pusher->motion.angular_velocity, b.pusher->motion.angular_velocity);
  }
  EXPECT_EQ(a.model.facets, b.model.facets);
  EXPECT_EQ(a.model.points, b.model.points);
  EXPECT_EQ(a.model.dt, b.model.dt);
  EXPECT_EQ(a.model.reduce, b.model.reduce);
}

TEST(SceneJson, ParsesTheCanonicalSceneOfSceneMd) {
  const Scene s = ParseScene(Canonical().dump());
  EXPECT_EQ(s.object.shape, ObjectShape::kBox);
  EXPECT_EQ(s.object.size, Eigen::Vector3d(0.05, 0.03, 0.10));
  EXPECT_EQ(s.object.mass, 0.2);
  EXPECT_EQ(s.gravity, Eigen::Vector3d(0, 0, -9.81));
  ASSERT_EQ(s.fingers.size(), 2u);
  EXPECT_EQ(s.fingers[1].name, "right");
  EXPECT_EQ(s.fingers[1].type, ContactType::kLine);
  EXPECT_EQ(s.fingers[1].axis, Eigen::Vector3d(0, 0, 1));
  EXPECT_EQ(s.fingers[1].length, 0.02);
  ASSERT_TRUE(s.pusher.has_value());
  EXPECT_EQ(s.pusher->name, "pusher");
  EXPECT_EQ(s.pusher->motion.velocity, Eigen::Vector3d(0, 0, 0.01));
  EXPECT_EQ(s.model.facets, 8);
  EXPECT_EQ(s.model.reduce, Reduce::kAuto);
}

TEST(SceneJson, RoundTripIsExact) {
  const Scene s = ParseScene(Canonical().dump());
  const std::string text = SceneToJson(s);
  const Scene again = ParseScene(text);
  ExpectSameScene(s, again);
  EXPECT_EQ(SceneToJson(again), text);
  EXPECT_EQ(SceneToJson(again, 2), SceneToJson(s, 2));
}

TEST(SceneJson, RoundTripOfCylinderWithInertiaPatchAndAwkwardNumbers) {
  json j = Canonical();
  j["object"] = {{"shape", "cylinder"},
                 {"radius", 0.1 / 3},
                 {"height", 0.1},
                 {"mass", 0.3},
                 {"inertia", {{1e-4, 1e-6, 0}, {1e-6, 1.1e-4, 0}, {0, 0, 1.5e-4}}},
                 {"pose", {{"position", {0.001, 0, 0}}, {"rpy", {0, 0, 0.3}}}}};
  const double r = 0.1 / 3;
  j["fingers"] = {{{"name", "a"},
                   {"type", "patch"},
                   {"position", {0.001 - r, 0, 0}},
                   {"normal", {1, 0, 0}},
                   {"radius", 0.005},
                   {"mu", 0.7}},
                  {{"name", "b"},
                   {"type", "point"},
                   {"position", {0.001 + r, 0, 0}},
                   {"normal", {-1, 0, 0}},
                   {"mu", 1.0 / 3}}};
  j["pusher"]["position"] = {0.001, 0, -0.05};
  j["model"] = {{"facets", 12}, {"points", 5}, {"dt", 0.001}, {"reduce", "full"}};
  const Scene s = ParseScene(j.dump());
  ExpectSameScene(s, ParseScene(SceneToJson(s)));
  EXPECT_EQ(s.fingers[1].mu, 1.0 / 3);
}

TEST(SceneJson, DefaultsForOptionalFields) {
  json j = Canonical();
  j.erase("gravity");
  j.erase("pusher");
  j.erase("model");
  j["object"].erase("pose");
  const Scene s = ParseScene(j.dump());
  EXPECT_EQ(s.gravity, Eigen::Vector3d::Zero());
  EXPECT_FALSE(s.pusher.has_value());
  EXPECT_EQ(s.model.facets, ModelOptions{}.facets);
  EXPECT_EQ(s.object.pose.position, Eigen::Vector3d::Zero());
  ExpectSameScene(s, ParseScene(SceneToJson(s)));
}

TEST(SceneJson, NearlyUnitDirectionsAreNormalised) {
  json j = Canonical();
  j["fingers"][0]["normal"] = {1.0005, 0, 0};
  j["fingers"][1]["axis"] = {0.0005, 0, 1};
  const Scene s = ParseScene(j.dump());
  EXPECT_NEAR(s.fingers[0].normal.norm(), 1, 1e-15);
  EXPECT_NEAR(s.fingers[1].axis.norm(), 1, 1e-15);
  EXPECT_NEAR(s.fingers[1].axis.dot(s.fingers[1].normal), 0, 1e-15);
}

// One rule per row: a mutation of the canonical scene, the field the error
// must name and a piece of its reason.
struct Rule {
  const char* what;
  std::function<void(json&)> mutate;
  const char* field;
  const char* reason;
};

TEST(SceneJson, EachRuleNamesItsField) {
  const std::vector<Rule> rules = {
      {"negative mu", [](json& j) { j["fingers"][1]["mu"] = -0.2; }, "fingers[1].mu",
       "must be >= 0, got -0.2"},
      {"zero mass", [](json& j) { j["object"]["mass"] = 0; }, "object.mass", "must be > 0, got 0"},
      {"negative size", [](json& j) { j["object"]["size"][2] = -0.1; }, "object.size[2]",
       "must be > 0"},
      {"size of 2",
       [](json& j) {
         j["object"]["size"] = {0.1, 0.1};
       },
       "object.size", "3 numbers"},
      {"cylinder zero height",
       [](json& j) {
         j["object"] = {{"shape", "cylinder"}, {"radius", 0.025}, {"height", 0}, {"mass", 1}};
       },
       "object.height", "must be > 0"},
      {"box with radius", [](json& j) { j["object"]["radius"] = 0.1; }, "object.radius",
       "only for shape"},
      {"missing shape", [](json& j) { j["object"].erase("shape"); }, "object.shape", "is required"},
      {"pose typo",
       [](json& j) {
         j["object"]["pose"]["rpy "] = {0, 0, 0};
       },
       "object.pose.rpy ", "unknown key"},
      {"pose position NaN-free but string",
       [](json& j) { j["object"]["pose"]["position"][1] = "0"; }, "object.pose.position[1]",
       "must be a number, got a string"},
      {"gravity null", [](json& j) { j["gravity"] = nullptr; }, "gravity", "got null"},
      {"zero duration", [](json& j) { j["duration"] = 0.0; }, "duration", "must be > 0"},
      {"hour-long duration", [](json& j) { j["duration"] = 3601.0; }, "duration",
       "must be <= 3600"},
      {"negative grip force", [](json& j) { j["grip_force"] = -1; }, "grip_force",
       "must be >= 0, got -1"},
      {"finger without name", [](json& j) { j["fingers"][0].erase("name"); }, "fingers[0].name",
       "is required"},
      {"finger named pusher", [](json& j) { j["fingers"][0]["name"] = "pusher"; },
       "fingers[0].name", "reserved"},
      {"finger name with comma", [](json& j) { j["fingers"][0]["name"] = "a,b"; },
       "fingers[0].name", "may contain"},
      {"duplicate names", [](json& j) { j["fingers"][1]["name"] = "left"; }, "fingers[1].name",
       "duplicates"},
      {"unknown type", [](json& j) { j["fingers"][0]["type"] = "edge"; }, "fingers[0].type",
       "\"edge\""},
      {"line without axis", [](json& j) { j["fingers"][1].erase("axis"); }, "fingers[1].axis",
       "is required"},
      {"zero axis",
       [](json& j) {
         j["fingers"][1]["axis"] = {0, 0, 0};
       },
       "fingers[1].axis", "zero vector"},
      {"axis along normal",
       [](json& j) {
         j["fingers"][1]["axis"] = {1, 0, 0};
       },
       "fingers[1].axis", "perpendicular"},
      {"negative length", [](json& j) { j["fingers"][1]["length"] = -0.02; }, "fingers[1].length",
       "must be > 0"},
      {"line off the face", [](json& j) { j["fingers"][1]["length"] = 0.2; }, "fingers[1].length",
       "surface"},
      {"point with axis",
       [](json& j) {
         j["fingers"][0]["axis"] = {0, 0, 1};
       },
       "fingers[0].axis", "only for type"},
      {"patch without radius", [](json& j) { j["fingers"][0]["type"] = "patch"; },
       "fingers[0].radius", "is required"},
      {"non-unit normal",
       [](json& j) {
         j["fingers"][0]["normal"] = {0.5, 0, 0};
       },
       "fingers[0].normal", "norm 0.5"},
      {"outward normal",
       [](json& j) {
         j["fingers"][0]["normal"] = {-1, 0, 0};
       },
       "fingers[0].normal", "into the object"},
      {"off surface",
       [](json& j) {
         j["fingers"][0]["position"] = {-0.03, 0, 0};
       },
       "fingers[0].position", "surface"},
      {"too many fingers",
       [](json& j) {
         for (int i = 0; i < 20; ++i) j["fingers"].push_back(j["fingers"][0]);
       },
       "fingers", "at most 16"},
      {"coincident fingers",
       [](json& j) {
         j["fingers"][1] = j["fingers"][0];
         j["fingers"][1]["name"] = "twin";
         j["fingers"][1]["position"] = {-0.025, 0, 1e-9};
       },
       "fingers[1].position", "coincides with fingers[0]"},
      {"pusher on a finger",
       [](json& j) {
         j["pusher"]["position"] = {-0.025, 0, 0};
         j["pusher"]["normal"] = {1, 0, 0};
       },
       "pusher.position", "coincides with fingers[0]"},
      {"pusher name", [](json& j) { j["pusher"]["name"] = "p"; }, "pusher.name", "unknown key"},
      {"pusher motion typo",
       [](json& j) {
         j["pusher"]["motion"]["velocty"] = {0, 0, 1};
       },
       "pusher.motion.velocty", "unknown key"},
      {"pusher negative mu", [](json& j) { j["pusher"]["mu"] = -1e-9; }, "pusher.mu",
       "must be >= 0"},
      {"facets 2", [](json& j) { j["model"]["facets"] = 2; }, "model.facets", "[3, 64]"},
      {"facets string", [](json& j) { j["model"]["facets"] = "8"; }, "model.facets",
       "got a string"},
      {"points 1", [](json& j) { j["model"]["points"] = 1; }, "model.points", "[2, 32]"},
      {"patch with 2 points",
       [](json& j) {
         j["fingers"][0]["type"] = "patch";
         j["fingers"][0]["radius"] = 0.005;
         j["model"]["points"] = 2;
       },
       "model.points", ">= 3 when the scene has a patch"},
      {"dt zero", [](json& j) { j["model"]["dt"] = 0; }, "model.dt", "must be > 0"},
      {"dt above duration", [](json& j) { j["model"]["dt"] = 1.5; }, "model.dt", "<= duration"},
      {"reduce", [](json& j) { j["model"]["reduce"] = "2d"; }, "model.reduce", "\"2d\""},
      {"inertia 2x3",
       [](json& j) {
         j["object"]["inertia"] = {{1, 0, 0}, {0, 1, 0}};
       },
       "object.inertia", "3x3"},
      {"inertia impossible",
       [](json& j) {
         j["object"]["inertia"] = {{1e-4, 0, 0}, {0, 1e-4, 0}, {0, 0, 3e-4}};
       },
       "object.inertia", "triangle inequality"},
      {"one finger", [](json& j) { j["fingers"].erase(1); }, "fingers", "do not balance"},
      {"fingers on one side",
       [](json& j) {
         j["fingers"][1]["position"] = {-0.025, 0, 0.03};
         j["fingers"][1]["normal"] = {1, 0, 0};
       },
       "fingers", "do not balance"},
      {"unknown top key",
       [](json& j) {
         j["gravity_"] = {0, 0, 0};
       },
       "gravity_", "unknown key"},
  };
  for (const Rule& rule : rules) {
    SCOPED_TRACE(rule.what);
    json j = Canonical();
    rule.mutate(j);
    std::string message;
    EXPECT_EQ(RefusedAt(j.dump(), &message), rule.field) << message;
    EXPECT_NE(message.find(rule.reason), std::string::npos) << message;
    EXPECT_EQ(message.rfind(rule.field + std::string(": "), 0), 0u) << message;
  }
}

TEST(SceneJson, MessageHasTheContractFormat) {
  json j = Canonical();
  j["fingers"][1]["mu"] = -0.2;
  std::string message;
  RefusedAt(j.dump(), &message);
  EXPECT_EQ(message, "fingers[1].mu: must be >= 0, got -0.2");
}

TEST(SceneJson, MalformedJsonNamesByteOffsetAndPath) {
  std::string message;
  const std::string text = R"({"object": {"shape": "box", "mass": ,}})";
  EXPECT_EQ(RefusedAt(text, &message), "object.mass");
  EXPECT_NE(message.find("invalid JSON at byte offset 36"), std::string::npos) << message;
}

TEST(SceneJson, UserTextInMessagesIsBoundedAndPrintable) {
  json j = Canonical();
  j["fingers"][0][std::string(100000, 'k') + "\x01"] = 1;
  std::string message;
  const std::string field = RefusedAt(j.dump(), &message);
  EXPECT_LT(field.size(), 100u);
  EXPECT_LT(message.size(), 400u);
  j = Canonical();
  j["object"]["shape"] = "\xc3\xa9" + std::string(39, 'x') + "\xc3\xa9";  // cut mid-character
  RefusedAt(j.dump(), &message);
  EXPECT_NO_THROW((void)json(message).dump());
}

TEST(SceneJson, ValidateSceneChecksScenesBuiltInCode) {
  Scene s = ParseScene(Canonical().dump());
  EXPECT_NO_THROW(ValidateScene(s));
  Scene bad = s;
  bad.fingers[0].normal =
      Eigen::Vector3d(1.001, 0, 0);  // parse would normalise; code must not rely on it
  try {
    ValidateScene(bad);
    ADD_FAILURE() << "accepted a non-unit normal";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "fingers[0].normal");
  }
  bad = s;
  bad.pusher->motion.velocity.x() = std::nan("");
  try {
    ValidateScene(bad);
    ADD_FAILURE() << "accepted a NaN velocity";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "pusher.motion.velocity[0]");
  }
  bad = s;
  bad.model.facets = 0;
  EXPECT_THROW(ValidateScene(bad), SceneError);
}

// tests/bad_inputs/scenes/MANIFEST.tsv: file, field ("<root>" for the
// document; a trailing '*' matches a prefix).
struct CorpusEntry {
  std::string file;
  std::string field;
};

std::vector<CorpusEntry> ReadManifest() {
  std::vector<CorpusEntry> out;
  std::ifstream in(kSourceDir / "tests/bad_inputs/scenes/MANIFEST.tsv");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const auto tab = line.find('\t');
    out.push_back({line.substr(0, tab), line.substr(tab + 1)});
  }
  return out;
}

bool FieldMatches(const std::string& field, const std::string& expected) {
  if (expected == "<root>") return field.empty();
  if (!expected.empty() && expected.back() == '*') {
    return field.rfind(expected.substr(0, expected.size() - 1), 0) == 0;
  }
  return field == expected;
}

TEST(SceneJson, BadInputCorpusIsRefusedAtTheManifestField) {
  const auto corpus = ReadManifest();
  ASSERT_GE(corpus.size(), 40u);
  for (const auto& entry : corpus) {
    SCOPED_TRACE(entry.file);
    const fs::path path = kSourceDir / "tests/bad_inputs/scenes" / entry.file;
    ASSERT_TRUE(fs::exists(path));
    try {
      LoadSceneFile(path.string());
      ADD_FAILURE() << "accepted";
    } catch (const SceneError& e) {
      EXPECT_TRUE(FieldMatches(e.field(), entry.field)) << e.what();
      // The message goes into JSON output: it must be valid UTF-8 and short.
      EXPECT_NO_THROW((void)json(e.what()).dump());
      EXPECT_LT(std::string(e.what()).size(), 400u);
    }
  }
}

TEST(SceneJson, OversizedInputIsRefusedBeforeParsing) {
  // A valid-looking document just over the limit: padding in a string.
  json j = Canonical();
  std::string text = j.dump();
  text.insert(text.size() - 1, ", \"pad\": \"" + std::string(kMaxSceneBytes, 'x') + "\"");
  std::string message;
  EXPECT_EQ(RefusedAt(text, &message), "");
  EXPECT_NE(message.find("larger than the limit"), std::string::npos) << message;

  // A 100 MB file is refused by size without reading it.
  const fs::path dir =
      fs::temp_directory_path() / ("arena_scene_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path big = dir / "big.json";
  {
    std::ofstream out(big, std::ios::binary);
    out.seekp(100 * 1000 * 1000 - 1);
    out.put('}');
  }
  try {
    LoadSceneFile(big.string());
    ADD_FAILURE() << "accepted a 100 MB scene";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "");
    EXPECT_NE(std::string(e.what()).find("100000000 bytes"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

// The fuzzer's corpus (scripts/fuzz.sh seeds it with the example and bad
// scenes) and the inputs it once crashed on (tests/fuzz/crashers/scene_fuzz,
// when there are any): each must be parsed, and then survive a round trip,
// or be refused with a SceneError; anything else thrown fails the test.
TEST(SceneJson, FuzzCorpusAndCrashersAreHandled) {
  int replayed = 0, accepted = 0;
  for (const char* sub :
       {"examples/scenes", "tests/bad_inputs/scenes", "tests/fuzz/crashers/scene_fuzz"}) {
    const fs::path dir = kSourceDir / sub;
    if (!fs::exists(dir)) continue;  // crashers: none recorded yet
    for (const auto& entry : fs::directory_iterator(dir)) {
      SCOPED_TRACE(entry.path().string());
      ++replayed;
      try {
        const Scene s = ParseScene(ReadText(entry.path()));
        ++accepted;
        EXPECT_EQ(SceneToJson(ParseScene(SceneToJson(s))), SceneToJson(s));
      } catch (const SceneError&) {
      }
    }
  }
  EXPECT_GE(replayed, 50);
  EXPECT_GE(accepted, 1);         // the example scene
  EXPECT_LT(accepted, replayed);  // the bad ones are refused
}

TEST(SceneJson, MissingFileIsRefused) {
  EXPECT_THROW(LoadSceneFile("/nonexistent/scene.json"), SceneError);
}

// Issue 31: "gripper": {"coupling": ...} says whether the two fingers are one
// parallel-jaw mechanism. Absent keeps the meaning every scene had (independent
// pads), and is written back only when it says otherwise, so existing scene
// files round-trip to the same text.
TEST(SceneJson, GripperCouplingIsAnAdditionThatDefaultsToIndependentPads) {
  json j = Canonical();
  const Scene plain = ParseScene(j.dump());
  EXPECT_EQ(plain.gripper.coupling, GripperCoupling::kIndependent);
  EXPECT_EQ(json::parse(SceneToJson(plain)).count("gripper"), 0u);

  j["gripper"] = {{"coupling", "parallel_jaw"}};
  const Scene jaw = ParseScene(j.dump());
  EXPECT_EQ(jaw.gripper.coupling, GripperCoupling::kParallelJaw);
  EXPECT_EQ(json::parse(SceneToJson(jaw))["gripper"]["coupling"], "parallel_jaw");
  EXPECT_EQ(ParseScene(SceneToJson(jaw)).gripper.coupling, GripperCoupling::kParallelJaw);

  j["gripper"] = {{"coupling", "independent"}};
  EXPECT_EQ(ParseScene(j.dump()).gripper.coupling, GripperCoupling::kIndependent);

  std::string message;
  j["gripper"] = {{"coupling", "vacuum"}};
  EXPECT_EQ(RefusedAt(j.dump(), &message), "gripper.coupling");
  EXPECT_NE(message.find("parallel_jaw"), std::string::npos) << message;
  j["gripper"] = {{"coupling", "independent"}, {"stroke", 0.1}};
  EXPECT_EQ(RefusedAt(j.dump()), "gripper.stroke");
  j["gripper"] = "parallel_jaw";
  EXPECT_EQ(RefusedAt(j.dump()), "gripper");

  // The example of a lab's parallel-jaw gripper reads as one.
  EXPECT_EQ(
      LoadSceneFile((kSourceDir / "examples/scenes/parallel_jaw.json").string()).gripper.coupling,
      GripperCoupling::kParallelJaw);

  // A jaw moves two opposed fingers: three fingers, or two that do not oppose, are refused.
  j["gripper"] = {{"coupling", "parallel_jaw"}};
  json one = j;
  one["fingers"] = json::array({j["fingers"][0]});
  one["grip_force"] = 0.0;
  EXPECT_EQ(RefusedAt(one.dump(), &message), "gripper.coupling") << message;
}

}  // namespace
}  // namespace arena::mechanics
