// Adaptive samplers: campaigns that choose their next trials from the
// outcomes of the finished ones (campaign "sampler": {"adaptive": ...};
// orchestrator/README.md, "Adaptive samplers"; docs/adaptive.md).
//
// Ask/tell in rounds, pipelined. Every decision is a pure function of
// (campaign, the outcomes of a set of finished rounds in trial order, the
// points of at most one pending round, round, batch size):
//   round 1      from round 0 (when all of it is finished);
//   round r >= 2 from rounds <= r-2 with round r-1 PENDING -- its points
//                count as asked (never proposed again, and a candidate near
//                one is as certain as if it were a sample) but not as
//                evidence -- decided as soon as rounds <= r-2 are finished,
//                so round r is queued while round r-1 runs and the cells do
//                not idle at a round boundary; only if that adds nothing is
//                round r decided from rounds <= r-1 once those are finished
//                (and only such a decision may stop the sampler).
// With "pipeline": false every round is decided from all the rounds before
// it (cells idle while a round's last trials finish). The decision's trials,
// one decision row per trial (why, and the basis: known_through_round,
// pending_round, pending_trials) and the sampler's new state are written in
// one transaction (db::Store::PlanAdaptiveRound), refused unless every trial
// of the known rounds is finished. So:
//   * a restarted service (SIGKILL at any moment) recomputes the same next
//     round from the same stored outcomes: the sequence does not depend on
//     the kill, nor on which cell ran which trial or finished first, nor on
//     timing (which rounds a decision may use is fixed by its round number);
//   * two services on one store cannot both advance a campaign (the write is
//     conditional on the state it read).
// The batch size is the campaign's sampler.batch, or else the number of idle
// cells when round 1 is decided, then stored with the state (fixed).
//
//   round 0   boundary: a coarse grid (coarse_levels per dimension, ends
//             included); replicates: min_replicates of every condition.
//             Planned by SubmitCampaign.
//   round k   boundary: `batch` points by the nearest-neighbour margin rule
//             (ProposeBoundaryPoints); replicates: one more replicate of each
//             of the `batch` conditions with the widest confidence interval
//             above target (ProposeReplicates).
//   stop      boundary: the estimated boundary is resolved (every point on it
//             is within `resolution` of a sample of each class), no class
//             change was found, or max_trials; replicates: every condition's
//             CI is on target or at max_replicates, or max_trials. The stop is
//             stored as a decision without a trial; the campaign is then done
//             when its trials are.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "arena/db/store.hpp"
#include "arena/orchestrator/campaign.hpp"

namespace arena::orchestrator {

// ------------------------------------------------------------ boundary (pure)

// A finished point: its coordinates in the unit box and its class.
struct LabelledPoint {
  std::vector<double> u;
  bool positive = false;  // the outcome holds (pivoted, sliding, grasp kept)
  std::int64_t trial_id = 0;
};

struct BoundaryProposal {
  std::vector<double> u;
  double uncertainty = 0;  // distance to the nearest evidence (unit box); the rule's score
  std::int64_t near_positive = 0, near_negative = 0;  // trial ids of the nearest of each class
};

// The first round: a grid of `levels` per dimension, ends included, first
// dimension fastest.
std::vector<std::vector<double>> CoarseGrid(int dims, int levels);
// Default coarse levels: 5 (1-D), 4 (2-D), 3 (3-D).
int DefaultCoarseLevels(int dims);
// The same, but no finer than a spacing of 8 x resolution (at least 3
// levels): the coarse batch costs levels^dims trials whatever the resolution,
// and at a coarse resolution it was most of the campaign (16 of 27 trials at
// 0.125 in 2-D; bench/README.md, "Adaptive boundary sampling").
// 2-D: 3 levels from resolution 0.0625 up, 4 below.
int DefaultCoarseLevels(int dims, double resolution);

// The nearest-neighbour margin rule. Candidates: a lattice of spacing
// resolution / 2. A candidate lies on the current estimate of the boundary
// when its nearest positive and nearest negative samples are equally far
// (|d+ - d-| <= one lattice spacing: the 1-NN classifier's decision
// boundary); its uncertainty is min(d+, d-), how far it is from any evidence.
// Greedily picks up to `count` candidates on the boundary with the largest
// uncertainty above `resolution`, each pick counting as evidence for the next
// (so one batch spreads along the boundary). In 1-D a candidate is on the
// boundary when its neighbours on either side disagree: one pick is the
// midpoint of the widest disagreeing bracket (bisection), a batch of b splits
// the brackets into smaller parts.
// `excluded`: points already planned or failed (never proposed again).
// *max_uncertainty (optional): the largest uncertainty on the boundary now
// (how far the sampler is from its resolution).
// @returns fewer than `count` (none: resolved) proposals, deterministic.
std::vector<BoundaryProposal> ProposeBoundaryPoints(
    const std::vector<LabelledPoint>& labelled, const std::vector<std::vector<double>>& excluded,
    int dims, double resolution, int count, double* max_uncertainty = nullptr);

// ------------------------------------------------------------ replicates (pure)

// One condition's finished replicates (final pose of each).
struct ConditionOutcomes {
  std::int64_t condition = 0;
  std::vector<std::array<double, 3>> final_position;  // m
  std::vector<double> final_angle;                    // rad, net rotation
  int planned = 0;  // replicates planned so far (incl. failed and pending)
  int pending = 0;  // of them, in a pipelined round still running: outcome unknown
};

// Half-width of the two-sided `confidence` interval of the mean of `values`
// (Student t); +infinity with fewer than 2 values.
double ConfidenceHalfWidth(const std::vector<double>& values, double confidence);
// The half-width expected once `extra` more values with the same spread are
// in: t(n+extra-1) * sd / sqrt(n+extra); +infinity with fewer than 2 values.
double ExpectedHalfWidth(const std::vector<double>& values, double confidence, int extra);
// The widest of the position coordinates' half-widths (m), expected with
// `extra` more replicates.
double PositionHalfWidth(const ConditionOutcomes& c, double confidence, int extra = 0);

struct ReplicateProposal {
  std::int64_t condition = 0;
  double ci_position = 0;           // m, current half-width
  double ci_angle = 0;              // rad
  double ci_position_expected = 0;  // m, expected once its pending replicates are in
};
// Conditions whose CI -- expected once their pending replicates are in -- is
// above target and that have fewer than max_replicates (planned): the
// `count` widest (relative to target) get one more.
std::vector<ReplicateProposal> ProposeReplicates(const std::vector<ConditionOutcomes>& conditions,
                                                 const AdaptiveSpec& spec, int count);

// ------------------------------------------------------------ the service's hook

// Stores a new adaptive campaign (`row`, sampler_open) and its round 0 (the
// coarse batch, or min_replicates of every condition) in ONE transaction
// (SubmitCampaign): a crash or an interrupt leaves nothing or both.
// @returns the campaign id. @throws db::StoreError, SubmitInterrupted.
std::int64_t CreateAdaptiveCampaign(db::Store& store, const db::NewCampaign& row,
                                    const Campaign& campaign,
                                    const std::function<bool()>& interrupted = {});

// The adaptive samplers of every open campaign in one store. The service
// calls Advance once per scheduling pass; it does its work every `period`,
// and at once when `finished` (trials the service has finished so far)
// changed since the last call -- a round's last trial should not leave the
// cells waiting for the timer -- and only for campaigns with a round to decide.
class AdaptivePlanner {
 public:
  explicit AdaptivePlanner(db::Store& store,
                           std::chrono::milliseconds period = std::chrono::milliseconds(200));
  ~AdaptivePlanner();
  // @returns trials planned in this call. @throws db::StoreError only for a
  //   failing store (a campaign whose spec cannot be read is closed with the reason).
  std::int64_t Advance(int idle_cells, std::int64_t finished = -1);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Decides and writes campaign_id's next round if its current one is
// finished (the work of one Advance for one campaign).
// @returns trials planned (0 also when it stopped or is waiting).
std::int64_t AdvanceCampaign(db::Store& store, std::int64_t campaign_id, const Campaign& campaign,
                             int idle_cells);

// What an adaptive campaign is doing, for `arena status` (from its stored state).
struct AdaptiveProgress {
  std::string sampler;  // "boundary", "replicates"
  int round = 0;
  bool open = false;
  std::string refining;  // e.g. "pivoted boundary in grip_force x pivot_offset"
  std::string
      progress;  // e.g. "uncertainty 0.083 -> 0.025 (resolution)", "12/40 conditions on target"
  double fraction = 0;  // [0, 1], how far towards the stop criterion
};
// @returns nullopt for a campaign that is not adaptive.
std::optional<AdaptiveProgress> ReadAdaptiveProgress(const db::Campaign& campaign);

}  // namespace arena::orchestrator
