// Calibration against a stand-in simulator whose answer is known: the fit
// must recover the true scale, bracket it by its bootstrap interval, improve
// the held-out error, and say so when a parameter cannot improve anything.
#include <cmath>

#include <gtest/gtest.h>

#include "arena/assessment/calibration.hpp"

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

}  // namespace
}  // namespace arena::assessment
