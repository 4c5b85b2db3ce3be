// Campaigns: what to vary, how to sample it, how often to repeat it.
//
// A campaign is a base scene (docs/scene.md) plus a variation space. Each
// *condition* is one point of that space, i.e. one concrete scene; each
// condition is run `replicates` times with identical initial conditions (only
// the per-trial seed, which drives a cell's defects, differs). The format is
// described in orchestrator/README.md and schemas/campaign.schema.json.
//
// Usage (all plain structs and free functions; nothing here holds state):
//
//   Campaign c = LoadCampaignFile("examples/campaigns/smoke.json");  // throws CampaignError
//   for (int64_t i = next_index; i < TrialCount(c); ++i) {
//     PlannedTrial t = PlanTrial(c, i);    // a pure function of (c, i): resumable
//     ... store t.index, t.condition, t.replicate, t.seed, SceneToJson(t.scene) ...
//   }
//
// Thread safety: all functions are pure; a Campaign may be shared read-only.
#pragma once

#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "arena/errors/error.hpp"
#include "arena/mechanics/scene.hpp"
#include "arena/orchestrator/claim_chooser.hpp"

namespace arena::orchestrator {

inline constexpr std::size_t kMaxCampaignBytes = 1 << 20;  // 1 MiB of JSON
inline constexpr int64_t kMaxConditions = 1'000'000;
inline constexpr int kMaxReplicates = 1000;
inline constexpr int64_t kMaxTrials = 1'000'000;
inline constexpr int kMaxChoices = 1000;
inline constexpr int kMaxGridLevels = 1000;

// Invalid campaign: field() is the JSON path ("variations.grip_force.min";
// "scene.fingers[0].mu" inside the base scene; empty for the whole document),
// what() is "<field>: <reason>" ("campaign: <reason>" when field() is empty).
class CampaignError : public Error {
 public:
  CampaignError(std::string field, const std::string& reason);
  const std::string& field() const { return field_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string field_;
  std::string reason_;
};

enum class SamplerKind { kGrid, kUniform, kLatinHypercube, kSobol };
const char* ToString(SamplerKind kind);  // "grid", "uniform", "latin_hypercube", "sobol"

// What a variation's values are.
enum class ValueType {
  kNumber,       // a scalar in SI units
  kContactType,  // "point", "line" or "patch"
  kVector,       // a 3-vector in the gripper frame (a direction; normalised)
};

// One value of a variation; only the member matching its ValueType is used.
struct VariationValue {
  double number = std::numeric_limits<double>::quiet_NaN();
  mechanics::ContactType contact_type = mechanics::ContactType::kPoint;
  Eigen::Vector3d vector = Eigen::Vector3d::Zero();
};

// One axis of the variation space. Names and meanings: the table in
// orchestrator/README.md (kVariationCatalog in campaign.cpp), e.g.
// "grip_force", "finger_type", "pivot_offset".
struct Variation {
  enum class Kind { kFixed, kRange, kChoices };
  std::string name;
  ValueType type = ValueType::kNumber;
  Kind kind = Kind::kFixed;
  double min = 0, max = 0;  // kRange (SI units)
  bool log_scale = false;   // kRange: sample log(value) uniformly (min > 0)
  int levels = 0;           // kRange under the grid sampler: evenly spaced values incl. ends
  std::vector<VariationValue> choices;  // kChoices; kFixed holds its one value here

  // A sampled axis: a range with min < max, or two or more choices.
  bool IsSampled() const {
    return (kind == Kind::kRange && min < max) || (kind == Kind::kChoices && choices.size() > 1);
  }
};

// An adaptive sampler (campaign "sampler": {"adaptive": ...}; adaptive.hpp
// decides its trials round by round from the outcomes in the store).
enum class AdaptiveKind { kBoundary, kReplicates };
const char* ToString(AdaptiveKind kind);  // "boundary", "replicates"

// What a trial's outcome is, for the boundary sampler (outcome.hpp computes it).
enum class OutcomeKind {
  kPivoted,     // |net rotation| > threshold (rad)
  kFingerSlip,  // fraction of finger contact-samples sliding > threshold
  kGraspKept,   // every finger still touching at the end and displacement <= threshold (m)
};
const char* ToString(OutcomeKind kind);  // "pivoted", "finger_slip", "grasp_kept"

// What `arena submit` stores for an adaptive campaign that does not say
// (bench/README.md: pipelined rounds keep the cells busy, 99-100 % against 97 %
// on closed_loop.json with two simulated cells at wall-clock pace).
inline constexpr bool kPipelineDefault = true;

struct AdaptiveSpec {
  AdaptiveKind kind = AdaptiveKind::kBoundary;
  int batch = 0;  // trials per round after the first; 0: the idle cells at round 1 (then fixed)
  int max_trials = 0;  // cap on the campaign's trials (> 0)
  // Pipelined rounds (adaptive.hpp): round k+1 is decided from rounds <= k-1
  // with round k pending, so it is queued while round k runs. false: a round
  // is decided only when every earlier trial is finished (cells idle between).
  // A stored campaign without the key is synchronous (how it was submitted
  // before pipelining became the default); `arena submit` writes the key into
  // every adaptive campaign it stores, true unless the campaign says false
  // (kPipelineDefault), so a service upgrade never changes a running
  // campaign's sequence.
  bool pipeline = false;
  bool pipeline_given = false;  // the campaign JSON has the key
  // boundary
  OutcomeKind outcome = OutcomeKind::kPivoted;
  double threshold = std::numeric_limits<double>::quiet_NaN();  // the outcome's threshold
  double resolution = 0.05;  // wanted boundary accuracy, as a fraction of each range (0, 0.5]
  int coarse_levels = 0;     // first batch: a grid of this many levels per dimension
  // replicates
  int min_replicates = 3;
  int max_replicates = 20;
  double ci_position = 0.001;  // m: target half-width of the mean final position's CI
  double ci_angle = 0;         // rad: same for the final angle (0: not a target)
  double confidence = 0.95;    // of the CI, in (0, 1)
};

struct Campaign {
  std::string name;                   // [A-Za-z0-9_.-]{1,64}
  std::string description;            // free text, optional
  uint64_t seed = 0;                  // all sampling and per-trial seeds derive from it
  int priority = 0;                   // higher runs first; [-1000, 1000]
  mechanics::Scene scene;             // the base scene; the cells simulate with its model settings
  std::vector<Variation> variations;  // in canonical order (kVariationNames), only those given
  SamplerKind sampler = SamplerKind::kSobol;
  int64_t conditions = 1;              // distinct sampled scenes
  int replicates = 1;                  // trials per condition (same scene, different seed)
  mechanics::ModelOptions prediction;  // model settings the predictor uses
  std::string predictor = "arena";     // prediction.predictor: arena | mujoco
  std::string predictor_settings_json =
      "{}";  // mujoco's knobs (timestep, cone, noslip_iterations, solref, solimp)
  std::string defects_json = "{}";  // defect profile (a JSON object), passed to cells as is
  std::string defects_file;         // when given as a path (relative to the campaign file)
  std::string source_json;  // the campaign as given, scene/defects files inlined (compact JSON)
  // Set for an adaptive campaign. Boundary: conditions = 0 (points are chosen
  // as results come in; PlanTrialAt builds them). Replicates: conditions and
  // `sampler` are the base plan, replicates = min_replicates.
  std::optional<AdaptiveSpec> adaptive;
  // prediction.calibration: a stored calibration whose fitted parameters the
  // predictor applies (SubmitCampaign resolves it into calibrated_scales).
  std::int64_t calibration_id = 0;
  std::map<std::string, double> calibrated_scales;  // e.g. {"mu_fingers": 1.42}
  // A campaign of listed scenes ("scenes" instead of "scene" and
  // "variations", e.g. an imported dataset's scenes.jsonl): condition i runs
  // scenes[i] (`scene` is scenes[0]); a listed seed is its first replicate's.
  std::vector<mechanics::Scene> scenes;
  std::vector<std::optional<uint64_t>> scene_seeds;
  // "scheduling" (issue 29): change-aware claims within blocks of the plan
  // (claim_chooser.hpp); read by ReadScheduling.
  SchedulingOptions scheduling;
};

// The largest file of listed scenes a campaign may name (recorded pushes
// carry their pusher paths: tens of kB per scene).
inline constexpr std::size_t kMaxScenesFileBytes = std::size_t{64} << 20;

// One trial of a campaign's plan. Replicates of a condition have the same
// scene and parameters, bit for bit.
struct PlannedTrial {
  int64_t index = 0;      // position in the campaign's sequence, [0, TrialCount)
  int64_t condition = 0;  // index / replicates
  int replicate = 0;      // index % replicates
  uint64_t seed = 0;  // per-trial seed (defects, noise), from (campaign seed, condition, replicate)
  mechanics::Scene scene;  // what the cell runs (valid)
  std::string
      parameters_json;  // {"grip_force": 12.5, "finger_type": "line", ...}: the sampled values
};

// How much of the plan ParseCampaign checks. kAllConditions builds and
// validates every condition's scene (about 10 us each: 10 s for a million);
// kBaseScene checks only the base scene and prediction settings, for
// reloading a campaign that was validated when it was submitted.
enum class ConditionCheck { kAllConditions, kBaseScene };

// Parses and validates a campaign, by default including every condition's
// scene (a campaign that would produce one invalid scene is refused up front).
// "scene" and "defects" may be file paths, resolved against base_dir (the
// current directory when empty); source_json then holds their contents.
// @throws CampaignError naming the first offending field.
Campaign ParseCampaign(std::string_view json_text, const std::string& base_dir = "",
                       ConditionCheck check = ConditionCheck::kAllConditions);

// The "scheduling" block of a campaign document (the whole campaign JSON
// text; defaults when it has none): {"change_aware": bool, "window": 1..256}.
// ParseCampaign calls it; the service reads a stored campaign's with it.
// @throws CampaignError naming scheduling.<field>.
SchedulingOptions ReadScheduling(std::string_view campaign_json);

// Reads a campaign file (at most kMaxCampaignBytes); file paths inside it are
// relative to the campaign file. @throws CampaignError.
Campaign LoadCampaignFile(const std::string& path);

// Values legal but implausible for the scene's scale, in the units a person
// types: a push longer than 10 object sizes, a pusher speed above the cells'
// limit (defects.max_pusher_speed, default 0.5 m/s), a push shorter than one
// model step, a grip above 250 times the object's weight. ParseCampaign calls
// it before validating scenes. @throws CampaignError naming the field written
// and the likely unit slip (plausibility.cpp).
void CheckPlausibility(const Campaign& campaign);

int64_t TrialCount(const Campaign& campaign);  // conditions * replicates

// The index-th trial. Pure: depends only on (campaign, index), so a resumed
// campaign continues the same sequence from a stored index.
// @pre 0 <= index < TrialCount(campaign), else std::out_of_range.
PlannedTrial PlanTrial(const Campaign& campaign, int64_t index);

// The SI unit of a catalogue variation's values ("m", "m/s", "N", "kg", "1"
// when dimensionless, "unit vector, gripper frame" for a direction); "" for a
// contact type or a controller setting (the controller's own units);
// std::nullopt for a name the catalogue does not have. The one table of
// variation units: plots, reports and sensitivity read it from here.
std::optional<std::string_view> VariationUnit(std::string_view name);

// A variation's value as a person reads it, 3 significant digits in the
// human unit of its SI value's unit (assessment::HumanUnitOf): "12 mm", "20 mm/s",
// "1.5 N", "0.2 kg"; a dimensionless or unknown one bare ("0.5").
std::string HumanVariationValue(std::string_view name, double value);

// The sampled variations' names, in campaign.variations order (the unit
// point's dimensions).
std::vector<std::string> SampledVariations(const Campaign& campaign);

// A trial at an arbitrary point u of the unit hypercube (one coordinate in
// [0, 1] per sampled variation, ranges only), for adaptive samplers. Its seed
// follows (campaign seed, condition, replicate) as PlanTrial's does.
// @throws std::invalid_argument for a wrong dimension or a coordinate outside [0, 1].
PlannedTrial PlanTrialAt(const Campaign& campaign, const std::vector<double>& u, int64_t index,
                         int64_t condition, int replicate);

// Replicate `replicate` of condition `condition` of the base plan (any
// replicate count), for the replicates sampler. @pre 0 <= condition < conditions.
PlannedTrial PlanReplicate(const Campaign& campaign, int64_t condition, int replicate,
                           int64_t index);

// The condition's point in the unit hypercube, one coordinate in [0, 1) per
// sampled variation (in campaign.variations order). Grid: level / levels.
std::vector<double> ConditionPoint(const Campaign& campaign, int64_t condition);

// The scene the predictor runs for a trial: its scene with the campaign's
// prediction model settings.
mechanics::Scene PredictionScene(const Campaign& campaign, const PlannedTrial& trial);

}  // namespace arena::orchestrator
