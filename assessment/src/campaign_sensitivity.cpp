#include "arena/assessment/campaign_sensitivity.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "arena/mechanics/scene_json.hpp"

namespace arena::assessment {
namespace {

using nlohmann::json;

struct Condition {
  int index = 0;
  std::string params_json = "{}";
  std::string defects_json = "{}";  // the campaign's profile (used when no trial ran)
  // The profiles the replicates really ran under (the cells'), one per
  // replicate with ground truth; ensemble member k draws from profile k mod n.
  std::vector<std::string> profiles;
  mechanics::Scene scene;                                 // the prediction scene
  std::vector<Eigen::Vector3d> displacements, rotations;  // observed, one per replicate
};

Eigen::Vector3d RotationVector(const Eigen::Quaterniond& from, const Eigen::Quaterniond& to) {
  Eigen::AngleAxisd turn(to * from.inverse());
  double angle = turn.angle();
  Eigen::Vector3d axis = turn.axis();
  if (angle > M_PI) {
    angle = 2 * M_PI - angle;
    axis = -axis;
  }
  return angle * axis;
}

Eigen::Quaterniond Quat(const std::array<double, 7>& pose) {
  return Eigen::Quaterniond(pose[3], pose[4], pose[5], pose[6]).normalized();
}

// The campaign's "prediction" settings over the trial's scene (what the
// service predicts with).
mechanics::Scene PredictionScene(const std::string& scene_json, const json& prediction) {
  mechanics::Scene s = mechanics::ParseScene(scene_json);
  if (prediction.is_object()) {
    if (auto it = prediction.find("facets"); it != prediction.end() && it->is_number_integer())
      s.model.facets = it->get<int>();
    if (auto it = prediction.find("points"); it != prediction.end() && it->is_number_integer())
      s.model.points = it->get<int>();
    if (auto it = prediction.find("dt"); it != prediction.end() && it->is_number())
      s.model.dt = it->get<double>();
    if (auto it = prediction.find("reduce"); it != prediction.end() && it->is_string()) {
      if (auto r = mechanics::ReduceFromString(it->get<std::string>())) s.model.reduce = *r;
    }
  }
  mechanics::ValidateScene(s);
  return s;
}

// The parameters probed for stability: those the cell's noise covers, those
// given a tolerance by name, and the --params ones (all of them when a
// relative tolerance is set without --params).
std::vector<std::string> StabilityFilters(const mechanics::Scene& scene,
                                          const CampaignSensitivityOptions& o,
                                          const StabilityOptions& st) {
  std::vector<std::string> out;
  const auto all = SceneParameters(scene);
  const auto chosen = SelectParameters(all, o.params);  // all when no filters
  for (const auto& p : all) {
    if (!(ToleranceFor(p, st).first > 0)) continue;
    const bool noise =
        (p.kind == ParameterKind::kMuScale && st.noise.mu_scale_std > 0) ||
        (p.kind == ParameterKind::kPushSpeed && st.noise.velocity_scale_std > 0) ||
        (p.kind == ParameterKind::kPusherVelocity && st.noise.velocity_offset_std[p.axis] > 0);
    const bool by_filter = (!o.params.empty() || st.relative_tolerance > 0) &&
                           std::any_of(chosen.begin(), chosen.end(),
                                       [&](const Parameter& c) { return c.name == p.name; });
    if (noise || st.tolerances.count(p.name) || by_filter) out.push_back(p.name);
  }
  return out;
}

// The replicates' observed spread and mean displacement and rotation.
void NoteObserved(const Condition& c, db::SensitivityCondition* row) {
  row->replicates = static_cast<int>(c.displacements.size());
  row->observed_position_spread = Spread(c.displacements);
  row->observed_rotation_spread = Spread(c.rotations);
  if (!c.displacements.empty()) {
    double d = 0, r = 0;
    for (const auto& v : c.displacements) d += v.norm();
    for (const auto& v : c.rotations) r += v.norm();
    row->observed_displacement = d / static_cast<double>(c.displacements.size());
    row->observed_rotation = r / static_cast<double>(c.rotations.size());
  }
}

// The noise the ensemble draws from: the profiles the replicates ran under,
// or the campaign's when no trial ran; member k draws from entry k mod n.
struct ConditionNoise {
  std::vector<ActuationNoise> actuation;
  std::vector<StartPoseNoise> start_pose;
  bool from_cells = false;
};

ConditionNoise NoiseOf(const Condition& c, const CampaignSensitivityOptions& o) {
  ConditionNoise n;
  for (const auto& p : c.profiles) {
    n.actuation.push_back(ParseActuationNoise(p));
    n.start_pose.push_back(ParseStartPoseNoise(p));
  }
  n.from_cells = !n.actuation.empty();
  if (!n.from_cells) {
    n.actuation.push_back(ParseActuationNoise(c.defects_json));
    n.start_pose.push_back(ParseStartPoseNoise(c.defects_json));
  }
  if (!o.draw_start_pose) {
    for (auto& st : n.start_pose) st.emulated = false;
  }
  return n;
}

// The stored detail's account of the noise (the first profile's).
json NoiseDetail(const Condition& c, const ConditionNoise& n) {
  const bool from_cells = n.from_cells;
  const ActuationNoise& noise = n.actuation.front();
  const StartPoseNoise& start = n.start_pose.front();
  json detail = {
      {"noise_source",
       from_cells ? "the profiles the trials ran under" : "the campaign's profile (no trial ran)"},
      {"distinct_profiles", std::set<std::string>(c.profiles.begin(), c.profiles.end()).size()},
      {"noise",
       {{"mu_scale_std", noise.mu_scale_std},
        {"velocity_scale_std", noise.velocity_scale_std},
        {"velocity_offset_std",
         {noise.velocity_offset_std.x(), noise.velocity_offset_std.y(),
          noise.velocity_offset_std.z()}}}},
      {"start_pose",
       {{"drawn", start.any()},
        {"placement_position_std", start.position_std},
        {"placement_angle_std", start.angle_std},
        {"sensing_position_std", start.sensing_position_std},
        {"sensing_angle_std", start.sensing_angle_std},
        {"position_tolerance", start.position_tolerance},
        {"angle_tolerance", start.angle_tolerance},
        {"max_attempts", start.max_attempts}}}};
  return detail;
}

// The ensemble: the cell's draws, from a stream of our own per condition;
// the predicted spread, the flips of the nominal's discrete outcome and the
// verdicts against the observed spread.
void RunEnsemble(const Condition& c, const CampaignSensitivityOptions& o,
                 const SimulateFn& simulate, const ConditionNoise& n, const Outcome& nominal,
                 db::SensitivityCondition* row, json* detail, long* runs) {
  std::seed_seq seq{static_cast<std::uint32_t>(o.seed), static_cast<std::uint32_t>(o.seed >> 32),
                    static_cast<std::uint32_t>(c.index), 0x5e57u};
  std::mt19937_64 rng(seq);
  std::vector<Eigen::Vector3d> disp, rot;
  int flips = 0;
  for (int k = 0; k < o.ensemble; ++k) {
    const size_t from = static_cast<size_t>(k) % n.actuation.size();
    // The start pose the reset leaves, then the trial's own draws (as the cell).
    const StartPoseDraw start_draw = DrawStartPose(n.start_pose[from], &rng);
    const NoiseDraw noise_draw = DrawNoise(n.actuation[from], &rng);
    mechanics::Scene s = c.scene;
    mechanics::SimulationResult r;
    try {
      s = ApplyNoise(ApplyStartPose(c.scene, start_draw), noise_draw);
      mechanics::ValidateScene(s);
      r = simulate(s);
    } catch (const mechanics::SceneError& e) {
      r.status = mechanics::SimulationStatus::kInvalidScene;
      r.error = e.what();
    }
    ++*runs;
    const Outcome out = MeasureOutcome(s, r);
    if (!out.ok) {
      ++row->ensemble_failed;
      continue;
    }
    ++row->ensemble;
    disp.push_back(r.samples.back().position - r.samples.front().position);
    rot.push_back(out.rotation_vector);
    if (!SameDiscreteOutcome(nominal, out)) ++flips;
  }
  row->flip_fraction = row->ensemble > 0 ? static_cast<double>(flips) / row->ensemble : 0.0;
  row->predicted_position_spread = Spread(disp);
  row->predicted_rotation_spread = Spread(rot);
  const std::string vp =
      SpreadVerdict(row->observed_position_spread, row->predicted_position_spread, row->replicates,
                    o.position_floor);
  const std::string vr =
      SpreadVerdict(row->observed_rotation_spread, row->predicted_rotation_spread, row->replicates,
                    o.rotation_floor);
  row->verdict = vp == "matches" ? vr : vp;
  (*detail)["position_verdict"] = vp;
  (*detail)["rotation_verdict"] = vr;
}

// The stability probes of the nominal scene under the condition's noise.
void ProbeStability(const Condition& c, const CampaignSensitivityOptions& o,
                    const SimulateFn& simulate, const ActuationNoise& noise,
                    db::SensitivityCondition* row, json* detail, long* runs) {
  SensitivityOptions so;
  so.stability = o.stability;
  so.stability.noise = noise;
  so.params = StabilityFilters(c.scene, o, so.stability);
  so.threads = 1;
  so.simulate = simulate;
  if (so.params.empty()) {
    (*detail)["stability"] =
        "no parameter has a tolerance (the profile has no actuation or "
        "friction noise and no --tolerance was given)";
    return;
  }
  const SensitivityReport rep = AnalyseScene(c.scene, so);
  *runs += rep.model_runs;
  const Stability& st = rep.stability;
  row->unstable = st.unstable;
  if (!st.reasons.empty()) row->reason = st.reasons.front();
  if (st.nearest) {
    row->boundary_parameter = st.nearest->parameter;
    row->boundary_offset = st.nearest->offset;
    row->boundary_tolerances = st.nearest->tolerances;
  }
  (*detail)["stability"] = ToJson(rep, c.scene)["stability"];
}

db::SensitivityCondition AnalyseCondition(const Condition& c, const CampaignSensitivityOptions& o,
                                          const SimulateFn& simulate, long* runs) {
  db::SensitivityCondition row;
  row.condition = c.index;
  row.params_json = c.params_json;
  NoteObserved(c, &row);
  const ConditionNoise noise = NoiseOf(c, o);
  json detail = NoiseDetail(c, noise);

  const Outcome nominal = MeasureOutcome(c.scene, simulate(c.scene));
  ++*runs;
  if (!nominal.ok) {
    row.verdict = "no_prediction";
    row.reason = "the model fails on the nominal scene: " + nominal.error;
    detail["error"] = nominal.error;
    row.detail_json = detail.dump();
    return row;
  }
  row.predicted_displacement = nominal.value(Quantity::kDisplacement);
  row.predicted_rotation = nominal.value(Quantity::kRotation);
  RunEnsemble(c, o, simulate, noise, nominal, &row, &detail, runs);
  if (o.check_stability)
    ProbeStability(c, o, simulate, noise.actuation.front(), &row, &detail, runs);
  row.detail_json = detail.dump();
  return row;
}

void Pool(const std::vector<db::SensitivityCondition>& rows, bool position,
          std::optional<double>* ratio, std::string* verdict, double floor) {
  double sum = 0;
  int dof = 0;
  for (const auto& r : rows) {
    const auto& obs = position ? r.observed_position_spread : r.observed_rotation_spread;
    const auto& pred = position ? r.predicted_position_spread : r.predicted_rotation_spread;
    if (!obs || !pred || *pred <= floor || r.replicates < 2) continue;
    const double q = *obs / *pred;
    sum += (r.replicates - 1) * q * q;
    dof += r.replicates - 1;
  }
  if (dof == 0) {
    *verdict = "too_few_replicates";
    return;
  }
  *ratio = std::sqrt(sum / dof);
  const auto [lo, hi] = ChiSquare95(dof);
  *verdict = sum < lo ? "model_overestimates" : sum > hi ? "model_underestimates" : "matches";
}

}  // namespace

std::pair<double, double> ChiSquare95(int dof) {
  static const double kLo[] = {0.000982, 0.0506, 0.216, 0.484, 0.831,
                               1.237,    1.690,  2.180, 2.700, 3.247};
  static const double kHi[] = {5.024,  7.378,  9.348,  11.143, 12.833,
                               14.449, 16.013, 17.535, 19.023, 20.483};
  if (dof < 1) throw std::invalid_argument("ChiSquare95: dof must be >= 1");
  if (dof <= 10) return {kLo[dof - 1], kHi[dof - 1]};
  // Wilson-Hilferty: chi^2_p(k) ~ k (1 - 2/(9k) + z_p sqrt(2/(9k)))^3.
  const double k = dof, a = 2.0 / (9.0 * k);
  auto q = [&](double z) { return k * std::pow(1 - a + z * std::sqrt(a), 3); };
  return {q(-1.959964), q(1.959964)};
}

std::optional<double> Spread(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 2) return std::nullopt;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  double ss = 0;
  for (const auto& p : points) ss += (p - mean).squaredNorm();
  return std::sqrt(ss / static_cast<double>(points.size() - 1));
}

std::string SpreadVerdict(std::optional<double> observed, std::optional<double> predicted,
                          int replicates, double floor) {
  if (replicates < 2 || !observed) return "too_few_replicates";
  if (!predicted) return "no_prediction";
  if (*predicted <= floor) return *observed <= floor ? "matches" : "model_underestimates";
  const int dof = replicates - 1;
  const auto [lo, hi] = ChiSquare95(dof);
  const double stat = dof * (*observed / *predicted) * (*observed / *predicted);
  if (stat < lo) return "model_overestimates";
  if (stat > hi) return "model_underestimates";
  return "matches";
}

CampaignSensitivityReport AnalyseCampaign(const db::Store& store, std::int64_t campaign_id,
                                          const CampaignSensitivityOptions& o) {
  if (o.ensemble < 2 || o.ensemble > 10000) {
    throw std::invalid_argument("--ensemble: must be in [2, 10000], got " +
                                std::to_string(o.ensemble));
  }
  const auto start = std::chrono::steady_clock::now();
  const db::Campaign campaign = store.GetCampaign(campaign_id);
  json prediction;
  try {
    const json spec = json::parse(campaign.spec_json);
    if (spec.is_object() && spec.contains("prediction")) prediction = spec["prediction"];
  } catch (const json::exception&) {
    // A spec that is not JSON predicts with each scene's own model settings.
  }
  const auto cell_profiles = db::AppliedDefectProfiles(store, campaign_id);
  std::map<int, Condition> by_condition;
  for (const db::Trial& t : store.ListTrials(campaign_id)) {
    auto [it, fresh] = by_condition.try_emplace(t.condition);
    Condition& c = it->second;
    if (fresh) {
      c.index = t.condition;
      c.params_json = t.params_json.empty() ? "{}" : t.params_json;
      c.defects_json = t.defects_json.empty() ? "{}" : t.defects_json;
      json model = prediction.is_object() ? prediction : json::object();
      if (o.facets > 0) model["facets"] = o.facets;
      if (o.points > 0) model["points"] = o.points;
      if (o.dt > 0) model["dt"] = o.dt;
      c.scene = PredictionScene(t.scene_json, model);
    }
    if (!t.gt_stream_id) continue;
    if (auto p = cell_profiles.find(t.id); p != cell_profiles.end()) {
      c.profiles.push_back(p->second.empty() ? "{}" : p->second);
    }
    const db::GroundTruth gt = store.ReadGroundTruth(t.id);
    if (gt.samples.size() < 2) continue;
    const auto& a = gt.samples.front().object_pose;
    const auto& b = gt.samples.back().object_pose;
    c.displacements.emplace_back(b[0] - a[0], b[1] - a[1], b[2] - a[2]);
    c.rotations.push_back(RotationVector(Quat(a), Quat(b)));
  }
  std::vector<const Condition*> list;
  for (const auto& [k, c] : by_condition) list.push_back(&c);
  // A tolerance for a parameter no condition has would be stored as if it
  // had been applied (the scene view refuses it the same way).
  for (const auto& [name, t] : o.stability.tolerances) {
    const bool known = std::any_of(list.begin(), list.end(), [&](const Condition* c) {
      const auto all = SceneParameters(c->scene);
      return std::any_of(all.begin(), all.end(),
                         [&](const Parameter& p) { return p.name == name; });
    });
    if (!known)
      throw std::invalid_argument("--tolerance " + name +
                                  ": no such parameter in this campaign's scenes (see `arena "
                                  "sensitivity SCENE.json` for the names)");
  }

  CampaignSensitivityReport report;
  report.campaign_id = campaign_id;
  report.threads = ThreadCount(o.threads);
  const SimulateFn simulate = o.simulate ? o.simulate : DefaultSimulate();
  std::vector<std::optional<db::SensitivityCondition>> rows(list.size());
  std::atomic<long> runs{0}, done{0};
  std::mutex progress_mutex;
  RunParallel(static_cast<long>(list.size()), report.threads, [&](long i) {
    if (o.cancel && o.cancel->load()) return;
    long local = 0;
    rows[static_cast<size_t>(i)] =
        AnalyseCondition(*list[static_cast<size_t>(i)], o, simulate, &local);
    runs += local;
    const long d = ++done;
    if (o.progress) {
      std::lock_guard<std::mutex> lock(progress_mutex);
      o.progress(d, static_cast<long>(list.size()));
    }
  });
  report.cancelled = o.cancel && o.cancel->load();
  for (auto& r : rows) {
    if (!r) continue;
    const std::string& v = r->verdict;
    report.matches += v == "matches";
    report.underestimates += v == "model_underestimates";
    report.overestimates += v == "model_overestimates";
    report.too_few += v == "too_few_replicates";
    report.no_prediction += v == "no_prediction";
    report.unstable += r->unstable;
    report.conditions.push_back(std::move(*r));
  }
  Pool(report.conditions, true, &report.pooled_position_ratio, &report.pooled_position_verdict,
       o.position_floor);
  Pool(report.conditions, false, &report.pooled_rotation_ratio, &report.pooled_rotation_verdict,
       o.rotation_floor);
  report.model_runs = runs;
  report.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

json SettingsJson(const CampaignSensitivityOptions& o) {
  json tol = json::object();
  for (const auto& [k, v] : o.stability.tolerances) tol[k] = v;
  return {{"ensemble", o.ensemble},
          {"seed", std::to_string(o.seed)},
          {"simulator", o.simulator_name},
          {"model_override", {{"facets", o.facets}, {"points", o.points}, {"dt", o.dt}}},
          {"check_stability", o.check_stability},
          {"draw_start_pose", o.draw_start_pose},
          {"noise_sigmas", o.stability.noise_sigmas},
          {"relative_tolerance", o.stability.relative_tolerance},
          {"tolerances", tol},
          {"linear_multiple", o.stability.linear_multiple},
          {"params", o.params}};
}

json SummaryJson(const CampaignSensitivityReport& r) {
  json unstable = json::array();
  for (const auto& c : r.conditions) {
    if (c.unstable) unstable.push_back(c.condition);
  }
  auto opt = [](const std::optional<double>& v) { return v ? json(*v) : json(nullptr); };
  return {{"campaign_id", r.campaign_id},
          {"conditions", r.conditions.size()},
          {"verdicts",
           {{"matches", r.matches},
            {"model_underestimates", r.underestimates},
            {"model_overestimates", r.overestimates},
            {"too_few_replicates", r.too_few},
            {"no_prediction", r.no_prediction}}},
          {"pooled_position_ratio", opt(r.pooled_position_ratio)},
          {"pooled_position_verdict", r.pooled_position_verdict},
          {"pooled_rotation_ratio", opt(r.pooled_rotation_ratio)},
          {"pooled_rotation_verdict", r.pooled_rotation_verdict},
          {"unstable_conditions", unstable},
          {"model_runs", r.model_runs},
          {"wall_s", r.wall_s},
          {"threads", r.threads}};
}

}  // namespace arena::assessment
