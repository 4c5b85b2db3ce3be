// The smoke campaign (a small version: one replicate, 12 trials) end to end
// with `arena run` on every backend: model (self-consistency), mujoco (an
// independent engine), then the mujoco run's export, in every format `arena
// export` writes (hdf5, csv, jsonl), served back as recorded data through
// replay:DIR, and through exec:examples/drivers/replay.py (which crashes once
// mid-trial, after streaming part of it: the trial is retried, never kept
// half). Every run finishes every trial, its summary names the truth it
// measured against, and a recorded run's truth is the mujoco run's, trial by
// trial; every trial records its backend, truth and applied defects. A
// damaged HDF5 export (truncated, a stream missing, a stream of the wrong
// type) stops `arena cell` at start with the file and the reason.
#include <hdf5.h>

#include <algorithm>
#include <filesystem>
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
  // Every trial's ground truth in short (its summary: samples, final pose,
  // largest forces, contact-mode fractions, 9 significant digits), by idx.
  std::string TruthOf(const std::string& db) {
    const auto r = Arena(
        "query --db " + dir_ + "/" + db +
        " --format csv \"select t.idx, s.samples, printf('%.9g %.9g %.9g %.9g %.9g %.9g %.9g', "
        "s.final_x, s.final_y, s.final_z, s.final_qw, s.final_qx, s.final_qy, s.final_qz), "
        "printf('%.9g %.9g %.9g %.9g %.9g', s.max_contact_force_n, s.max_pusher_force_n, "
        "s.stick_fraction, s.slide_fraction, s.separate_fraction) from trials t join gt_summary "
        "s on s.stream_id = t.gt_stream_id order by t.idx\"");
    EXPECT_EQ(r.rc, 0) << r.err;
    return r.out;
  }
  // `arena cell` on a damaged copy of an HDF5 export: its error output.
  std::string CellOnDamaged(const std::string& data, const std::string& damage) {
    namespace fs = std::filesystem;
    const std::string copy = dir_ + "/damaged-" + damage;
    fs::copy(data, copy, fs::copy_options::recursive);
    const std::string h5 = copy + "/dataset.h5";
    if (damage == "truncated") {
      fs::resize_file(h5, fs::file_size(h5) * 2 / 3);
    } else {
      H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
      const hid_t f = H5Fopen(h5.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
      EXPECT_GE(f, 0);
      EXPECT_GE(H5Ldelete(f, "/trials/3/true", H5P_DEFAULT), 0);
      if (damage == "integers") {  // a stream of the wrong type in its place
        const hsize_t dims[2] = {4, 3};
        const int values[12] = {};
        const hid_t space = H5Screate_simple(2, dims, nullptr);
        const hid_t ds = H5Dcreate2(f, "/trials/3/true", H5T_STD_I32LE, space, H5P_DEFAULT,
                                    H5P_DEFAULT, H5P_DEFAULT);
        H5Dwrite(ds, H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, values);
        H5Dclose(ds);
        H5Sclose(space);
      }
      H5Fclose(f);
    }
    const auto r = Arena("cell --id broken --domain 7 --backend 'replay:" + copy + "'");
    EXPECT_EQ(r.rc, 2) << damage << ": " << r.err;
    return r.err;
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

  // The recorded run served back from every format `arena export` writes.
  const std::string recorded = TruthOf("mujoco.db");
  ASSERT_EQ(std::count(recorded.begin(), recorded.end(), '\n'), 13) << recorded;  // header + 12
  for (const std::string format : {"hdf5", "csv", "jsonl"}) {
    SCOPED_TRACE("export format " + format);
    const std::string data = dir_ + "/data-" + format, db = "replay-" + format + ".db";
    const auto exported = Arena("export --db " + dir_ + "/mujoco.db --campaign 1 --format " +
                                format + " --no-predictions --out " + data);
    ASSERT_EQ(exported.rc, 0) << exported.err;
    auto replay = Run(sensing, db, "replay:" + data);
    ASSERT_EQ(replay.rc, 0) << replay.out << replay.err;
    EXPECT_NE(replay.out.find("12 done, 0 failed"), std::string::npos) << replay.out;
    EXPECT_NE(replay.out.find("recorded data"), std::string::npos) << replay.out;
    EXPECT_NE(Truths(db).find("recorded|replay:"), std::string::npos);
    EXPECT_EQ(TruthOf(db), recorded);
  }

  // A damaged HDF5 export: the cell does not start; the file and the reason are named.
  const std::string truncated = CellOnDamaged(dir_ + "/data-hdf5", "truncated");
  EXPECT_NE(truncated.find("damaged-truncated/dataset.h5: "), std::string::npos) << truncated;
  EXPECT_NE(truncated.find("truncated file"), std::string::npos) << truncated;
  EXPECT_NE(CellOnDamaged(dir_ + "/data-hdf5", "missing")
                .find("damaged-missing/dataset.h5: /trials/3/true: missing"),
            std::string::npos);
  EXPECT_NE(CellOnDamaged(dir_ + "/data-hdf5", "integers")
                .find("/trials/3/true: holds 32-bit integers, expected 64-bit floats"),
            std::string::npos);

  // The reference driver crashes once, mid-trial, after its first samples
  // were streamed: that attempt fails, the retry serves the trial whole.
  auto exec = Run(sensing, "exec.db",
                  "exec:python3 " + std::string(ARENA_SOURCE_DIR) + "/examples/drivers/replay.py " +
                      dir_ + "/data-jsonl --fail-mode crash --fail-once " + dir_ + "/crashed");
  ASSERT_EQ(exec.rc, 0) << exec.out << exec.err;
  EXPECT_NE(exec.out.find("12 done, 0 failed"), std::string::npos) << exec.out;
  EXPECT_NE(exec.out.find("recorded data (exec:"), std::string::npos) << exec.out;
  const auto retried = Arena("query --db " + dir_ +
                             "/exec.db --format csv \"select count(*) from trials where attempt "
                             "> 1\"");
  EXPECT_NE(retried.out.find("\n1"), std::string::npos) << retried.out;
  EXPECT_EQ(TruthOf("exec.db"), recorded);
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
