// The smoke campaign (a small version: one replicate, 12 trials) end to end
// with `arena run` on every backend: model (self-consistency), mujoco (an
// independent engine), then the mujoco run's export served back as recorded
// data through replay:DIR and through exec:examples/drivers/replay.py. Every
// run finishes every trial and its summary names the truth it measured
// against; every trial records its backend, truth and applied defects.
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arena_command_test.hpp"

namespace arena::test {
namespace {

using nlohmann::json;

class BackendsE2e : public ArenaCommandTest {
 protected:
  // The smoke campaign with one replicate; `physical` false drops the defects
  // that perturb the physics (recorded data cannot apply them: refused).
  std::string Campaign(const std::string& name, bool physical) {
    json c = json::parse(
        std::ifstream(std::string(ARENA_SOURCE_DIR) + "/examples/campaigns/smoke.json"));
    c["replicates"] = 1;
    if (!physical) c["defects"].erase("friction_variability");
    const std::string path = dir_ + "/" + name + ".json";
    std::ofstream(path) << c.dump(2);
    return path;
  }
  CommandResult Run(const std::string& campaign, const std::string& db,
                    const std::string& backend) {
    return Arena("run " + campaign + " --db " + dir_ + "/" + db + " --quiet --backend '" + backend +
                 "'");
  }
  // "truth|backend|has defects_applied" of every trial.
  std::string Truths(const std::string& db) {
    const auto r = Arena("query --db " + dir_ + "/" + db +
                         " --format csv \"select truth || '|' || backend || '|' || "
                         "(defects_applied is not null) as k, count(*) from trials group by k\"");
    EXPECT_EQ(r.rc, 0) << r.err;
    return r.out;
  }
};

TEST_F(BackendsE2e, SmokeCampaignOnEveryBackend) {
  const std::string full = Campaign("smoke", true), sensing = Campaign("smoke_sensing", false);

  auto model = Run(full, "model.db", "model");
  ASSERT_EQ(model.rc, 0) << model.out << model.err;
  EXPECT_NE(model.out.find("12 done, 0 failed"), std::string::npos) << model.out;
  EXPECT_NE(model.out.find("self-consistency"), std::string::npos) << model.out;
  EXPECT_NE(Truths("model.db").find("self-consistency|model|1,12"), std::string::npos);

  auto mujoco = Run(full, "mujoco.db", "mujoco");
  ASSERT_EQ(mujoco.rc, 0) << mujoco.out << mujoco.err;
  EXPECT_NE(mujoco.out.find("12 done, 0 failed"), std::string::npos) << mujoco.out;
  EXPECT_NE(mujoco.out.find("model error is against MuJoCo (an independent engine), 12 trials"),
            std::string::npos)
      << mujoco.out;
  EXPECT_EQ(mujoco.out.find("self-consistency"), std::string::npos) << mujoco.out;
  EXPECT_NE(Truths("mujoco.db").find("simulator|mujoco|1,12"), std::string::npos);
  // The campaign's friction variability reached the cell and was drawn per trial.
  const auto applied = Arena("query --db " + dir_ +
                             "/mujoco.db --format csv \"select count(distinct "
                             "json_extract(defects_applied, '$.perturbation.mu_scale')) from "
                             "trials\"");
  EXPECT_NE(applied.out.find("\n12"), std::string::npos) << applied.out;

  const auto exported = Arena("export --db " + dir_ +
                              "/mujoco.db --campaign 1 --format jsonl --out " + dir_ + "/data");
  ASSERT_EQ(exported.rc, 0) << exported.err;

  auto replay = Run(sensing, "replay.db", "replay:" + dir_ + "/data");
  ASSERT_EQ(replay.rc, 0) << replay.out << replay.err;
  EXPECT_NE(replay.out.find("12 done, 0 failed"), std::string::npos) << replay.out;
  EXPECT_NE(replay.out.find("recorded data"), std::string::npos) << replay.out;
  EXPECT_NE(Truths("replay.db").find("recorded|replay:"), std::string::npos);

  auto exec = Run(sensing, "exec.db",
                  "exec:python3 " + std::string(ARENA_SOURCE_DIR) + "/examples/drivers/replay.py " +
                      dir_ + "/data");
  ASSERT_EQ(exec.rc, 0) << exec.out << exec.err;
  EXPECT_NE(exec.out.find("12 done, 0 failed"), std::string::npos) << exec.out;
  EXPECT_NE(exec.out.find("recorded data (exec:"), std::string::npos) << exec.out;
}

TEST_F(BackendsE2e, UnknownBackendIsBadInput) {
  const auto r = Arena("cell --id c1 --domain 7 --backend bullet");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--backend: unknown backend 'bullet'"), std::string::npos) << r.err;
  const auto s =
      Arena("cell --id c1 --domain 7 --backend mujoco --backend-settings '{\"cone\": 3}'");
  EXPECT_EQ(s.rc, 2);
  EXPECT_NE(s.err.find("mujoco.cone"), std::string::npos) << s.err;
}

}  // namespace
}  // namespace arena::test
