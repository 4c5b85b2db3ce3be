// Campaigns: the examples load and plan valid scenes, planning is
// deterministic and resumable, replicates share their scene, and bad
// campaigns (tests/bad_inputs/campaigns/MANIFEST.tsv) are refused at the
// field the manifest names.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/mechanics/scene_json.hpp"
#include "arena/mechanics/simulate.hpp"
#include "arena/orchestrator/campaign.hpp"

namespace arena::orchestrator {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
const fs::path kSourceDir = ARENA_SOURCE_DIR;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

Campaign Smoke() {
  return LoadCampaignFile((kSourceDir / "examples/campaigns/smoke.json").string());
}

std::string Fingerprint(const PlannedTrial& t) {
  return std::to_string(t.index) + "/" + std::to_string(t.condition) + "/" +
         std::to_string(t.replicate) + "/" + std::to_string(t.seed) + "/" +
         mechanics::SceneToJson(t.scene) + "/" + t.parameters_json;
}

TEST(Campaign, SmokeExamplePlansAbout40ValidTrialsOverAllContactTypes) {
  const Campaign c = Smoke();
  EXPECT_EQ(c.name, "smoke");
  EXPECT_EQ(c.sampler, SamplerKind::kGrid);
  EXPECT_EQ(c.conditions, 12);
  EXPECT_EQ(TrialCount(c), 36);
  std::set<mechanics::ContactType> types;
  std::set<double> pusher_y;
  double total_duration = 0;
  for (int64_t i = 0; i < TrialCount(c); ++i) {
    const PlannedTrial t = PlanTrial(c, i);
    EXPECT_NO_THROW(mechanics::ValidateScene(t.scene)) << i;
    EXPECT_NO_THROW(mechanics::ValidateScene(PredictionScene(c, t))) << i;
    for (const auto& f : t.scene.fingers) types.insert(f.type);
    pusher_y.insert(t.scene.pusher->position.y());
    EXPECT_NEAR(t.scene.duration, 0.2, 1e-12);  // push_distance / push_speed
    total_duration += t.scene.duration;
  }
  EXPECT_EQ(types.size(), 3u);
  EXPECT_EQ(pusher_y.size(), 2u);  // a straight and a pivoting push
  EXPECT_LT(total_duration, 10.0);
  EXPECT_EQ(json::parse(c.defects_json)["latency_ms"], 4);
}

// The first campaign a new user runs must run: every trial simulates, and so
// does its prediction (the timing of the whole set is in the report, not here).
TEST(Campaign, SmokeExampleTrialsSimulateWithTheModel) {
  const Campaign c = Smoke();
  for (int64_t i = 0; i < TrialCount(c); i += c.replicates) {
    const PlannedTrial t = PlanTrial(c, i);
    const auto truth = mechanics::Simulate(t.scene);
    EXPECT_EQ(truth.status, mechanics::SimulationStatus::kOk) << i << ": " << truth.error;
    const auto prediction = mechanics::Simulate(PredictionScene(c, t));
    EXPECT_EQ(prediction.status, mechanics::SimulationStatus::kOk) << i << ": " << prediction.error;
    EXPECT_EQ(prediction.model.facets, 4);
  }
}

TEST(Campaign, LargerExampleResolvesFilesAndPlansValidScenes) {
  const Campaign c =
      LoadCampaignFile((kSourceDir / "examples/campaigns/pivot_study.json").string());
  EXPECT_EQ(c.sampler, SamplerKind::kSobol);
  EXPECT_EQ(TrialCount(c), 2048);
  EXPECT_EQ(c.defects_file, "lab_defects.json");
  EXPECT_EQ(json::parse(c.defects_json)["drop_probability"], 0.002);
  // The stored source is self-contained: scene and defects inlined.
  const json source = json::parse(c.source_json);
  EXPECT_TRUE(source["scene"].is_object());
  EXPECT_TRUE(source["defects"].is_object());
  EXPECT_NO_THROW(ParseCampaign(c.source_json));
  for (int64_t i = 0; i < TrialCount(c); i += 7) {
    const PlannedTrial t = PlanTrial(c, i);
    EXPECT_NO_THROW(mechanics::ValidateScene(t.scene)) << i;
    const json p = json::parse(t.parameters_json);
    EXPECT_GE(p["grip_force"].get<double>(), 2.0);
    EXPECT_LE(p["grip_force"].get<double>(), 20.0);
    EXPECT_EQ(t.scene.grip_force, p["grip_force"].get<double>());
    EXPECT_NEAR(t.scene.object.size.x(), p["object_size_x"].get<double>(), 1e-15);
    // Fingers follow the object's faces when its width changes.
    EXPECT_NEAR(t.scene.fingers[1].position.x(), t.scene.object.size.x() / 2, 1e-12);
  }
}

TEST(Campaign, ReadmeExampleIsValid) {
  const std::string readme = ReadText(kSourceDir / "orchestrator/README.md");
  const auto start = readme.find("```json\n");
  ASSERT_NE(start, std::string::npos);
  const auto end = readme.find("```", start + 8);
  const Campaign c = ParseCampaign(readme.substr(start + 8, end - start - 8),
                                   (kSourceDir / "examples/campaigns").string());
  EXPECT_EQ(TrialCount(c), 36);
}

TEST(Campaign, PlanningIsDeterministic) {
  const Campaign a = Smoke();
  const Campaign b = Smoke();
  for (int64_t i = 0; i < TrialCount(a); ++i)
    EXPECT_EQ(Fingerprint(PlanTrial(a, i)), Fingerprint(PlanTrial(b, i)));
}

TEST(Campaign, PlanningIsResumableFromAnIndex) {
  for (const char* sampler : {"uniform", "latin_hypercube", "sobol", "grid"}) {
    SCOPED_TRACE(sampler);
    json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
    doc["sampler"] = sampler;
    if (std::string(sampler) != "grid") {
      doc["conditions"] = 20;
      doc["variations"]["grip_force"] = {{"min", 5}, {"max", 15}};
    }
    const std::string text = doc.dump();
    const Campaign full = ParseCampaign(text, (kSourceDir / "examples/campaigns").string());
    std::vector<std::string> sequence;
    for (int64_t i = 0; i < TrialCount(full); ++i)
      sequence.push_back(Fingerprint(PlanTrial(full, i)));
    // A "restarted service": a fresh campaign object, starting mid-sequence.
    const Campaign resumed = ParseCampaign(text, (kSourceDir / "examples/campaigns").string());
    for (int64_t i = TrialCount(resumed) - 1; i >= TrialCount(resumed) / 2; --i) {
      EXPECT_EQ(Fingerprint(PlanTrial(resumed, i)), sequence[static_cast<size_t>(i)]) << i;
    }
  }
}

TEST(Campaign, ReplicatesShareTheSceneAndDifferInSeed) {
  const Campaign c = Smoke();
  std::set<uint64_t> seeds;
  for (int64_t condition = 0; condition < c.conditions; ++condition) {
    const PlannedTrial first = PlanTrial(c, condition * c.replicates);
    for (int r = 0; r < c.replicates; ++r) {
      const PlannedTrial t = PlanTrial(c, condition * c.replicates + r);
      EXPECT_EQ(t.condition, condition);
      EXPECT_EQ(t.replicate, r);
      EXPECT_EQ(mechanics::SceneToJson(t.scene), mechanics::SceneToJson(first.scene));
      EXPECT_EQ(t.parameters_json, first.parameters_json);
      seeds.insert(t.seed);
    }
  }
  EXPECT_EQ(seeds.size(), static_cast<size_t>(TrialCount(c)));
}

TEST(Campaign, DifferentSeedsGiveDifferentSamples) {
  json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
  doc["sampler"] = "sobol";
  doc["conditions"] = 8;
  doc["variations"]["grip_force"] = {{"min", 5}, {"max", 15}};
  const Campaign a = ParseCampaign(doc.dump());
  doc["seed"] = 1;
  const Campaign b = ParseCampaign(doc.dump());
  EXPECT_NE(PlanTrial(a, 0).parameters_json, PlanTrial(b, 0).parameters_json);
}

TEST(Campaign, GridCoversEveryCombinationOnce) {
  const Campaign c = Smoke();
  std::set<std::string> combos;
  for (int64_t condition = 0; condition < c.conditions; ++condition) {
    combos.insert(PlanTrial(c, condition * c.replicates).parameters_json);
  }
  EXPECT_EQ(combos.size(), 12u);
  const json first = json::parse(PlanTrial(c, 0).parameters_json);
  EXPECT_EQ(first["grip_force"], 8.0);  // a range's grid includes its ends
}

TEST(Campaign, ReloadingCanSkipTheConditionCheck) {
  json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
  doc["variations"]["pivot_offset"] = {
      {"choices", {0, 0.05}}};  // off the object for half the conditions
  EXPECT_THROW(ParseCampaign(doc.dump()), CampaignError);
  const Campaign c = ParseCampaign(doc.dump(), "", ConditionCheck::kBaseScene);
  EXPECT_EQ(TrialCount(c), 36);
  const Campaign smoke = Smoke();
  const Campaign reloaded = ParseCampaign(smoke.source_json, "", ConditionCheck::kBaseScene);
  EXPECT_EQ(Fingerprint(PlanTrial(reloaded, 35)), Fingerprint(PlanTrial(smoke, 35)));
}

// Listed scenes (an imported dataset's scenes.jsonl): one condition each, the
// listed seed for the first replicate, the scenes inline in the stored campaign.
TEST(Campaign, ListedScenesAreOneConditionEachWithTheirSeeds) {
  const json base = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"))["scene"];
  json second = base;
  second["grip_force"] = 12.5;
  char tmpl[] = "/tmp/arena-scenes-test-XXXXXX";
  const fs::path dir = mkdtemp(tmpl);
  std::ofstream(dir / "scenes.jsonl")
      << json({{"trial_id", 7}, {"seed", "123"}, {"scene", base}}).dump() << "\n"
      << json({{"trial_id", 8}, {"scene", second}}).dump() << "\n";
  const json doc = {{"name", "listed"}, {"seed", 5}, {"scenes", "scenes.jsonl"}, {"replicates", 2}};
  std::ofstream(dir / "campaign.json") << doc.dump();
  const Campaign c = LoadCampaignFile((dir / "campaign.json").string());
  ASSERT_EQ(TrialCount(c), 4);
  EXPECT_EQ(PlanTrial(c, 0).seed, 123u);
  EXPECT_NE(PlanTrial(c, 1).seed, 123u);  // the second replicate: its own seed
  EXPECT_EQ(PlanTrial(c, 2).scene.grip_force, 12.5);
  EXPECT_EQ(PlanTrial(c, 3).parameters_json, R"({"scene_index":1})");
  // Stored and reloaded without the file.
  fs::remove_all(dir);
  const Campaign reloaded = ParseCampaign(c.source_json, "", ConditionCheck::kBaseScene);
  EXPECT_EQ(Fingerprint(PlanTrial(reloaded, 2)), Fingerprint(PlanTrial(c, 2)));
  EXPECT_EQ(PlanTrial(reloaded, 0).seed, 123u);
  // Refused: with variations, an empty list, a bad scene named by its index.
  json bad = doc;
  bad["scenes"] = json::array({base});
  bad["variations"] = {{"grip_force", 3}};
  EXPECT_THROW(ParseCampaign(bad.dump()), CampaignError);
  bad.erase("variations");
  bad["scenes"] = json::array();
  EXPECT_THROW(ParseCampaign(bad.dump()), CampaignError);
  json broken = base;
  broken["object"]["mass"] = -1;
  bad["scenes"] = json::array({base, broken});
  try {
    ParseCampaign(bad.dump());
    ADD_FAILURE() << "accepted";
  } catch (const CampaignError& e) {
    EXPECT_EQ(e.field().rfind("scenes[1]", 0), 0u) << e.what();
  }
}

// A rotated box: contacts placed on its rotated faces stay on them when the
// box is stretched (every condition is validated, surface check included).
TEST(Campaign, StretchingARotatedBoxCarriesTheContacts) {
  const double yaw = 0.3, c = std::cos(yaw), s = std::sin(yaw);
  json scene = json::parse(ReadText(kSourceDir / "examples/scenes/canonical.json"));
  scene["object"]["pose"] = {{"position", {0.01, 0.02, 0}}, {"rpy", {0, 0, yaw}}};
  const double hx = 0.025;
  scene["fingers"][0]["position"] = {0.01 - hx * c, 0.02 - hx * s, 0};
  scene["fingers"][0]["normal"] = {c, s, 0};
  scene["fingers"][1]["position"] = {0.01 + hx * c, 0.02 + hx * s, 0};
  scene["fingers"][1]["normal"] = {-c, -s, 0};
  scene["pusher"]["position"] = {0.01, 0.02, -0.05};
  json doc = {{"name", "rotated"},
              {"seed", 3},
              {"scene", scene},
              {"sampler", "latin_hypercube"},
              {"conditions", 50},
              {"variations",
               {{"object_size_x", {{"min", 0.03}, {"max", 0.09}}},
                {"object_size_z", {{"min", 0.08}, {"max", 0.2}}},
                {"finger_type", {{"choices", {"point", "line", "patch"}}}},
                {"finger_length", 0.02},
                {"finger_radius", 0.004}}}};
  const Campaign campaign = ParseCampaign(doc.dump());
  for (int64_t i = 0; i < TrialCount(campaign); ++i) {
    const PlannedTrial t = PlanTrial(campaign, i);
    // The fingers sit at +-size_x/2 along the rotated x axis.
    const Eigen::Vector3d x_axis(c, s, 0);
    EXPECT_NEAR((t.scene.fingers[1].position - t.scene.object.pose.position).dot(x_axis),
                t.scene.object.size.x() / 2, 1e-12);
    EXPECT_NEAR(t.scene.pusher->position.z(), -t.scene.object.size.z() / 2, 1e-12);
  }
}

TEST(Campaign, CylinderRadiusVariationKeepsFingersOnTheSide) {
  json scene = json::parse(ReadText(kSourceDir / "examples/scenes/canonical.json"));
  scene["object"] = {{"shape", "cylinder"}, {"radius", 0.02}, {"height", 0.1}, {"mass", 0.3}};
  scene["fingers"][0]["position"] = {-0.02, 0, 0};
  scene["fingers"][1]["position"] = {0.02, 0, 0};
  json doc = {
      {"name", "cylinder"},
      {"seed", 4},
      {"scene", scene},
      {"sampler", "sobol"},
      {"conditions", 32},
      {"variations", {{"object_radius", {{"min", 0.01}, {"max", 0.04}}}, {"object_height", 0.12}}}};
  const Campaign campaign = ParseCampaign(doc.dump());
  for (int64_t i = 0; i < TrialCount(campaign); ++i) {
    const PlannedTrial t = PlanTrial(campaign, i);
    EXPECT_NEAR(t.scene.fingers[1].position.x(), t.scene.object.radius, 1e-12);
    EXPECT_NEAR(t.scene.pusher->position.z(), -0.06, 1e-12);
  }
}

// Campaign-level Latin hypercube: n conditions put one value in each of the
// n equal strata of every range.
TEST(Campaign, LatinHypercubeConditionsStratifyEachRange) {
  json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
  doc["sampler"] = "latin_hypercube";
  doc["conditions"] = 40;
  doc["variations"]["grip_force"] = {{"min", 5}, {"max", 15}};
  doc["variations"]["finger_mu"] = {{"min", 0.2}, {"max", 1.0}};
  const Campaign c = ParseCampaign(doc.dump());
  std::vector<int> grip(40, 0), mu(40, 0);
  for (int64_t condition = 0; condition < c.conditions; ++condition) {
    const json p = json::parse(PlanTrial(c, condition * c.replicates).parameters_json);
    ++grip[static_cast<size_t>((p["grip_force"].get<double>() - 5) / 10 * 40)];
    ++mu[static_cast<size_t>((p["finger_mu"].get<double>() - 0.2) / 0.8 * 40)];
  }
  for (int k = 0; k < 40; ++k) {
    EXPECT_EQ(grip[static_cast<size_t>(k)], 1) << k;
    EXPECT_EQ(mu[static_cast<size_t>(k)], 1) << k;
  }
}

TEST(Campaign, LogScaleRangeIsUniformInLog) {
  json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
  doc["sampler"] = "latin_hypercube";
  doc["conditions"] = 100;
  doc["variations"]["grip_force"] = {{"min", 1}, {"max", 100}, {"scale", "log"}};
  const Campaign c = ParseCampaign(doc.dump());
  int below_10 = 0;
  for (int64_t condition = 0; condition < c.conditions; ++condition) {
    const double g =
        json::parse(PlanTrial(c, condition * c.replicates).parameters_json)["grip_force"];
    EXPECT_GE(g, 1.0);
    EXPECT_LE(g, 100.0);
    below_10 += g < 10;
  }
  EXPECT_EQ(below_10, 50);  // half the strata of log(g) lie below log(10)
}

TEST(Campaign, OutOfRangeIndexIsAnError) {
  const Campaign c = Smoke();
  EXPECT_THROW(PlanTrial(c, -1), std::out_of_range);
  EXPECT_THROW(PlanTrial(c, TrialCount(c)), std::out_of_range);
}

TEST(Campaign, ErrorMessageNamesPathAndReason) {
  json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
  doc["variations"]["grip_force"]["min"] = -1;
  try {
    ParseCampaign(doc.dump());
    FAIL() << "accepted";
  } catch (const CampaignError& e) {
    EXPECT_EQ(std::string(e.what()), "variations.grip_force.min: must be >= 0, got -1");
  }
}

// tests/bad_inputs/campaigns/MANIFEST.tsv: file, field ("<root>" for the
// document; a trailing '*' matches a prefix).
TEST(Campaign, BadInputCorpusIsRefusedAtTheManifestField) {
  const fs::path dir = kSourceDir / "tests/bad_inputs/campaigns";
  std::ifstream manifest(dir / "MANIFEST.tsv");
  std::string line;
  int checked = 0;
  while (std::getline(manifest, line)) {
    if (line.empty() || line[0] == '#') continue;
    const auto tab = line.find('\t');
    const std::string file = line.substr(0, tab);
    const std::string expected = line.substr(tab + 1);
    SCOPED_TRACE(file);
    ++checked;
    try {
      LoadCampaignFile((dir / file).string());
      ADD_FAILURE() << "accepted";
    } catch (const CampaignError& e) {
      if (expected == "<root>") {
        EXPECT_EQ(e.field(), "") << e.what();
      } else if (expected.back() == '*') {
        EXPECT_EQ(e.field().rfind(expected.substr(0, expected.size() - 1), 0), 0u) << e.what();
      } else {
        EXPECT_EQ(e.field(), expected) << e.what();
      }
      EXPECT_NO_THROW((void)json(e.what()).dump());  // printable as JSON
      EXPECT_LT(std::string(e.what()).size(), 1000u);
    }
  }
  EXPECT_GE(checked, 30);
}

// The fuzzer's corpus (scripts/fuzz.sh seeds it with the example and bad
// campaigns) and the inputs it once crashed on (tests/fuzz/crashers/
// campaign_fuzz, when there are any): each must be parsed, its first trial's
// scene valid, or be refused with a CampaignError; anything else thrown fails.
TEST(Campaign, FuzzCorpusAndCrashersAreHandled) {
  int replayed = 0, accepted = 0;
  for (const char* sub :
       {"examples/campaigns", "tests/bad_inputs/campaigns", "tests/fuzz/crashers/campaign_fuzz"}) {
    const fs::path dir = kSourceDir / sub;
    if (!fs::exists(dir)) continue;  // crashers: none recorded yet
    for (const auto& entry : fs::directory_iterator(dir)) {
      SCOPED_TRACE(entry.path().string());
      ++replayed;
      try {
        const Campaign c = ParseCampaign(ReadText(entry.path()), "/nonexistent-arena-fuzz-dir");
        ++accepted;
        if (TrialCount(c) > 0) {
          EXPECT_NO_THROW(mechanics::ValidateScene(PlanTrial(c, 0).scene));
        }
      } catch (const CampaignError&) {
      }
    }
  }
  EXPECT_GE(replayed, 40);
  EXPECT_GE(accepted, 1);
  EXPECT_LT(accepted, replayed);
}

TEST(Campaign, OversizedFileIsRefusedBeforeReading) {
  const fs::path dir =
      fs::temp_directory_path() / ("arena_campaign_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path big = dir / "big.json";
  {
    std::ofstream out(big, std::ios::binary);
    out.seekp(100 * 1000 * 1000 - 1);
    out.put('}');
  }
  try {
    LoadCampaignFile(big.string());
    ADD_FAILURE() << "accepted";
  } catch (const CampaignError& e) {
    EXPECT_EQ(e.field(), "");
    EXPECT_NE(std::string(e.what()).find("larger than the limit"), std::string::npos);
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace arena::orchestrator

namespace arena::orchestrator {
namespace {

// `doc` with `prediction` replaced is refused, naming `field`.
void ExpectPredictionRefused(const json& doc, const std::string& dir, const json& prediction,
                             const std::string& field) {
  json bad = doc;
  bad["prediction"] = prediction;
  try {
    ParseCampaign(bad.dump(), dir);
    ADD_FAILURE() << prediction.dump() << " was accepted";
  } catch (const CampaignError& e) {
    EXPECT_EQ(e.field(), field) << e.what();
  }
}

// The campaign's `prediction` may name its predictor (issue 14): arena's
// model or MuJoCo, each with its own knobs only.
TEST(Campaign, PredictionNamesAPredictor) {
  json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
  const std::string dir = (kSourceDir / "examples/campaigns").string();
  EXPECT_EQ(ParseCampaign(doc.dump(), dir).predictor, "arena");
  doc["prediction"] = {{"predictor", "mujoco"}, {"timestep", 0.001}, {"cone", "elliptic"}};
  const Campaign m = ParseCampaign(doc.dump(), dir);
  EXPECT_EQ(m.predictor, "mujoco");
  EXPECT_EQ(json::parse(m.predictor_settings_json)["timestep"], 0.001);
  auto refused = [&](const json& prediction, const std::string& field) {
    ExpectPredictionRefused(doc, dir, prediction, field);
  };
  refused({{"predictor", "bullet"}}, "prediction.predictor");
  refused({{"predictor", "mujoco"}, {"facets", 8}}, "prediction.facets");
  refused({{"timestep", 0.001}}, "prediction.timestep");  // arena has no timestep
  refused({{"predictor", "mujoco"}, {"timestep", 1.0}}, "prediction.timestep");
  refused({{"predictor", "mujoco"}, {"cone", "round"}}, "prediction.cone");
  // Contact softness is a MuJoCo knob too (checked by the simulator).
  doc["prediction"] = {{"predictor", "mujoco"}, {"solref", {0.005, 1}}};
  EXPECT_EQ(json::parse(ParseCampaign(doc.dump(), dir).predictor_settings_json)["solref"][0],
            0.005);
  refused({{"solref", {0.005, 1}}}, "prediction.solref");  // not an arena knob
  refused({{"predictor", "mujoco"}, {"solref", {0.005}}}, "prediction.solref");
  refused({{"predictor", "mujoco"}, {"solimp", {0.9, 0.95, 0.001, 0.5, 0.5}}}, "prediction.solimp");
}

// arena's model takes issue 31's choices in `prediction` (pads, cone,
// inertia); `cone` keeps its MuJoCo meaning for the MuJoCo predictor, and
// pads and inertia are not MuJoCo's. The smoke example predicts with the
// aligned cone: its trials start from measured, slightly tilted poses.
TEST(Campaign, PredictionTakesTheModelsChoices) {
  json doc = json::parse(ReadText(kSourceDir / "examples/campaigns/smoke.json"));
  const std::string dir = (kSourceDir / "examples/campaigns").string();
  EXPECT_EQ(ParseCampaign(doc.dump(), dir).prediction.cone, mechanics::ConeModel::kAligned);
  doc["prediction"] = {{"cone", "polyhedral"}, {"pads", "rigid"}, {"inertia", "quasi_static"}};
  const Campaign c = ParseCampaign(doc.dump(), dir);
  EXPECT_EQ(c.prediction.cone, mechanics::ConeModel::kPolyhedral);
  EXPECT_EQ(c.prediction.pads, mechanics::PadModel::kRigid);
  EXPECT_EQ(c.prediction.inertia, mechanics::InertiaModel::kQuasiStatic);
  auto refused = [&](const json& prediction, const std::string& field) {
    ExpectPredictionRefused(doc, dir, prediction, field);
  };
  refused({{"cone", "elliptic"}}, "prediction.cone");  // MuJoCo's value, not arena's
  refused({{"pads", "soft"}}, "prediction.pads");
  refused({{"inertia", 1}}, "prediction.inertia");
  refused({{"predictor", "mujoco"}, {"pads", "rigid"}}, "prediction.pads");
  refused({{"predictor", "mujoco"}, {"inertia", "auto"}}, "prediction.inertia");
  refused({{"predictor", "mujoco"}, {"cone", "aligned"}}, "prediction.cone");
}

// One table of variation units (issue 27, one home per idea): plots, the
// boundary report and the sensitivity table read a variation's unit from the
// campaign catalogue, and a person reads lengths in mm, speeds in mm/s.
TEST(VariationUnits, EveryNumericVariationHasItsSiUnitAndAHumanValue) {
  EXPECT_EQ(VariationUnit("grip_force"), "N");
  EXPECT_EQ(VariationUnit("push_speed"), "m/s");
  EXPECT_EQ(VariationUnit("pivot_offset"), "m");
  EXPECT_EQ(VariationUnit("object_size_x"), "m");
  EXPECT_EQ(VariationUnit("object_mass"), "kg");
  EXPECT_EQ(VariationUnit("finger_mu"), "1");
  EXPECT_EQ(VariationUnit("finger_type"), "");  // a contact type has none
  EXPECT_EQ(VariationUnit("no_such_variation"), std::nullopt);
  EXPECT_EQ(HumanVariationValue("push_speed", 0.02), "20 mm/s");
  EXPECT_EQ(HumanVariationValue("pivot_offset", 0.00813), "8.13 mm");
  EXPECT_EQ(HumanVariationValue("grip_force", 1.14), "1.14 N");
  EXPECT_EQ(HumanVariationValue("object_mass", 0.2), "0.2 kg");
  EXPECT_EQ(HumanVariationValue("finger_mu", 0.5), "0.5");
  EXPECT_EQ(HumanVariationValue("no_such_variation", 3.0), "3");
}

}  // namespace
}  // namespace arena::orchestrator
