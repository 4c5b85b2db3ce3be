// Adaptive campaigns against the store: read the finished round's outcomes,
// decide the next round with the pure rules (adaptive_rules.cpp), write it
// in one transaction. Design and guarantees: adaptive.hpp.
#include "arena/orchestrator/adaptive.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <stdexcept>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "arena/mechanics/scene_json.hpp"
#include "arena/orchestrator/outcome.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/orchestrator/submit.hpp"

namespace arena::orchestrator {
namespace {

using nlohmann::json;

std::string Fixed(double v, int digits = 3) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

std::string JoinNames(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : " x ") + n;
  return out;
}

db::PlannedTrial ToStoreTrial(const Campaign& c, const PlannedTrial& t) {
  db::PlannedTrial p;
  p.condition = static_cast<int>(t.condition);
  p.replicate = t.replicate;
  p.seed = t.seed;
  p.scene_json = mechanics::SceneToJson(t.scene);
  p.facts = SceneFactsOf(t.scene);
  p.params_json = t.parameters_json;
  p.defects_json = c.defects_json;
  return p;
}

// What a decision is based on: the outcomes of rounds 0 .. known_through
// (every trial of them finished) and, pipelined, the points of round
// `pending` (planned, outcome unknown: used as if asked, never as evidence).
struct Basis {
  int known_through = -1;
  int pending = -1;  // -1: none
};

// Everything a decision needs from the store, in trial order.
struct Finished {
  std::vector<db::Trial> trials;                    // all of the campaign's
  std::map<std::int64_t, json> basis;               // trial id -> its decision's basis
  std::map<std::int64_t, int> round_of;             // trial id -> the round that planned it
  std::map<std::int64_t, db::TrialOutcome> stored;  // outcomes the ingest stored (issue 15)
  Basis on;

  int RoundOf(const db::Trial& t) const {
    const auto it = round_of.find(t.id);
    return it == round_of.end() ? 0 : it->second;
  }
  bool Known(const db::Trial& t) const { return RoundOf(t) <= on.known_through; }
  bool Pending(const db::Trial& t) const { return on.pending >= 0 && RoundOf(t) == on.pending; }
  // Every trial of rounds <= known_through is finished.
  bool KnownFinished(int known_through) const {
    for (const auto& t : trials)
      if (RoundOf(t) <= known_through && !db::IsTerminal(t.state)) return false;
    return true;
  }
  std::vector<std::int64_t> PendingIds() const {
    std::vector<std::int64_t> ids;
    for (const auto& t : trials)
      if (Pending(t)) ids.push_back(t.id);
    return ids;
  }
};

// The campaign's trials and decisions; outcomes are read once a basis is
// known to be finished (DecideRound).
Finished ReadTrials(db::Store& store, std::int64_t campaign_id) {
  Finished f;
  f.trials = store.ListTrials(campaign_id);
  for (const auto& d : store.ListDecisions(campaign_id)) {
    if (!d.trial_id) continue;
    f.basis[*d.trial_id] = json::parse(d.basis_json);
    f.round_of[*d.trial_id] = d.round;
  }
  return f;
}

// The basis in words, appended to every reason ("from rounds 0-3; round 4's
// 2 trials pending").
std::string BasisText(const Finished& f) {
  std::string text = f.on.known_through <= 0
                         ? "from round 0"
                         : "from rounds 0-" + std::to_string(f.on.known_through);
  if (f.on.pending >= 0) {
    const std::size_t n = f.PendingIds().size();
    text += "; round " + std::to_string(f.on.pending) + "'s " + std::to_string(n) +
            (n == 1 ? " trial" : " trials") + " pending";
  }
  return text;
}

// The basis as JSON, stored with every decision and in the sampler state.
json BasisJson(const Finished& f) {
  json b{{"known_through_round", f.on.known_through}};
  if (f.on.pending >= 0) {
    b["pending_round"] = f.on.pending;
    b["pending_trials"] = f.PendingIds();
  } else {
    b["pending_round"] = nullptr;
  }
  return b;
}

TrialOutcome OutcomeOf(db::Store& store, const db::Trial& t) {
  const mechanics::Scene scene = mechanics::ParseScene(t.scene_json);
  return ComputeOutcome(store.ReadGroundTruth(t.id).samples,
                        static_cast<int>(scene.fingers.size()));
}

// The boundary's class for a done trial. pivoted and finger_slip come from
// the per-contact outcomes the store computed at ingest (contact_outcomes,
// gt_summary: the numbers `arena query` and the exports show, with each
// contact's role taken from the scene rather than its position in the
// sample), so the sampler and the user read the same outcome; a trial
// without them is derived from its stream. grasp_kept keeps the stream
// (its rule looks at the last 10 % of samples, the store's at the last one).
bool ClassOf(db::Store& store, const Finished& f, const AdaptiveSpec& a, const db::Trial& t) {
  if (const auto it = f.stored.find(t.id);
      it != f.stored.end() && a.outcome != OutcomeKind::kGraspKept) {
    if (const auto o = FromStoredOutcome(it->second)) return Classify(a.outcome, a.threshold, *o);
  }
  return Classify(a.outcome, a.threshold, OutcomeOf(store, t));
}

// ------------------------------------------------------------ boundary

void DecideBoundary(db::Store& store, const Campaign& c, const Finished& f, int round, int batch,
                    db::AdaptiveRound* out, json* state) {
  const AdaptiveSpec& a = *c.adaptive;
  const auto names = SampledVariations(c);
  const int dims = static_cast<int>(names.size());
  const int levels =
      a.coarse_levels > 0 ? a.coarse_levels : DefaultCoarseLevels(dims, a.resolution);
  (*state)["refining"] = std::string(ToString(a.outcome)) + " boundary in " + JoinNames(names);
  (*state)["resolution"] = a.resolution;
  auto add = [&](const std::vector<double>& u, const std::string& reason, json basis) {
    const auto index = static_cast<std::int64_t>(f.trials.size() + out->trials.size());
    out->trials.push_back(ToStoreTrial(c, PlanTrialAt(c, u, index, index, 0)));
    basis["u"] = u;
    out->reasons.push_back(reason);
    out->bases_json.push_back(basis.dump());
  };

  if (round == 0) {
    const auto grid = CoarseGrid(dims, levels);
    for (size_t i = 0; i < grid.size() && static_cast<int>(i) < a.max_trials; ++i) {
      add(grid[i],
          "coarse grid point " + std::to_string(i + 1) + " of " + std::to_string(grid.size()) +
              " (" + std::to_string(levels) + " levels per dimension)",
          json{{"rule", "coarse_grid"}, {"levels", levels}});
    }
    (*state)["uncertainty"] = nullptr;
    return;
  }

  std::vector<LabelledPoint> labelled;
  std::vector<std::vector<double>> excluded;
  json seen = json::array();
  int positives = 0;
  int pending = 0;
  for (const auto& t : f.trials) {
    const auto it = f.basis.find(t.id);
    if (it == f.basis.end() || !it->second.contains("u")) continue;
    const auto u = it->second["u"].get<std::vector<double>>();
    if (f.Pending(t)) {
      excluded.push_back(u);  // asked already: neither asked again nor evidence yet
      ++pending;
      continue;
    }
    if (!f.Known(t)) continue;
    if (t.state != db::TrialState::kDone) {
      excluded.push_back(u);  // failed or cancelled: do not ask again
      continue;
    }
    const bool positive = ClassOf(store, f, a, t);
    positives += positive;
    labelled.push_back({u, positive, t.id});
    seen.push_back({t.id, ClassName(a.outcome, positive)});
  }
  (*state)["labelled"] = labelled.size();
  (*state)["positives"] = positives;
  (*state)["pending"] = pending;
  const int room = a.max_trials - static_cast<int>(f.trials.size());
  double uncertainty = 0;
  const auto proposals = ProposeBoundaryPoints(labelled, excluded, dims, a.resolution,
                                               std::min(batch, std::max(room, 0)), &uncertainty);
  (*state)["uncertainty"] = uncertainty;
  std::map<std::int64_t, bool> class_of;
  for (const auto& p : labelled) class_of[p.trial_id] = p.positive;
  for (const auto& p : proposals) {
    const std::string reason = "on the estimated boundary between trial " +
                               std::to_string(p.near_positive) + " (" + ClassName(a.outcome, true) +
                               ") and trial " + std::to_string(p.near_negative) + " (" +
                               ClassName(a.outcome, false) + "), " + Fixed(p.uncertainty) +
                               " from the nearest evidence (" + "resolution " +
                               Fixed(a.resolution) + "; " + BasisText(f) + ")";
    json basis{{"rule", "nn_margin"},
               {"uncertainty", p.uncertainty},
               {"nearest",
                {{ClassName(a.outcome, true), p.near_positive},
                 {ClassName(a.outcome, false), p.near_negative}}},
               {"seen", labelled.size()},
               {"positives", positives}};
    basis.update(BasisJson(f));
    add(p.u, reason, basis);
  }
  if (!proposals.empty()) return;
  out->open = false;
  if (positives == 0 || positives == static_cast<int>(labelled.size())) {
    out->stop_reason = "no class change: all " + std::to_string(labelled.size()) +
                       " finished points are '" + ClassName(a.outcome, positives > 0) + "'";
  } else if (room <= 0) {
    out->stop_reason = "max_trials reached (" + std::to_string(a.max_trials) +
                       "); boundary uncertainty " + Fixed(uncertainty) + " > resolution " +
                       Fixed(a.resolution);
  } else {
    out->stop_reason = "resolved: every point of the estimated boundary is within " +
                       Fixed(uncertainty) + " (<= resolution " + Fixed(a.resolution) +
                       ") of a sample of each class";
  }
}

// ------------------------------------------------------------ replicates

void DecideReplicates(db::Store& store, const Campaign& c, const Finished& f, int round, int batch,
                      db::AdaptiveRound* out, json* state) {
  const AdaptiveSpec& a = *c.adaptive;
  (*state)["refining"] =
      "replicates until the " + Fixed(a.confidence * 100, 0) +
      " % CI of the mean final position is <= " + Fixed(a.ci_position * 1e3, 2) + " mm" +
      (a.ci_angle > 0 ? " and of the angle <= " + Fixed(a.ci_angle, 4) + " rad" : std::string());
  auto add = [&](std::int64_t condition, int replicate, const std::string& reason, json basis) {
    const auto index = static_cast<std::int64_t>(f.trials.size() + out->trials.size());
    out->trials.push_back(ToStoreTrial(c, PlanReplicate(c, condition, replicate, index)));
    basis["condition"] = condition;
    basis["replicate"] = replicate;
    out->reasons.push_back(reason);
    out->bases_json.push_back(basis.dump());
  };
  if (round == 0) {
    const std::int64_t total =
        std::min<std::int64_t>(c.conditions * a.min_replicates, a.max_trials);
    for (std::int64_t i = 0; i < total; ++i) {
      add(i / a.min_replicates, static_cast<int>(i % a.min_replicates),
          "initial replicate " + std::to_string(i % a.min_replicates + 1) + " of " +
              std::to_string(a.min_replicates) + " (min_replicates)",
          json{{"rule", "initial"}});
    }
    (*state)["conditions"] = c.conditions;
    (*state)["on_target"] = 0;
    return;
  }
  std::vector<ConditionOutcomes> conditions(static_cast<size_t>(c.conditions));
  for (std::int64_t i = 0; i < c.conditions; ++i) conditions[static_cast<size_t>(i)].condition = i;
  for (const auto& t : f.trials) {
    auto& co = conditions.at(static_cast<size_t>(t.condition));
    ++co.planned;
    if (f.Pending(t)) ++co.pending;
    if (!f.Known(t) || t.state != db::TrialState::kDone) continue;
    const TrialOutcome o = OutcomeOf(store, t);
    co.final_position.push_back(o.final_position);
    co.final_angle.push_back(o.rotation);
  }
  const int room = a.max_trials - static_cast<int>(f.trials.size());
  const auto proposals = ProposeReplicates(conditions, a, std::min(batch, std::max(room, 0)));
  int on_target = 0;
  double widest = 0;
  for (const auto& co : conditions) {
    const double w = PositionHalfWidth(co, a.confidence);
    const bool angle_ok =
        a.ci_angle <= 0 || ConfidenceHalfWidth(co.final_angle, a.confidence) <= a.ci_angle;
    on_target += w <= a.ci_position && angle_ok;
    if (std::isfinite(w)) widest = std::max(widest, w);
  }
  (*state)["conditions"] = c.conditions;
  (*state)["on_target"] = on_target;
  (*state)["widest_ci_position"] = widest;
  for (const auto& p : proposals) {
    const auto& co = conditions[static_cast<size_t>(p.condition)];
    const std::string reason =
        "condition " + std::to_string(p.condition) + ": " + Fixed(a.confidence * 100, 0) +
        " % CI of the mean final position +-" + Fixed(p.ci_position * 1e3, 3) + " mm (target " +
        Fixed(a.ci_position * 1e3, 3) + " mm) after " + std::to_string(co.final_position.size()) +
        " replicates" +
        (co.pending > 0 ? ", +-" + Fixed(p.ci_position_expected * 1e3, 3) + " mm expected with " +
                              std::to_string(co.pending) + " pending"
                        : std::string()) +
        " (" + BasisText(f) + ")";
    auto finite = [](double v) { return std::isfinite(v) ? json(v) : json(); };
    json basis{{"rule", "ci_above_target"},
               {"ci_position_m", finite(p.ci_position)},
               {"ci_angle_rad", finite(p.ci_angle)},
               {"ci_position_expected_m", finite(p.ci_position_expected)},
               {"replicates_done", co.final_position.size()},
               {"replicates_pending", co.pending}};
    basis.update(BasisJson(f));
    add(p.condition, co.planned, reason, basis);
  }
  if (!proposals.empty()) return;
  out->open = false;
  out->stop_reason = room <= 0 ? "max_trials reached (" + std::to_string(a.max_trials) + ")"
                               : std::to_string(on_target) + " of " + std::to_string(c.conditions) +
                                     " conditions on target; the rest reached max_replicates (" +
                                     std::to_string(a.max_replicates) + ")";
}

// The next round of an adaptive campaign, decided from the stored state
// only; nothing written. nullopt: nothing to decide now (not adaptive, not
// open, the rounds it must be based on still running, no cell to size the
// batch by).
//
// Round r >= 2 of a pipelined campaign is first decided from rounds <= r-2
// with round r-1 pending, as soon as rounds <= r-2 are finished (so it is
// queued while round r-1 runs); only when that finds nothing to add is it
// decided from rounds <= r-1, once those are finished (and only then may the
// sampler stop). Round 1, and every round of a campaign with
// "pipeline": false, is decided from all the rounds before it. Each attempt
// is a pure function of stored state that does not depend on timing: the
// outcomes of finished rounds and the points of the pending one.
std::optional<db::AdaptiveRound> DecideRound(db::Store& store, std::int64_t campaign_id,
                                             const Campaign& c, int idle_cells,
                                             std::string* expected_state) {
  if (!c.adaptive) return std::nullopt;
  const db::Campaign stored = store.GetCampaign(campaign_id);
  if (!stored.sampler_open || stored.state != db::CampaignState::kActive) return std::nullopt;
  Finished f = ReadTrials(store, campaign_id);
  const json before = json::parse(stored.sampler_state_json);
  const int round = before.contains("round") ? before["round"].get<int>() + 1 : 0;
  int batch = before.value("batch", 0);
  std::vector<Basis> bases;
  if (round == 0) {
    bases.push_back({-1, -1});
  } else {
    if (c.adaptive->pipeline && round >= 2) bases.push_back({round - 2, round - 1});
    bases.push_back({round - 1, -1});
  }
  bool outcomes_read = false;
  for (size_t i = 0; i < bases.size(); ++i) {
    if (!f.KnownFinished(bases[i].known_through)) return std::nullopt;  // wait for them
    if (round >= 1 && batch == 0) {
      batch = c.adaptive->batch > 0 ? c.adaptive->batch : idle_cells;
      if (batch <= 0) return std::nullopt;  // no cell to size the batch by yet
    }
    if (round >= 1 && !outcomes_read) {
      f.stored = store.ReadTrialOutcomes(campaign_id);
      outcomes_read = true;
    }
    f.on = bases[i];
    db::AdaptiveRound out;
    out.round = round;
    out.known_through_round = f.on.known_through;
    json state = before;
    state["sampler"] = ToString(c.adaptive->kind);
    state["round"] = round;
    state["batch"] = batch;
    state["pipeline"] = c.adaptive->pipeline;
    state.update(BasisJson(f));
    if (c.adaptive->kind == AdaptiveKind::kBoundary)
      DecideBoundary(store, c, f, round, batch, &out, &state);
    else
      DecideReplicates(store, c, f, round, batch, &out, &state);
    // A pipelined attempt that adds nothing does not stop the sampler: the
    // pending round's outcomes may still show more to do.
    if (out.trials.empty() && i + 1 < bases.size()) continue;
    state["trials"] = f.trials.size() + out.trials.size();
    state["max_trials"] = c.adaptive->max_trials;
    state["open"] = out.open;
    if (!out.open) state["stop_reason"] = out.stop_reason;
    out.sampler_state_json = state.dump();
    *expected_state = stored.sampler_state_json;
    return out;
  }
  return std::nullopt;
}

void LogRound(std::int64_t campaign_id, const db::AdaptiveRound& out) {
  if (out.open) {
    spdlog::info("campaign {}: adaptive round {}: {} trials planned", campaign_id, out.round,
                 out.trials.size());
  } else {
    spdlog::info("campaign {}: adaptive sampler finished after round {}: {}", campaign_id,
                 out.round, out.stop_reason);
  }
}

}  // namespace

std::int64_t AdvanceCampaign(db::Store& store, std::int64_t campaign_id, const Campaign& c,
                             int idle_cells) {
  std::int64_t planned = 0;
  // Up to two rounds at once: when round 0 finishes, round 1 (from it) and,
  // pipelined, round 2 (from it, round 1 pending) are both decided.
  for (int i = 0; i < 2; ++i) {
    std::string expected;
    const auto out = DecideRound(store, campaign_id, c, idle_cells, &expected);
    if (!out || !store.PlanAdaptiveRound(campaign_id, expected, *out)) break;
    // A closed sampler whose trials are all finished: the campaign is done now
    // (a service without exit_when_done completes campaigns nowhere else).
    if (!out->open && out->trials.empty()) store.CompleteFinishedCampaigns();
    LogRound(campaign_id, *out);
    planned += static_cast<std::int64_t>(out->trials.size());
    if (!out->open) break;
  }
  return planned;
}

std::int64_t CreateAdaptiveCampaign(db::Store& store, const db::NewCampaign& row,
                                    const Campaign& campaign,
                                    const std::function<bool()>& interrupted) {
  if (!campaign.adaptive) throw std::logic_error("CreateAdaptiveCampaign: not adaptive");
  bool closed_empty = false;
  db::AdaptiveRound first;
  const std::int64_t id = store.CreateAdaptiveCampaign(row, [&](std::int64_t campaign_id) {
    std::string expected;
    auto out = DecideRound(store, campaign_id, campaign, 0, &expected);
    // Round 0 needs no cell and nothing finished: always decided.
    if (!out) throw std::logic_error("CreateAdaptiveCampaign: round 0 not decided");
    if (interrupted && interrupted()) throw SubmitInterrupted();
    closed_empty = !out->open && out->trials.empty();
    first = *out;
    return *out;
  });
  if (closed_empty) store.CompleteFinishedCampaigns();
  LogRound(id, first);
  return id;
}

// ------------------------------------------------------------ planner

struct AdaptivePlanner::Impl {
  db::Store& store;
  std::chrono::milliseconds period;
  std::chrono::steady_clock::time_point next{};
  std::int64_t finished = -1;                                 // at the last pass
  std::map<std::int64_t, std::optional<Campaign>> campaigns;  // nullopt: not adaptive
};

AdaptivePlanner::AdaptivePlanner(db::Store& store, std::chrono::milliseconds period)
    : impl_(std::make_unique<Impl>(Impl{store, period, {}, -1, {}})) {}
AdaptivePlanner::~AdaptivePlanner() = default;

std::int64_t AdaptivePlanner::Advance(int idle_cells, std::int64_t finished) {
  const auto now = std::chrono::steady_clock::now();
  if (now < impl_->next && finished == impl_->finished) return 0;
  impl_->finished = finished;
  impl_->next = now + impl_->period;
  std::int64_t planned = 0;
  for (const auto& stored : impl_->store.ListCampaigns()) {
    if (!stored.sampler_open || stored.state != db::CampaignState::kActive) continue;
    auto it = impl_->campaigns.find(stored.id);
    if (it == impl_->campaigns.end()) {
      std::optional<Campaign> parsed;
      try {
        parsed = ParseCampaign(stored.spec_json, "", ConditionCheck::kBaseScene);
        if (!parsed->adaptive) parsed.reset();
      } catch (const CampaignError& e) {
        spdlog::error("campaign {}: spec unreadable, adaptive sampler stopped: {}", stored.id,
                      e.what());
      }
      it = impl_->campaigns.emplace(stored.id, std::move(parsed)).first;
    }
    if (!it->second) continue;
    try {
      planned += AdvanceCampaign(impl_->store, stored.id, *it->second, idle_cells);
    } catch (const db::StoreError& e) {
      using K = db::StoreError::Kind;
      if (e.kind() != K::kBusy && e.kind() != K::kBadInput && e.kind() != K::kNotFound) throw;
      spdlog::warn("campaign {}: adaptive round not planned now: {}", stored.id, e.what());
    } catch (const std::exception& e) {
      spdlog::error("campaign {}: adaptive round failed: {}", stored.id, e.what());
    }
  }
  return planned;
}

// ------------------------------------------------------------ status

std::optional<AdaptiveProgress> ReadAdaptiveProgress(const db::Campaign& campaign) {
  json state;
  try {
    state = json::parse(campaign.sampler_state_json);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  if (!state.is_object() || !state.contains("round") || !state.contains("sampler"))
    return std::nullopt;
  AdaptiveProgress p;
  p.sampler = state.value("sampler", "");
  p.round = state.value("round", 0);
  p.open = campaign.sampler_open;
  p.refining = state.value("refining", "");
  const double trials = state.value("trials", 0.0);
  const double max_trials = std::max(1.0, state.value("max_trials", 1.0));
  if (p.sampler == "boundary") {
    const double res = state.value("resolution", 0.0);
    if (state.contains("uncertainty") && state["uncertainty"].is_number()) {
      const double u = state["uncertainty"].get<double>();
      p.progress = "boundary uncertainty " + Fixed(u) + " (target " + Fixed(res) + "), " +
                   std::to_string(state.value("labelled", 0)) + " points classified";
      p.fraction = u > 0 ? std::min(1.0, res / u) : 1.0;
    } else {
      p.progress = "coarse batch of " + Fixed(trials, 0) + " points";
      p.fraction = 0;
    }
  } else {
    const double n = std::max(1.0, state.value("conditions", 1.0));
    const double on = state.value("on_target", 0.0);
    p.progress = Fixed(on, 0) + "/" + Fixed(n, 0) + " conditions on target";
    if (state.contains("widest_ci_position"))
      p.progress +=
          ", widest CI +-" + Fixed(state["widest_ci_position"].get<double>() * 1e3, 3) + " mm";
    p.fraction = on / n;
  }
  p.fraction = std::max(p.fraction, trials / max_trials);
  if (state.contains("known_through_round") && p.round >= 1) {
    const int known = state["known_through_round"].get<int>();
    p.progress += "; round " + std::to_string(p.round) + " decided from round" +
                  (known == 0 ? " 0" : "s 0-" + std::to_string(known));
    if (state.contains("pending_round") && state["pending_round"].is_number())
      p.progress += " while round " + std::to_string(state["pending_round"].get<int>()) + " ran";
  }
  if (!p.open) {
    p.fraction = 1;
    p.progress = "finished: " + state.value("stop_reason", std::string());
  }
  p.progress += " (" + Fixed(trials, 0) + "/" + Fixed(max_trials, 0) + " trials max)";
  return p;
}

}  // namespace arena::orchestrator
