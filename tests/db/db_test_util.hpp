// Shared fixtures for the store tests: a fresh directory per test, real files.
#pragma once

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <unistd.h>

#include "arena/db/store.hpp"

namespace arena::db::testing {

inline std::string SceneJson(double grip_force = 10.0, const std::string& finger = "point",
                             double mu = 0.5, double x0 = 0.0) {
  return R"({"object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2,
              "pose": {"position": [)" +
         std::to_string(x0) + R"(, 0, 0], "rpy": [0, 0, 0]}},
     "gravity": [0, 0, -9.81], "duration": 1.0, "grip_force": )" +
         std::to_string(grip_force) + R"(,
     "fingers": [
       {"name": "left",  "type": ")" +
         finger + R"(", "position": [-0.025, 0, 0], "normal": [1, 0, 0],
        "axis": [0, 0, 1], "length": 0.02, "radius": 0.01, "mu": )" +
         std::to_string(mu) + R"(},
       {"name": "right", "type": ")" +
         finger + R"(", "position": [0.025, 0, 0], "normal": [-1, 0, 0],
        "axis": [0, 0, 1], "length": 0.02, "radius": 0.01, "mu": )" +
         std::to_string(mu) + R"(}],
     "pusher": {"type": "point", "position": [0, 0, -0.05], "normal": [0, 0, 1], "mu": 0.3,
                "motion": {"velocity": [0, 0, 0.01], "angular_velocity": [0, 0, 0]}}})";
}

// The contacts of SceneJson (fingers left, right; the pusher), as the
// caller hands them to the store (db reads no scene).
inline std::vector<ContactSite> SceneSites() {
  return {{"left", false, {-0.025, 0, 0}, {1, 0, 0}, true},
          {"right", false, {0.025, 0, 0}, {-1, 0, 0}, true},
          {"pusher", true, {0, 0, -0.05}, {0, 0, 1}, true}};
}

// What the caller (orchestrator::SceneFactsOf) computes of SceneJson(...).
inline SceneFacts SceneFactsFor(double grip_force = 10.0, const std::string& finger = "point",
                                double mu = 0.5, double x0 = 0.0) {
  SceneFacts f;
  f.object_shape = "box";
  f.object_mass = 0.2;
  f.grip_force = grip_force;
  f.finger_type = finger;
  f.finger_count = 2;
  f.finger_mu = mu;
  f.pusher_type = "point";
  f.pusher_mu = 0.3;
  f.pusher_speed = 0.01;
  f.pusher_angular_speed = 0.0;
  f.duration = 1.0;
  f.contact_mask = kPointBit | (finger == "line" ? kLineBit : finger == "patch" ? kPatchBit : 0);
  f.nominal = {x0, 0, 0, 1, 0, 0, 0};
  f.contacts = SceneSites();
  return f;
}

inline std::vector<PlannedTrial> MakeTrials(int n, const std::string& finger = "point") {
  std::vector<PlannedTrial> out;
  for (int i = 0; i < n; ++i) {
    PlannedTrial t;
    t.condition = i / 2;
    t.replicate = i % 2;
    t.seed = 1000u + static_cast<unsigned>(i);
    t.scene_json = SceneJson(5.0 + i, finger, 0.3 + 0.01 * i);
    t.facts = SceneFactsFor(5.0 + i, finger, 0.3 + 0.01 * i);
    t.params_json = R"({"grip_force": )" + std::to_string(5.0 + i) + "}";
    out.push_back(t);
  }
  return out;
}

inline NewCampaign MakeCampaign(const std::string& name = "c", int priority = 0) {
  NewCampaign c;
  c.name = name;
  c.spec_json = R"({"name": ")" + name + R"(", "trials": 4})";
  c.priority = priority;
  c.seed = 42;
  return c;
}

// Sample i of a synthetic trajectory: pure functions of i, so any reader can check it.
inline Sample MakeSample(int i, int contacts = 3) {
  Sample s;
  s.t = i / 250.0;
  s.object_pose = {0.001 * i, 0.0, 0.0, 1, 0, 0, 0};
  s.object_twist = {0.25, 0, 0, 0, 0, 0.01 * i};
  s.pusher_pose = {0, 0, -0.05 + 0.00004 * i, 1, 0, 0, 0};
  s.pusher_twist = {0, 0, 0.01, 0, 0, 0};
  for (int c = 0; c < contacts; ++c) {
    ContactWrench w;
    w.force = {1.0 * c, 0.5, 10.0 + i};
    w.torque = {0, 0.001 * c, 0};
    w.mode = static_cast<ContactMode>((i + c) % 3);
    s.contacts.push_back(w);
  }
  s.observed_valid = (i % 7) != 3;
  s.observed_object_pose = s.object_pose;
  s.observed_object_pose[0] += 0.0005;
  s.observed_pusher_wrench = {0, 0, 10.0 + i, 0, 0, 0};
  s.observed_finger_wrenches.assign(12, 0.1 * i);
  return s;
}

class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::temp_directory_path() /
            ("arena_db_" + std::to_string(::getpid()) + "_" + (info ? info->name() : "x") + "_" +
             std::to_string(counter++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string File(const std::string& name) const { return (path_ / name).string(); }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// SQL that takes a current file back to schema version 4 (undoes migration 5),
// for tests that make an "older" store and open it again.
inline constexpr const char* kUndoMigration5 =
    " DROP TABLE store_meta; DROP TABLE services; DROP TABLE cell_events;"
    " ALTER TABLE cells DROP COLUMN lease_s; ALTER TABLE cells DROP COLUMN serving;"
    " ALTER TABLE trials DROP COLUMN service_restarts;";
// Undoes migration 10 (trials.backend, truth, defects_applied).
inline constexpr const char* kUndoMigration10 =
    " ALTER TABLE trials DROP COLUMN backend; ALTER TABLE trials DROP COLUMN truth;"
    " ALTER TABLE trials DROP COLUMN defects_applied;";
// Undoes migration 14 (cells.start_for_trial).
inline constexpr const char* kUndoMigration14 = " ALTER TABLE cells DROP COLUMN start_for_trial;";
// Undoes migration 15 (trial_transitions.rule).
inline constexpr const char* kUndoMigration15 = " ALTER TABLE trial_transitions DROP COLUMN rule;";

// SQL that takes a store back from schema version 6 to 5 (outcomes and
// parameter views out). Migration 6 also re-applies over a file that kept
// them, so a test that only sets user_version back still migrates.
inline constexpr const char* kUndoMigration6 =
    " DROP VIEW trial_results; DROP VIEW contact_results;"
    " DROP TABLE contact_outcomes; DROP TABLE campaign_parameters;"
    " ALTER TABLE gt_summary DROP COLUMN net_dx; ALTER TABLE gt_summary DROP COLUMN net_dy;"
    " ALTER TABLE gt_summary DROP COLUMN net_dz; ALTER TABLE gt_summary DROP COLUMN net_rx;"
    " ALTER TABLE gt_summary DROP COLUMN net_ry; ALTER TABLE gt_summary DROP COLUMN net_rz;"
    " ALTER TABLE gt_summary DROP COLUMN grasp_kept;";

// The same for migration 7 (adaptive samplers' decisions, calibrations).
inline constexpr const char* kUndoMigration7 =
    " DROP VIEW trial_decisions; DROP TABLE sampler_decisions; DROP TABLE calibrations;"
    " ALTER TABLE campaigns DROP COLUMN sampler_open;";

// Runs one trial through the whole state machine with n samples.
inline void RunTrialToDone(Store& store, const ClaimedTrial& t, int n,
                           const IngestOptions& options = {}) {
  auto ingest = store.BeginIngest(t.trial_id, t.attempt, SceneSites(), options);
  for (int i = 0; i < n; ++i) ingest->Add(MakeSample(i));
  ingest->Finish();
  store.BeginReset(t.trial_id, t.attempt);
  ResetReport r;
  r.ok = true;
  r.observed_pose = {0.002, -0.001, 0, 1, 0, 0, 0};
  store.CompleteReset(t.trial_id, t.attempt, r);
  Prediction p;
  p.model_key = "g8_k3";
  p.final_position_error = 0.001;
  p.final_angle_error = 0.01;
  p.force_error = 0.2;
  p.mode_agreement = 0.9;
  p.wall_s = 0.003;
  store.RecordPrediction(t.trial_id, t.attempt, p);
  store.FinishTrial(t.trial_id, t.attempt);
}

}  // namespace arena::db::testing
