// Calibration against a stand-in simulator whose answer is known: the fit
// must recover the true scale, bracket it by its bootstrap interval, improve
// the held-out error, and say so when a parameter cannot improve anything.
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena/assessment/calibration.hpp"
#include "arena/simulators/simulator.hpp"
#include "mechanics/scenes.hpp"

namespace arena::assessment {
namespace {

// A one-finger "simulator": the finger's tangential force is mu * grip
// force (sliding friction), the object moves 1 mm per unit of pusher mu.
// Truth is made with the true scales; the fit starts from scale 1.
mechanics::SimulationResult FakeSimulate(const mechanics::Scene& s) {
  mechanics::SimulationResult r;
  for (int i = 0; i < 20; ++i) {
    mechanics::TrajectorySample t;
    t.t = i / 250.0;
    t.position = Eigen::Vector3d(0, 0, 1e-3 * s.pusher->mu * i / 19.0);
    mechanics::ContactState f;
    f.normal_force = s.grip_force;
    f.tangential_force = Eigen::Vector3d(0, 0, s.fingers[0].mu * s.grip_force);
    t.contacts = {f, mechanics::ContactState{}};
    r.samples.push_back(t);
  }
  return r;
}

std::vector<CalibrationTrial> MakeTrials(double true_mu_scale, double true_pusher_scale) {
  std::vector<CalibrationTrial> trials;
  for (int i = 0; i < 12; ++i) {
    mechanics::Scene s;
    s.grip_force = 2.0 + i;
    s.fingers.resize(1);
    s.fingers[0].mu = 0.5;
    s.fingers[0].normal = Eigen::Vector3d::UnitX();
    s.pusher.emplace();
    s.pusher->mu = 0.3;
    s.pusher->normal = Eigen::Vector3d::UnitZ();
    CalibrationTrial t;
    t.trial_id = 100 + i;
    t.scene = s;
    t.truth = FakeSimulate(
                  ApplyScales(s, {{"mu_fingers", true_mu_scale}, {"mu_pusher", true_pusher_scale}}))
                  .samples;
    trials.push_back(t);
  }
  return trials;
}

TEST(Calibrate, RecoversKnownScalesWithAnInterval) {
  CalibrationOptions o;
  o.params = {CalibrationParam::kMuFingers, CalibrationParam::kMuPusher};
  o.bootstrap = 8;
  const auto r = Calibrate(MakeTrials(1.3, 0.8), FakeSimulate, o);
  ASSERT_EQ(r.fitted.size(), 2u);
  EXPECT_NEAR(r.fitted[0].scale, 1.3, 0.01);
  EXPECT_NEAR(r.fitted[1].scale, 0.8, 0.01);
  EXPECT_LE(r.fitted[0].ci_low, 1.3 + 0.01);
  EXPECT_GE(r.fitted[0].ci_high, 1.3 - 0.01);
  ASSERT_TRUE(r.fitted[0].nominal);
  EXPECT_NEAR(*r.fitted[0].nominal * r.fitted[0].scale, 0.65, 0.01);
  EXPECT_TRUE(r.improved);
  EXPECT_LT(r.heldout_after, 0.01 * r.heldout_before);
  EXPECT_EQ(r.optimizer, "LN_BOBYQA");
  EXPECT_EQ(r.train_ids.size() + r.heldout_ids.size(), 12u);
  EXPECT_EQ(r.heldout_ids.size(), 4u);  // round(0.3 * 12)
}

TEST(Calibrate, AParameterWithoutEffectDoesNotImprove) {
  // The truth was made with the model as it is: nothing to gain; the mass
  // does not enter the stand-in at all.
  CalibrationOptions o;
  o.params = {CalibrationParam::kObjectMass};
  o.bootstrap = 0;
  const auto r = Calibrate(MakeTrials(1.0, 1.0), FakeSimulate, o);
  EXPECT_FALSE(r.improved);
  EXPECT_EQ(r.heldout_after, r.heldout_before);
  EXPECT_EQ(r.optimizer, "LN_COBYLA");
}

// A pusher that sticks once its friction reaches 0.3: above that its
// friction changes nothing (the stand-in moves the object by min(mu, 0.3)).
mechanics::SimulationResult StickingPusherSimulate(const mechanics::Scene& s) {
  mechanics::Scene capped = s;
  capped.pusher->mu = std::min(s.pusher->mu, 0.3);
  return FakeSimulate(capped);
}

TEST(Calibrate, AProfileBoundsAnIdentifiedParameterAndFlagsAFlatOne) {
  // Truth: fingers 1.3x, pusher 1.3x (0.39: past where it sticks). The
  // fingers' profile brackets 1.3 on both sides; the pusher's runs from
  // about 1 (where the truth's effect saturates) up to the upper bound, and
  // it is reported as not identified, whatever its bootstrap says.
  std::vector<CalibrationTrial> trials = MakeTrials(1.0, 1.0);
  for (auto& t : trials)
    t.truth =
        StickingPusherSimulate(ApplyScales(t.scene, {{"mu_fingers", 1.3}, {"mu_pusher", 1.3}}))
            .samples;
  CalibrationOptions o;
  o.params = {CalibrationParam::kMuFingers, CalibrationParam::kMuPusher};
  o.bootstrap = 4;
  const auto r = Calibrate(trials, StickingPusherSimulate, o);
  ASSERT_EQ(r.fitted.size(), 2u);
  const FittedParam& fingers = r.fitted[0];
  const FittedParam& pusher = r.fitted[1];
  EXPECT_NEAR(fingers.scale, 1.3, 0.01);
  ASSERT_TRUE(fingers.profiled);
  EXPECT_TRUE(fingers.identified());
  EXPECT_LT(fingers.profile_low, 1.3);
  EXPECT_GT(fingers.profile_high, 1.3);
  EXPECT_GT(fingers.profile_low, 1.3 * 0.8);  // the neighbours near the fit (x 0.82 .. 1.22)
  EXPECT_LT(fingers.profile_high, 1.3 * 1.25);
  ASSERT_TRUE(pusher.profiled);
  EXPECT_FALSE(pusher.identified());
  EXPECT_TRUE(pusher.bounded_low);
  EXPECT_FALSE(pusher.bounded_high);
  EXPECT_DOUBLE_EQ(pusher.profile_high, o.upper);
  EXPECT_LT(pusher.profile_low, 1.0);
  EXPECT_GT(pusher.profile_low, 0.5);
  ASSERT_GE(pusher.profile.size(), 12u);
  for (size_t i = 1; i < pusher.profile.size(); ++i)
    EXPECT_LT(pusher.profile[i - 1].first, pusher.profile[i].first);
  // Stored with the fit.
  const auto stored = nlohmann::json::parse(ParamsJson(r));
  EXPECT_EQ(stored["mu_pusher"]["profile"]["identified"], false);
  EXPECT_EQ(stored["mu_fingers"]["profile"]["identified"], true);
  EXPECT_EQ(stored["mu_pusher"]["profile"]["bounded"][1], false);

  o.profile_points = 0;  // no profile: nothing claimed either way
  const auto plain = Calibrate(trials, StickingPusherSimulate, o);
  EXPECT_FALSE(plain.fitted[1].profiled);
  EXPECT_TRUE(plain.fitted[1].identified());
  EXPECT_FALSE(nlohmann::json::parse(ParamsJson(plain))["mu_pusher"].contains("profile"));
  o.profile_points = 2;
  EXPECT_THROW(Calibrate(trials, StickingPusherSimulate, o), CalibrationError);
}

// A fit outside its own bootstrap interval is said, in the text and the
// stored JSON (seen on docs/adaptive.md's walk-through: mu_fingers 1.3354
// with a bootstrap interval [1.2882, 1.3258], printed with no comment).
TEST(Calibrate, AFitOutsideItsBootstrapIntervalIsSaid) {
  FittedParam inside;
  inside.name = "mu_pusher";
  inside.scale = 1.1668;
  inside.ci_low = 1.1493;
  inside.ci_high = 1.4033;
  EXPECT_FALSE(inside.fit_outside_bootstrap());
  EXPECT_EQ(BootstrapWarning(inside), "");
  FittedParam above = inside;
  above.name = "mu_fingers";
  above.scale = 1.3354;
  above.ci_low = 1.2882;
  above.ci_high = 1.3258;
  EXPECT_TRUE(above.fit_outside_bootstrap());
  const std::string w = BootstrapWarning(above);
  EXPECT_NE(w.find("mu_fingers: the fit 1.3354 lies outside its own bootstrap interval "
                   "[1.2882, 1.3258]: every resampled refit moved below it"),
            std::string::npos)
      << w;
  FittedParam below = inside;
  below.scale = 1.0221;
  below.ci_low = 1.0507;
  below.ci_high = 1.8550;
  EXPECT_NE(BootstrapWarning(below).find("moved above it"), std::string::npos);
  FittedParam no_bootstrap;  // --bootstrap 0: the interval is the fit itself
  no_bootstrap.scale = no_bootstrap.ci_low = no_bootstrap.ci_high = 1.2;
  EXPECT_FALSE(no_bootstrap.fit_outside_bootstrap());
  CalibrationResult r;
  r.fitted = {inside, above};
  const auto j = nlohmann::json::parse(ParamsJson(r));
  EXPECT_FALSE(j["mu_pusher"]["fit_outside_ci95"].get<bool>());
  EXPECT_TRUE(j["mu_fingers"]["fit_outside_ci95"].get<bool>());
}

TEST(Calibrate, RefusesBadOptions) {
  CalibrationOptions o;
  EXPECT_THROW(Calibrate(MakeTrials(1, 1), FakeSimulate, o), CalibrationError);  // no params
  o.params = {CalibrationParam::kMuFingers, CalibrationParam::kMuFingers};
  EXPECT_THROW(Calibrate(MakeTrials(1, 1), FakeSimulate, o), CalibrationError);
  o.params = {CalibrationParam::kMuFingers};
  auto few = MakeTrials(1, 1);
  few.resize(3);
  EXPECT_THROW(Calibrate(few, FakeSimulate, o), CalibrationError);
  EXPECT_THROW(ParseCalibrationParam("mu_everything"), CalibrationError);
  EXPECT_THROW(ApplyScales(mechanics::Scene{}, {{"mu_fingers", -1}}), CalibrationError);
}

// Against MuJoCo itself (the `--predictor mujoco` path): truth made by MuJoCo
// with the fingers' friction 1.3x the scenes', the fit runs the same engine
// with each trial's model compiled once and only the friction patched. No
// cell noise here, so the scale is recovered closely; the e2e test does it
// with real cells. Scenes: a held box pushed up from below, off centre, at
// 2-7 N of grip (the fingers slide: their friction sets the pusher force).
TEST(Calibrate, RecoversTheFingersFrictionAgainstMujocoOnPreparedModels) {
  const auto sim = simulators::MakeSimulator("mujoco", R"({"timestep": 0.002})");
  std::vector<CalibrationTrial> trials;
  for (int i = 0; i < 6; ++i) {
    mechanics::Scene s = mechanics::testing::HeldBox(0.2, 2.0 + i, 0.5);
    mechanics::PusherSpec p;
    p.name = "pusher";
    p.type = mechanics::ContactType::kPoint;
    p.position = {0, 0.002 * (i % 3), -0.05};
    p.normal = {0, 0, 1};
    p.mu = 0.3;
    p.motion.velocity = {0, 0, 0.02};
    s.pusher = p;
    s.duration = 0.12;
    CalibrationTrial t;
    t.trial_id = 1 + i;
    t.scene = s;
    const auto truth = sim->Simulate(ApplyScales(s, {{"mu_fingers", 1.3}}));
    ASSERT_EQ(truth.status, mechanics::SimulationStatus::kOk) << truth.error;
    t.truth = truth.samples;
    trials.push_back(t);
  }
  CalibrationOptions o;
  o.params = {CalibrationParam::kMuFingers};
  o.max_evaluations = 20;
  o.bootstrap = 10;
  o.bootstrap_method = BootstrapMethod::kReuse;
  o.scales.force_window_s = 0.04;
  o.threads = 2;
  int seen = 0;
  o.on_evaluation = [&](int n, int budget, double, double) {
    EXPECT_EQ(n, ++seen);
    EXPECT_EQ(budget, 20);
  };
  const auto r = Calibrate(trials, *sim, o);
  EXPECT_NEAR(r.fitted[0].scale, 1.3, 0.065);  // 5 %: the loss is rough at small scales (chatter)
  EXPECT_LE(r.fitted[0].ci_low, r.fitted[0].scale);
  EXPECT_GE(r.fitted[0].ci_high, r.fitted[0].scale);
  EXPECT_TRUE(r.improved);
  EXPECT_LE(r.train_after, r.train_before);
  EXPECT_EQ(seen, r.evaluations);
  EXPECT_LE(r.evaluations, 20);
  // Memoised: at most one run per trial and evaluated point (+ held-out twice,
  // + the profile's scales: profile_points and 7 more at most); the reuse
  // bootstrap simulated nothing; every run on its trial's prepared model.
  EXPECT_LE(r.simulations,
            static_cast<long>((r.evaluations + o.profile_points + 7) * r.train_ids.size() +
                              2 * r.heldout_ids.size()));
  EXPECT_TRUE(r.fitted[0].profiled);
  EXPECT_EQ(r.models_reused, r.simulations);
  EXPECT_EQ(r.bootstrap_method, "reuse");
}

}  // namespace
}  // namespace arena::assessment
