// A week in a test (issue 29): one campaign whose trials add up to 7 days of
// a lab's time, on three simulated cells at --speed 0, with every fault a
// week brings: resets that fail (cell c_reset), sensors that drop samples and
// resets that place the object off its start (c_drop), a cell killed and
// started again (c_main), a disk that fills (a real tmpfs, filled with a
// ballast file and emptied again) and another process holding the store's
// write lock. Every suspension fires and lifts by itself, `arena resume`
// lifts one at once, the reset condition is set aside after its budget (the
// cell quarantined) and the campaign goes on; every trial ends done or failed
// with a reason, nothing is lost or duplicated, the events reach --notify,
// and the service's memory stays flat.
//
// The week: a trial is a 0.4 s push; a lab's reset between two trials is a
// release and a regrasp of 120 s each (the cells' defect profiles say so,
// `reset.grasp_time`), so one trial takes 240.4 s of a lab's time and
// 7 days are ceil(604800 / 240.4) = 2516 trials: 12 conditions x 210
// replicates = 2520.
#include <sys/mount.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>

#include <nlohmann/json.hpp>

#include "service_support.hpp"

namespace arena::test {
namespace {

using namespace std::chrono_literals;

constexpr double kPushS = 0.4;
constexpr double kGraspS = 120.0;
constexpr int kConditions = 12;  // 3 finger types x 2 grip forces x 2 pivot offsets

int ReplicatesForAWeek() {
  const double cycle = kPushS + 2 * kGraspS;
  const int trials = static_cast<int>(std::ceil(7 * 86400.0 / cycle));
  return (trials + kConditions - 1) / kConditions;
}

std::string Campaign(int replicates) {
  nlohmann::json c = nlohmann::json::parse(R"({
    "name": "week",
    "seed": 29,
    "scene": {
      "object": {"shape": "box", "size": [0.05, 0.03, 0.10], "mass": 0.2},
      "gravity": [0, 0, -9.81], "duration": 0.4, "grip_force": 10.0,
      "fingers": [
        {"name": "left",  "type": "point", "position": [-0.025, 0, 0], "normal": [1, 0, 0],  "mu": 0.5},
        {"name": "right", "type": "point", "position": [0.025, 0, 0],  "normal": [-1, 0, 0], "mu": 0.5}],
      "pusher": {"type": "point", "position": [0, 0, -0.05], "normal": [0, 0, 1], "mu": 0.3,
                 "motion": {"velocity": [0, 0, 0.02], "angular_velocity": [0, 0, 0]}},
      "model": {"facets": 4, "points": 3, "dt": 0.008, "reduce": "auto"}},
    "variations": {
      "finger_type": {"choices": ["point", "line", "patch"]}, "finger_length": 0.02,
      "finger_radius": 0.005, "grip_force": {"min": 8, "max": 12, "levels": 2},
      "pivot_offset": {"choices": [0, 0.01]}, "push_speed": 0.02, "push_distance": 0.008},
    "sampler": "grid",
    "prediction": {"facets": 4, "points": 3, "dt": 0.008, "reduce": "auto"}})");
  c["replicates"] = replicates;
  return c.dump(2);
}

double FreeBytes(const std::string& dir) {
  struct statvfs v {};
  if (::statvfs(dir.c_str(), &v) != 0) return -1;
  return static_cast<double>(v.f_bavail) * static_cast<double>(v.f_frsize);
}

long RssKiB(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
  return -1;
}

// A real small disk for the store; unmounted (lazily) at the end.
struct Tmpfs {
  std::string path;
  bool mounted = false;
  Tmpfs(const std::string& at, const std::string& size) : path(at) {
    std::filesystem::create_directories(at);
    mounted = ::mount("tmpfs", at.c_str(), "tmpfs", 0, ("size=" + size).c_str()) == 0;
  }
  ~Tmpfs() {
    if (mounted) ::umount2(path.c_str(), MNT_DETACH);
  }
};

std::vector<db::Suspension> Suspensions(const std::string& db, bool active_only) {
  return OpenReadOnly(db)->ListSuspensions(active_only);
}

bool ActiveNow(const std::string& db, const std::string& condition, const std::string& cell = "") {
  for (const auto& s : Suspensions(db, true))
    if (s.condition == condition && (cell.empty() || s.cell_id == cell)) return true;
  return false;
}

// Fired and lifted by its own rule (not by `arena resume`).
bool FiredAndLiftedByRule(const std::string& db, const std::string& condition) {
  for (const auto& s : Suspensions(db, false))
    if (s.condition == condition && s.lifted_at && s.lifted_by != "arena resume") return true;
  return false;
}

int Finished(const std::string& db) {
  auto c = CountStates(db, 1);
  return c["done"] + c["failed"];
}

TEST(WeekSoak, AWeekOfTrialsWithEveryFaultEndsWithEveryTrialAccountedFor) {
  TempDir dir;
  Tmpfs disk(dir / "disk", "512m");
  if (!disk.mounted)
    GTEST_SKIP() << "cannot mount a tmpfs for the filling disk (needs CAP_SYS_ADMIN): "
                 << std::strerror(errno);
  const std::string db = disk.path + "/week.db";
  const std::string domain = std::to_string(TestDomain(29));
  const int replicates = ReplicatesForAWeek();
  const int trials = kConditions * replicates;
  ASSERT_GE(trials * (kPushS + 2 * kGraspS), 7 * 86400.0);
  // docs/operations.md quotes the week's size.
  EXPECT_NE(ReadFile(std::string(ARENA_SOURCE_DIR) + "/docs/operations.md")
                .find(std::to_string(trials) + " trials of a 0.4 s push"),
            std::string::npos);
  {
    std::ofstream(dir / "week.json") << Campaign(replicates);
    const std::string grasp = std::to_string(kGraspS);
    std::ofstream(dir / "main.json") << R"({"reset": {"grasp_time": )" << grasp << "}}";
    std::ofstream(dir / "reset.json")
        << R"({"reset": {"failure_probability": 1.0, "max_attempts": 1, "grasp_time": )" << grasp
        << "}}";
    std::ofstream(dir / "drop.json")
        << R"({"drop_probability": 0.5, "reset": {"placement_position_std": 0.004,
              "position_tolerance": 0.05, "grasp_time": )"
        << grasp << "}}";
    // Short holds (a week in minutes); the free-space threshold is the tmpfs's edge.
    std::ofstream(dir / "suspenders.json") << R"({
      "reset_failure_rate": {"threshold": 0.5, "window": 6, "min_evidence": 4, "hold_s": 2, "budget": 2},
      "start_pose_drift":   {"threshold": 0.002, "window": 4, "min_evidence": 3, "hold_s": 2, "budget": 100000},
      "sample_drop_rate":   {"threshold": 0.2, "window": 4, "min_evidence": 3, "hold_s": 2, "budget": 100000},
      "cell_silence":       {"threshold": 1, "hold_s": 2, "budget": 100},
      "store_free_space":   {"threshold": 67108864, "hold_s": 2}})";
  }
  ASSERT_EQ(RunArena({"submit", dir / "week.json", "--db", db}, dir / "submit.out", 120s), 0)
      << ReadFile(dir / "submit.out");
  auto cell = [&](const std::string& id, const std::string& defects, const std::string& log) {
    return StartArena(
        {"cell", "--id", id, "--domain", domain, "--speed", "0", "--defects", dir / defects},
        dir / log);
  };
  auto c_main = cell("c_main", "main.json", "c_main.log");
  auto c_reset = cell("c_reset", "reset.json", "c_reset.log");
  auto c_drop = cell("c_drop", "drop.json", "c_drop.log");
  auto serve =
      StartArena({"serve", "--db", db, "--domain", domain, "--suspenders", dir / "suspenders.json",
                  "--quarantine-after", "1000000", "--cell-backoff-max", "0.5", "--max-attempts",
                  "5", "--notify", "cat >> " + dir / "events.jsonl", "--notify-timeout", "5"},
                 dir / "serve.out");
  const auto progress = [&] { return Finished(db); };
  const auto stall = 90s;  // a stuck service fails within this
  const auto cap = 900s;
  std::vector<std::pair<int, long>> rss;  // (finished trials, KiB)
  auto sample_rss = [&] { rss.emplace_back(Finished(db), RssKiB(serve->pid())); };
  auto wait_for = [&](const std::function<bool()>& done, const char* what) {
    const bool ok = WaitWhileProgressing(
        [&] {
          if (rss.empty() || Finished(db) >= rss.back().first + trials / 40) sample_rss();
          return done();
        },
        progress, stall, cap);
    EXPECT_TRUE(ok) << what << "\n" << ReadFile(dir / "serve.out").substr(0, 4000);
    return ok;
  };

  // 1. Resets failing on c_reset: suspended, lifted, twice; then set aside (quarantined).
  // 2. Drops and drift on c_drop: suspended and lifted again and again.
  ASSERT_TRUE(wait_for([&] { return ActiveNow(db, "sample_drop_rate", "c_drop"); },
                       "c_drop's dropped samples never suspended it"));
  // `arena resume` lifts it at once (the operator's override).
  ASSERT_EQ(RunArena({"status", "--db", db}, dir / "status.out", 60s), 0);
  EXPECT_NE(ReadFile(dir / "status.out").find("sample_drop_rate"), std::string::npos)
      << ReadFile(dir / "status.out");
  ASSERT_EQ(RunArena({"resume", "1", "--cell", "c_drop", "--db", db}, dir / "resume.out", 60s), 0)
      << ReadFile(dir / "resume.out");
  EXPECT_NE(ReadFile(dir / "resume.out").find("lifted: sample_drop_rate"), std::string::npos)
      << ReadFile(dir / "resume.out");
  ASSERT_TRUE(wait_for(
      [&] { return OpenReadOnly(db)->GetCell("c_reset").state == db::CellState::kQuarantined; },
      "c_reset's reset condition was never set aside"));
  ASSERT_TRUE(wait_for([&] { return Finished(db) >= trials / 5; }, "a fifth of the week"));

  // 3. c_main dies and comes back: its silence suspends it until it is back for the hold.
  c_main.reset();  // SIGKILL
  ASSERT_TRUE(wait_for([&] { return ActiveNow(db, "cell_silence", "c_main"); },
                       "the killed cell's silence never suspended it"));
  c_main = cell("c_main", "main.json", "c_main2.log");
  ASSERT_TRUE(wait_for([&] { return FiredAndLiftedByRule(db, "cell_silence"); },
                       "the cell came back but its suspension was never lifted"));
  ASSERT_TRUE(wait_for([&] { return Finished(db) >= trials / 2; }, "half of the week"));

  // 4. The disk fills: every cell is held back until there is room again.
  const double free_before = FreeBytes(disk.path);
  ASSERT_GT(free_before, 128.0 * 1024 * 1024) << "the store grew more than expected";
  {
    std::ofstream ballast(disk.path + "/ballast", std::ios::binary);
    const std::string mib(1 << 20, '\0');
    const auto mibs = static_cast<long>((free_before - 40.0 * 1024 * 1024) / (1 << 20));
    for (long i = 0; i < mibs; ++i) ballast.write(mib.data(), mib.size());
  }
  ASSERT_TRUE(WaitUntil([&] { return ActiveNow(db, "store_free_space"); }, 30s))
      << "free space " << FreeBytes(disk.path) << " never suspended dispatch";
  std::this_thread::sleep_for(3s);
  std::filesystem::remove(disk.path + "/ballast");
  ASSERT_TRUE(wait_for([&] { return FiredAndLiftedByRule(db, "store_free_space"); },
                       "the disk has room again but dispatch stayed suspended"));

  // 5. Another process holds the store's write lock for 4 s.
  {
    std::ofstream(dir / "lock.py") << "import sqlite3, sys, time\n"
                                      "c = sqlite3.connect(sys.argv[1], isolation_level=None, "
                                      "timeout=30)\n"
                                      "c.execute('BEGIN IMMEDIATE')\n"
                                      "print('locked', flush=True)\n"
                                      "time.sleep(4)\n"
                                      "c.execute('ROLLBACK')\n";
  }
  Child lock({"/usr/bin/python3", dir / "lock.py", db}, dir / "lock.out");
  ASSERT_TRUE(lock.Wait(60s).has_value());
  EXPECT_NE(ReadFile(dir / "lock.out").find("locked"), std::string::npos)
      << ReadFile(dir / "lock.out");

  // The rest of the week (the lock met a write of the service, a trial step
  // or a claim: the test proves something).
  EXPECT_TRUE(WaitUntil(
      [&] {
        const std::string log = ReadFile(dir / "serve.out");
        return log.find("another process holds the write lock") != std::string::npos ||
               log.find("database is locked") != std::string::npos;
      },
      10s))
      << "no write of the service met the foreign lock";
  ASSERT_TRUE(wait_for([&] { return Finished(db) == trials; }, "the week never ended"));
  ASSERT_TRUE(WaitUntil(
      [&] { return OpenReadOnly(db)->GetCampaign(1).state == db::CampaignState::kDone; }, 30s));
  std::this_thread::sleep_for(2s);  // the watch's next pass tells campaign_done
  sample_rss();
  serve->Signal(SIGTERM);
  ASSERT_TRUE(serve->Wait(60s).has_value());

  // Every trial ended once, done or failed with a reason; the file is intact.
  ExpectCampaignConsistent(db, 1, trials);
  auto store = OpenReadOnly(db);
  int done = 0, failed = 0;
  for (const auto& t : store->ListTrials(1)) {
    if (t.state == db::TrialState::kDone) {
      ++done;
    } else {
      ++failed;
      ASSERT_EQ(t.state, db::TrialState::kFailed);
      const auto rows = store->ListTransitions(t.id);
      EXPECT_FALSE(rows.back().reason.empty()) << "trial " << t.id << " failed without a reason";
    }
  }
  EXPECT_EQ(done + failed, trials);
  // While a suspension held, no trial was dispatched to what it held back
  // (a trial's last dispatch; 0.5 s for the claim of the tick that fired it).
  const auto all_trials = store->ListTrials(1);
  for (const auto& s : store->ListSuspensions(false, 1000000)) {
    if (s.scope == "campaign") continue;
    const double until = s.lifted_at.value_or(1e300);
    for (const auto& t : all_trials)
      if (t.dispatched_at && *t.dispatched_at > s.fired_at + 0.5 && *t.dispatched_at < until &&
          (s.scope == "service" || t.cell_id == s.cell_id))
        ADD_FAILURE() << "trial " << t.id << " dispatched to " << t.cell_id << " at "
                      << *t.dispatched_at << " while " << s.condition << " held (" << s.fired_at
                      << " .. " << until << ")";
  }
  // Every condition the week brought fired and was lifted by its own rule.
  for (const char* c : {"reset_failure_rate", "sample_drop_rate", "start_pose_drift",
                        "cell_silence", "store_free_space"})
    EXPECT_TRUE(FiredAndLiftedByRule(db, c)) << c;
  bool resumed = false;
  for (const auto& s : store->ListSuspensions(false))
    resumed = resumed || (s.condition == "sample_drop_rate" && s.lifted_by == "arena resume");
  EXPECT_TRUE(resumed) << "`arena resume` did not lift c_drop's suspension";
  EXPECT_TRUE(store->ListSuspensions(true).empty() ||
              std::all_of(store->ListSuspensions(true).begin(), store->ListSuspensions(true).end(),
                          [](const db::Suspension& s) { return s.cell_id == "c_drop"; }))
      << "a suspension other than the faulty c_drop's still holds at the end";
  EXPECT_EQ(store->GetCell("c_reset").state, db::CellState::kQuarantined);
  EXPECT_NE(store->GetCell("c_reset").quarantine_reason.find("set aside: reset_failure_rate"),
            std::string::npos)
      << store->GetCell("c_reset").quarantine_reason;
  // The operator was told: each kind of event is in the store and reached --notify.
  std::set<std::string> stored, notified;
  for (const auto& e : store->ListEvents(0, 1000000)) stored.insert(e.kind);
  {
    std::ifstream in(dir / "events.jsonl");
    std::string line;
    while (std::getline(in, line)) {
      const auto j = nlohmann::json::parse(line, nullptr, false);
      ASSERT_FALSE(j.is_discarded()) << "not one JSON object per line: " << line;
      notified.insert(j["event"].get<std::string>());
    }
  }
  for (const char* kind : {"suspension_fired", "suspension_lifted", "condition_set_aside",
                           "cell_gone", "cell_back", "campaign_done"}) {
    EXPECT_TRUE(stored.count(kind)) << kind << " not in service_events";
    EXPECT_TRUE(notified.count(kind)) << kind << " never reached --notify";
  }
  // Memory flat: the service's RSS over the second half of the week grew by
  // less than 16 MiB (a leak per trial would show: 1,260 trials).
  std::vector<std::pair<int, long>> second_half;
  for (const auto& p : rss)
    if (p.first >= trials / 2 && p.second > 0) second_half.push_back(p);
  ASSERT_GE(second_half.size(), 2u);
  const long growth = second_half.back().second - second_half.front().second;
  std::string trace;
  for (const auto& [n, kib] : rss) trace += std::to_string(n) + ":" + std::to_string(kib) + " ";
  EXPECT_LT(growth, 16 * 1024) << "RSS (finished trials:KiB) " << trace;
  std::printf("[week] %d trials (%d done, %d failed), %zu suspensions, RSS trace %s\n", trials,
              done, failed, store->ListSuspensions(false).size(), trace.c_str());
  std::fflush(stdout);
}

}  // namespace
}  // namespace arena::test
