// ScorePrediction on hand-built trajectories whose errors are known.
#include <cmath>

#include <gtest/gtest.h>

#include "arena/assessment/scoring.hpp"

namespace arena::assessment {
namespace {

using mechanics::ContactMode;
using mechanics::ContactState;
using mechanics::TrajectorySample;

std::vector<TrajectorySample> Trajectory(int n, double dx_per_sample, double fn, ContactMode mode) {
  std::vector<TrajectorySample> out(n);
  for (int i = 0; i < n; ++i) {
    out[i].t = i / 250.0;
    out[i].position = Eigen::Vector3d(dx_per_sample * i, 0, 0);
    ContactState c;
    c.normal_force = fn;
    c.tangential_force = Eigen::Vector3d(0, 0, 1.0);
    c.mode = mode;
    out[i].contacts = {c, c};
  }
  return out;
}

TEST(ScorePrediction, IdenticalTrajectoriesHaveNoError) {
  const auto truth = Trajectory(50, 1e-3, 10, ContactMode::kSlide);
  const PredictionError e = ScorePrediction(truth, truth);
  EXPECT_EQ(e.final_position, 0);
  EXPECT_EQ(e.final_angle, 0);
  EXPECT_EQ(e.force_rms, 0);
  EXPECT_DOUBLE_EQ(e.mode_agreement, 1.0);
  EXPECT_EQ(e.samples_compared, 50);
  EXPECT_NEAR(e.force_scale, std::sqrt(101.0), 1e-12);
}

TEST(ScorePrediction, KnownOffsetsAreMeasured) {
  const auto truth = Trajectory(50, 1e-3, 10, ContactMode::kSlide);
  auto predicted = Trajectory(60, 2e-3, 12, ContactMode::kStick);  // longer: paired over 50
  predicted[49].orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.25, Eigen::Vector3d::UnitY()));
  for (int i = 0; i < 25; ++i) predicted[i].contacts[0].mode = ContactMode::kSlide;
  const PredictionError e = ScorePrediction(predicted, truth);
  EXPECT_NEAR(e.final_position, 49e-3, 1e-12);
  EXPECT_NEAR(e.final_angle, 0.25, 1e-12);
  EXPECT_NEAR(e.force_rms, 2.0, 1e-12);
  EXPECT_NEAR(e.mode_agreement, 25.0 / 100.0, 1e-12);
}

TEST(ScorePrediction, ContactCountMismatchIsAnError) {
  const auto truth = Trajectory(5, 0, 1, ContactMode::kStick);
  auto predicted = truth;
  predicted[3].contacts.pop_back();
  EXPECT_THROW(ScorePrediction(predicted, truth), std::invalid_argument);
}

}  // namespace
}  // namespace arena::assessment
