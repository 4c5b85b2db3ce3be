// probe (temporary exploration)
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>
#include <nlohmann/json.hpp>
#include "arena/orchestrator/campaign.hpp"
#include "arena/simulators/simulator.hpp"
namespace sim = arena::simulators;
int main(int argc, char** argv) {
  const std::string file = argv[1];
  if (file == "held") {
    // held box: argv[2] = finger type (point/line/patch), argv[3] = settings, argv[4] = grip
    arena::mechanics::Scene s;
    s.object.shape = arena::mechanics::ObjectShape::kBox;
    s.object.size = {0.05, 0.03, 0.10};
    s.object.mass = 0.2;
    s.gravity = {0, 0, -9.81};
    s.duration = 1.0;
    s.grip_force = argc > 4 ? std::atof(argv[4]) : 10;
    for (int i = 0; i < 2; ++i) {
      arena::mechanics::ContactSpec f;
      f.name = i ? "right" : "left";
      const std::string ty = argv[2];
      f.type = ty == "point" ? arena::mechanics::ContactType::kPoint : ty == "line" ? arena::mechanics::ContactType::kLine : arena::mechanics::ContactType::kPatch;
      f.position = {i ? 0.025 : -0.025, 0, 0};
      f.normal = {i ? -1.0 : 1.0, 0, 0};
      f.axis = {0, 0, 1};
      f.length = 0.02;
      f.radius = 0.006;
      f.mu = 0.5;
      s.fingers.push_back(f);
    }
    for (double dt : {0.001, 0.0005, 0.00025}) {
      auto j = nlohmann::json::parse(argv[3]);
      j["timestep"] = dt;
      auto r = sim::MakeSimulator("mujoco", j.dump())->Simulate(s);
      if (r.status != arena::mechanics::SimulationStatus::kOk) { std::printf("failed %s\n", r.error.c_str()); continue; }
      std::printf("held %s dt %g: z after 0.5 s %.4f mm, after 1 s %.4f mm, N %.3f\n", argv[2], dt,
                  r.samples[125].position.z() * 1e3, r.samples.back().position.z() * 1e3,
                  r.samples.back().contacts[0].normal_force);
    }
    return 0;
  }
  const int cond = std::atoi(argv[2]);
  const std::string base = argc > 3 ? argv[3] : "{}";
  const bool series = argc > 4;
  const auto c = arena::orchestrator::LoadCampaignFile(std::string(ARENA_SOURCE_DIR) + "/" + file);
  arena::mechanics::Scene scene;
  for (std::int64_t i = 0;; ++i) {
    const auto t = arena::orchestrator::PlanTrial(c, i);
    if (t.replicate == 0 && t.condition == cond) { scene = t.scene; break; }
  }
  if (std::getenv("PROBE_XML")) { std::puts(sim::MujocoModelXml(scene, {}).c_str()); return 0; }
  std::vector<double> dts = {0.001, 0.0005, 0.00025, 0.000125, 0.0000625};
  std::vector<arena::mechanics::SimulationResult> rs;
  for (double dt : dts) {
    auto j = nlohmann::json::parse(base);
    j["timestep"] = dt;
    auto r = sim::MakeSimulator("mujoco", j.dump())->Simulate(scene);
    if (r.status != arena::mechanics::SimulationStatus::kOk) { std::printf("dt %g failed %s\n", dt, r.error.c_str()); rs.push_back(r); continue; }
    const auto& f = r.samples.back();
    Eigen::AngleAxisd aa(f.orientation);
    std::printf("dt %-9g pos %.4f %.4f %.4f mm  rot %.3f mrad about %.2f %.2f %.2f  wall %.2f\n", dt,
                f.position.x() * 1e3, f.position.y() * 1e3, f.position.z() * 1e3, aa.angle() * 1e3,
                aa.axis().x(), aa.axis().y(), aa.axis().z(), r.wall_s);
    rs.push_back(r);
  }
  for (size_t k = 1; k < rs.size(); ++k) {
    if (rs[k].samples.empty() || rs[k-1].samples.empty()) continue;
    const auto &a = rs[k - 1].samples.back(), &b = rs[k].samples.back();
    std::printf("  %g vs %g: %.4f mm %.3f mrad\n", dts[k - 1], dts[k], (a.position - b.position).norm() * 1e3,
                a.orientation.angularDistance(b.orientation) * 1e3);
  }
  if (series) {
    const auto& A = rs[1].samples; const auto& B = rs[3].samples;
    for (size_t i = 0; i < A.size() && i < B.size(); i += 5) {
      Eigen::AngleAxisd aa(A[i].orientation), bb(B[i].orientation);
      std::printf("t %.3f  A y %.4f z %.4f ang %.3f | B y %.4f z %.4f ang %.3f | dpos %.4f  modes", A[i].t,
                  A[i].position.y()*1e3, A[i].position.z()*1e3, aa.angle()*1e3, B[i].position.y()*1e3,
                  B[i].position.z()*1e3, bb.angle()*1e3, (A[i].position-B[i].position).norm()*1e3);
      for (size_t k = 0; k < A[i].contacts.size(); ++k)
        std::printf(" %d/%d N%.2f/%.2f", (int)A[i].contacts[k].mode, (int)B[i].contacts[k].mode,
                    A[i].contacts[k].normal_force, B[i].contacts[k].normal_force);
      std::printf("\n");
    }
  }
}
// xml dump helper
struct XmlDump { XmlDump() { if (const char* c = std::getenv("PROBE_XML")) { (void)c; } } } g_xml_dump;
