// Defect profiles: parsing with field-named errors, seeded determinism and
// the statistics of the noise they ask for.
#include <cmath>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "arena/executors/defects.hpp"

namespace arena::executors {
namespace {

std::string ErrorOf(const std::string& json) {
  try {
    ParseDefectProfile(json);
  } catch (const DefectError& e) {
    return e.field();
  }
  return "(accepted)";
}

TEST(DefectProfile, EmptyProfileIsAPerfectCell) {
  const DefectProfile p = ParseDefectProfile("{}");
  EXPECT_EQ(p.position_std, Eigen::Vector3d::Zero());
  EXPECT_EQ(p.drop_probability, 0);
  EXPECT_EQ(p.contact_types.size(), 3u);
}

TEST(DefectProfile, ShippedExampleIsValid) {
  std::ifstream in(std::string(ARENA_SOURCE_DIR) + "/examples/defects/noisy.json");
  std::stringstream text;
  text << in.rdbuf();
  const DefectProfile p = ParseDefectProfile(text.str());
  EXPECT_DOUBLE_EQ(p.latency_ms, 8);
  EXPECT_DOUBLE_EQ(p.force_std.z(), 0.08);
}

TEST(DefectProfile, BadFieldsAreNamed) {
  EXPECT_EQ(ErrorOf(R"({"pose_noise": {"position_std": [0.1, -1, 0]}})"),
            "pose_noise.position_std[1]");
  EXPECT_EQ(ErrorOf(R"({"latency_ms": "x"})"), "latency_ms");
  EXPECT_EQ(ErrorOf(R"({"drop_probability": 1.0})"), "drop_probability");
  EXPECT_EQ(ErrorOf(R"({"colour": 1})"), "colour");
  EXPECT_EQ(ErrorOf(R"({"ft_noise": {"force": 1}})"), "ft_noise.force");
  EXPECT_EQ(ErrorOf(R"({"contact_types": ["point", "glue"]})"), "contact_types[1]");
  EXPECT_EQ(ErrorOf(R"({"workspace": {"min": [0, 0, 0], "max": [0.1, 0.1, -0.1]}})"),
            "workspace.min[2]");
  EXPECT_EQ(ErrorOf(R"({"reset": {"max_attempts": 0}})"), "reset.max_attempts");
  EXPECT_EQ(ErrorOf(R"({"reset": {"failure_probability": 2}})"), "reset.failure_probability");
  EXPECT_EQ(ErrorOf("[1, 2"), "(document)");
  EXPECT_EQ(ErrorOf(R"({"fault_injection": {"hang_after_accept": 1}})"),
            "fault_injection.hang_after_accept");
  EXPECT_EQ(ErrorOf(R"({"fault_injection": {"stream": "garbage"}})"), "fault_injection.stream");
  EXPECT_EQ(ErrorOf(R"({"fault_injection": {"crash": true}})"), "fault_injection.crash");
}

// The fault-injection knobs (fault tests only) survive the round trip and are
// absent from a normal profile's JSON.
TEST(DefectProfile, FaultInjectionKnobsRoundTrip) {
  const DefectProfile p =
      ParseDefectProfile(R"({"fault_injection": {"hang_after_accept": true, "stream": "gap"}})");
  EXPECT_TRUE(p.hang_after_accept);
  EXPECT_EQ(p.corrupt_stream, "gap");
  const DefectProfile q = ParseDefectProfile(DefectProfileToJson(p));
  EXPECT_TRUE(q.hang_after_accept);
  EXPECT_EQ(q.corrupt_stream, "gap");
  EXPECT_EQ(DefectProfileToJson(ParseDefectProfile("{}")).find("fault_injection"),
            std::string::npos);
}

TEST(DefectProfile, RoundTripsThroughJson) {
  const DefectProfile p = ParseDefectProfile(
      R"({"pose_noise": {"position_std": 0.001, "rotation_std": [0.01, 0.02, 0.03]},
          "latency_ms": 20, "drop_probability": 0.1, "contact_types": ["point"],
          "friction_variability": {"mu_scale_std": 0.1}, "reset": {"max_attempts": 5}})");
  const DefectProfile q = ParseDefectProfile(DefectProfileToJson(p));
  EXPECT_EQ(DefectProfileToJson(p), DefectProfileToJson(q));
  EXPECT_EQ(q.rotation_std.z(), 0.03);
  EXPECT_EQ(q.reset.max_attempts, 5);
}

std::vector<mechanics::TrajectorySample> Line(int n) {
  std::vector<mechanics::TrajectorySample> samples(n);
  for (int i = 0; i < n; ++i) {
    samples[i].t = i / 250.0;
    samples[i].position = Eigen::Vector3d(0, 0, 0.001 * samples[i].t);
    samples[i].pusher_force = Eigen::Vector3d(0, 0, 2.0);
    samples[i].contacts.resize(1);
    samples[i].contacts[0].normal_force = 10;
  }
  return samples;
}

mechanics::Scene OneFinger() {
  mechanics::Scene s;
  s.fingers.resize(1);
  s.fingers[0].normal = Eigen::Vector3d::UnitX();
  return s;
}

TEST(DefectProfile, NoiseHasTheRequestedStandardDeviation) {
  const DefectProfile p = ParseDefectProfile(
      R"({"pose_noise": {"position_std": [0.001, 0.002, 0.0005]}, "ft_noise": {"force_std": 0.2}})");
  const auto truth = Line(20000);
  const auto seen = Observe(truth, OneFinger(), p, 11, 3);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum2 = Eigen::Vector3d::Zero();
  double f_sum = 0, f_sum2 = 0;
  for (size_t i = 0; i < truth.size(); ++i) {
    ASSERT_TRUE(seen[i].valid);
    const Eigen::Vector3d e = seen[i].position - truth[i].position;
    sum += e;
    sum2 += e.cwiseProduct(e);
    const double fe = seen[i].pusher_wrench[2] - 2.0;
    f_sum += fe;
    f_sum2 += fe * fe;
  }
  const double n = static_cast<double>(truth.size());
  for (int k = 0; k < 3; ++k) {
    const double std_dev = std::sqrt(sum2[k] / n - std::pow(sum[k] / n, 2));
    // 20000 samples: the sample std is within ~1.5 % of the true one (3 sigma).
    EXPECT_NEAR(std_dev / p.position_std[k], 1.0, 0.03) << "axis " << k;
  }
  EXPECT_NEAR(std::sqrt(f_sum2 / n - std::pow(f_sum / n, 2)) / 0.2, 1.0, 0.03);
}

TEST(DefectProfile, SameSeedTrialAndProfileGiveBitIdenticalObservations) {
  const DefectProfile p = ParseDefectProfile(
      R"({"pose_noise": {"position_std": 0.001, "rotation_std": 0.01}, "ft_noise": {"force_std": 0.1},
          "drop_probability": 0.2, "latency_ms": 12})");
  const auto truth = Line(500);
  const auto a = Observe(truth, OneFinger(), p, 5, 9);
  const auto b = Observe(truth, OneFinger(), p, 5, 9);
  const auto c = Observe(truth, OneFinger(), p, 5, 10);
  int differ = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].valid, b[i].valid);
    ASSERT_EQ(a[i].position, b[i].position);  // bit for bit
    ASSERT_EQ(a[i].orientation.coeffs(), b[i].orientation.coeffs());
    ASSERT_EQ(a[i].pusher_wrench, b[i].pusher_wrench);
    differ += a[i].position != c[i].position;
  }
  EXPECT_GT(differ, 100);  // another trial id, other noise
  const auto pa = DrawPerturbation(p, 5, 9), pb = DrawPerturbation(p, 5, 9);
  EXPECT_EQ(pa.mu_scale, pb.mu_scale);
}

TEST(DefectProfile, LatencyDelaysAndDropsRemoveObservations) {
  const DefectProfile p = ParseDefectProfile(R"({"latency_ms": 20, "drop_probability": 0.25})");
  const auto truth = Line(8000);
  const auto seen = Observe(truth, OneFinger(), p, 1, 1);
  for (int i = 0; i < 5; ++i) EXPECT_FALSE(seen[i].valid) << i;  // 20 ms = 5 samples
  int dropped = 0;
  for (size_t i = 5; i < seen.size(); ++i) {
    if (!seen[i].valid) {
      ++dropped;
      continue;
    }
    EXPECT_DOUBLE_EQ(seen[i].t, truth[i - 5].t);
    EXPECT_EQ(seen[i].position, truth[i - 5].position);
  }
  EXPECT_NEAR(dropped / 7995.0, 0.25, 0.02);
}

TEST(DefectProfile, FrictionVariabilityScalesEveryMu) {
  const DefectProfile p = ParseDefectProfile(R"({"friction_variability": {"mu_scale_std": 0.1}})");
  double sum = 0, sum2 = 0;
  const int n = 4000;
  for (int trial = 0; trial < n; ++trial) {
    const double s = DrawPerturbation(p, 3, static_cast<std::uint64_t>(trial)).mu_scale;
    sum += s;
    sum2 += s * s;
  }
  EXPECT_NEAR(sum / n, 1.0, 0.01);
  EXPECT_NEAR(std::sqrt(sum2 / n - std::pow(sum / n, 2)), 0.1, 0.006);
  mechanics::Scene scene = OneFinger();
  scene.fingers[0].mu = 0.5;
  TrialPerturbation t;
  t.mu_scale = 1.2;
  EXPECT_DOUBLE_EQ(ApplyPerturbation(scene, t).fingers[0].mu, 0.6);
}

TEST(DefectProfile, CapabilitiesRefuseWithAReason) {
  const DefectProfile p = ParseDefectProfile(
      R"({"workspace": {"min": -0.05, "max": 0.05}, "contact_types": ["point"], "max_pusher_speed": 0.02})");
  mechanics::Scene s = OneFinger();
  EXPECT_EQ(CheckCapabilities(p, s), "");
  s.object.pose.position = Eigen::Vector3d(0.1, 0, 0);
  EXPECT_NE(CheckCapabilities(p, s).find("object.pose.position"), std::string::npos);
  s.object.pose.position.setZero();
  s.fingers[0].type = mechanics::ContactType::kLine;
  EXPECT_NE(CheckCapabilities(p, s).find("fingers[0].type"), std::string::npos);
  s.fingers[0].type = mechanics::ContactType::kPoint;
  s.pusher = mechanics::PusherSpec{};
  s.pusher->motion.velocity = Eigen::Vector3d(0, 0, 0.05);
  EXPECT_NE(CheckCapabilities(p, s).find("pusher.motion.velocity"), std::string::npos);
  s.pusher->motion.velocity = Eigen::Vector3d(0, 0, 0.01);
  s.duration = 10;  // 0.1 m of travel
  EXPECT_NE(CheckCapabilities(p, s).find("outside the workspace"), std::string::npos);
}

// A recorded path's velocity field is unused (zero): the speed limit and the
// travel check must read the path, or a 10 m/s path would pass any cell.
TEST(DefectProfile, CapabilitiesReadARecordedPath) {
  const DefectProfile p = ParseDefectProfile(
      R"({"workspace": {"min": -0.05, "max": 0.05}, "contact_types": ["point"], "max_pusher_speed": 0.02})");
  mechanics::Scene s = OneFinger();
  s.pusher = mechanics::PusherSpec{};
  mechanics::PusherPath path;
  path.t = {0, 0.5, 1.0};
  path.position = {{0, 0, 0}, {0, 0, 0.005}, {0, 0, 0.010}};  // 10 mm/s
  s.pusher->path = path;
  s.duration = 1;
  EXPECT_EQ(CheckCapabilities(p, s), "");
  s.pusher->path->position[2] = {0, 0, 0.030};  // its last segment at 50 mm/s
  EXPECT_NE(CheckCapabilities(p, s).find("pusher.motion.path: 0.05"), std::string::npos)
      << CheckCapabilities(p, s);
  // Out of the workspace half way and back: the end alone would pass.
  s.pusher->path->t = {0, 5, 10};
  s.pusher->path->position = {{0, 0, 0}, {0, 0, 0.08}, {0, 0, 0}};
  s.duration = 10;
  const std::string why = CheckCapabilities(p, s);
  EXPECT_NE(why.find("pusher.motion.path"), std::string::npos) << why;
  EXPECT_NE(why.find("outside the workspace"), std::string::npos) << why;
}

TEST(DefectProfile, ActuationErrorAndPusherStateFollowARecordedPath) {
  mechanics::Scene s = OneFinger();
  s.pusher = mechanics::PusherSpec{};
  s.pusher->position = {0, 0, 0.001};
  mechanics::PusherPath path;
  path.t = {0, 0.5, 1.0};
  path.position = {{0, 0, 0.001}, {0, 0, 0.006}, {0, 0.002, 0.006}};
  s.pusher->path = path;
  TrialPerturbation t;
  t.velocity_scale = 2;
  t.velocity_offset = {0.001, 0, 0};
  const mechanics::Scene a = ApplyPerturbation(s, t);
  ASSERT_TRUE(a.pusher->path);
  EXPECT_EQ(a.pusher->path->position[0], Eigen::Vector3d(0, 0, 0.001));  // the start stays
  EXPECT_NEAR((a.pusher->path->position[1] - Eigen::Vector3d(0.0005, 0, 0.011)).norm(), 0, 1e-15);
  EXPECT_NEAR((a.pusher->path->position[2] - Eigen::Vector3d(0.001, 0.004, 0.011)).norm(), 0,
              1e-15);
  mechanics::TrajectorySample sample;
  sample.t = 0.25;
  EXPECT_NEAR((PusherAt(s, sample).velocity - Eigen::Vector3d(0, 0, 0.01)).norm(), 0, 1e-12);
  sample.t = 0.75;
  EXPECT_NEAR((PusherAt(s, sample).velocity - Eigen::Vector3d(0, 0.004, 0)).norm(), 0, 1e-12);
  sample.t = 2;  // at rest after the path
  EXPECT_NEAR(PusherAt(s, sample).velocity.norm(), 0, 1e-15);
}

}  // namespace
}  // namespace arena::executors
