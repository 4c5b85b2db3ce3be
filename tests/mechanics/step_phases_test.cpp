// The model's step in named phases (mechanics/src/model_tester.hpp): run one
// at a time they give Step()'s answer to the last bit, each phase's product
// is the closed form it stands for, and bad values are refused typed.
#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "arena/mechanics/model.hpp"
#include "model_tester.hpp"
#include "scenes.hpp"

namespace arena::mechanics {
namespace {

using testing::CanonicalScene;
using testing::HeldBox;

// Runs every phase of one step through the tester.
StepReport StepByPhases(ContactModelTester& tester) {
  StepReport rep;
  if (!tester.BeginStep(rep)) return rep;
  for (int i = 0; i < kStepPhases; ++i) {
    if (!tester.Run(static_cast<StepPhase>(i), rep)) return rep;
  }
  return rep;
}

TEST(StepPhases, OneAtATimeIsTheStepToTheLastBit) {
  for (Reduce reduce : {Reduce::kAuto, Reduce::kFull}) {
    Scene scene = CanonicalScene();
    scene.model.reduce = reduce;
    // The phases are the carried step's (a quasi-static step repeats them).
    scene.model.inertia = InertiaModel::kCarried;
    ContactModel whole(scene), phased(scene);
    ContactModelTester tester(phased);
    for (int k = 0; k < 60; ++k) {
      const StepReport a = whole.Step();
      const StepReport b = StepByPhases(tester);
      ASSERT_TRUE(a.ok && b.ok) << a.error << b.error;
      EXPECT_EQ(a.pivots, b.pivots);
      ASSERT_EQ(whole.position(), phased.position()) << "step " << k;
      ASSERT_EQ(whole.velocity(), phased.velocity());
      ASSERT_EQ(whole.angular_velocity(), phased.angular_velocity());
      ASSERT_EQ(whole.pusher_force(), phased.pusher_force());
    }
  }
}

// Free motion: with only gravity and the fingers' equal and opposite known
// forces, the reduced twist after dt is v + dt g (no torque: the fingers
// press along one line through the centre of mass).
TEST(StepPhases, FreeMotionIsGravityOverOneStep) {
  Scene scene = HeldBox(0.2, 10.0, 0.5);
  scene.model.reduce = Reduce::kFull;
  ContactModel model(scene);
  ContactModelTester tester(model);
  StepReport rep;
  ASSERT_TRUE(tester.BeginStep(rep));
  for (StepPhase p : {StepPhase::kPlaceContacts, StepPhase::kMassMatrix, StepPhase::kFreeMotion})
    ASSERT_TRUE(tester.Run(p, rep));
  ASSERT_EQ(tester.reduced_coordinates(), 6);
  const Eigen::VectorXd vfree = tester.free_twist();
  const double dt = scene.model.dt;
  EXPECT_NEAR(vfree[2], dt * -9.81, 1e-15);
  for (int i : {0, 1, 3, 4, 5}) EXPECT_NEAR(vfree[i], 0.0, 1e-15) << i;
  // The mass matrix: m I and the box's inertia m (b² + c²) / 12 about x.
  const Eigen::MatrixXd M = tester.mass_matrix();
  EXPECT_DOUBLE_EQ(M(0, 0), 0.2);
  EXPECT_NEAR(M(3, 3), 0.2 * (0.03 * 0.03 + 0.1 * 0.1) / 12, 1e-15);
}

// The grasp map: the column of a force unknown is its direction d and its
// moment arm × d about the centre of mass; the solved forces balance the
// wrench the step's new twist says (Newton-Euler over dt).
TEST(StepPhases, GraspMapColumnsAreDirectionsAndMoments) {
  Scene scene = CanonicalScene();
  scene.model.reduce = Reduce::kFull;
  ContactModel model(scene);
  ContactModelTester tester(model);
  StepReport rep;
  ASSERT_TRUE(tester.BeginStep(rep));
  for (int i = 0; i <= static_cast<int>(StepPhase::kSolve); ++i)
    ASSERT_TRUE(tester.Run(static_cast<StepPhase>(i), rep)) << rep.error;
  const Eigen::MatrixXd J = tester.grasp_map();
  ASSERT_EQ(J.rows(), 6);
  ASSERT_EQ(J.cols(), tester.force_unknowns());
  for (int k = 0; k < J.cols(); ++k) {
    const Eigen::Vector3d d = J.col(k).head<3>();
    if (d.norm() == 0) continue;  // a point without rows this step
    EXPECT_NEAR(d.norm(), 1.0, 1e-12) << k;
    EXPECT_NEAR(J.col(k).tail<3>().dot(d), 0.0, 1e-12) << "moment ⊥ force, column " << k;
  }
  const Eigen::MatrixXd A = tester.lcp_matrix();
  ASSERT_EQ(A.rows(), tester.lcp_size());
  EXPECT_TRUE(A.allFinite());
  EXPECT_TRUE(tester.lcp_vector().allFinite());
  // Newton from rest: m v+ / dt = J f + (known: m g and the point finger's
  // grip along +x).
  const Eigen::Matrix<double, 6, 1> tw = tester.new_twist();
  const Eigen::VectorXd wrench = J * tester.forces() + tester.known_wrench();
  const double m = scene.object.mass, dt = scene.model.dt;
  EXPECT_NEAR(tester.known_wrench()[0], scene.grip_force, 1e-12);
  EXPECT_NEAR(tester.known_wrench()[2], m * scene.gravity[2], 1e-12);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(m * tw[i] / dt, wrench[i], 1e-9 * scene.grip_force) << i;
}

// A twist gone bad is refused before the solver sees it, typed, with the
// state left as it was.
TEST(StepPhases, NonFiniteTwistIsRefusedTyped) {
  // The carried step uses the twist it carries (a quasi-static step does not).
  Scene scene = CanonicalScene();
  scene.model.inertia = InertiaModel::kCarried;
  ContactModel model(scene);
  ASSERT_TRUE(model.Step().ok);
  ContactModelTester tester(model);
  const Eigen::Vector3d c0 = model.position();
  const double t0 = model.time();
  tester.SetTwist(Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 0),
                  Eigen::Vector3d::Zero());
  const StepReport rep = model.Step();
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.failure, StepFailure::kNonFinite);
  EXPECT_NE(rep.error.find("non-finite free twist"), std::string::npos) << rep.error;
  EXPECT_EQ(model.position(), c0);
  EXPECT_EQ(model.time(), t0);
  tester.SetTwist(Eigen::Vector3d::Zero(),
                  Eigen::Vector3d(0, std::numeric_limits<double>::infinity(), 0));
  EXPECT_EQ(model.Step().failure, StepFailure::kNonFinite);
}

TEST(StepPhases, ATakenStepReportsNoFailure) {
  ContactModel model(CanonicalScene());
  const StepReport rep = model.Step();
  EXPECT_TRUE(rep.ok);
  EXPECT_EQ(rep.failure, StepFailure::kNone);
}

}  // namespace
}  // namespace arena::mechanics
