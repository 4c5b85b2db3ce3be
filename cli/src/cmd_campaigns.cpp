// arena submit | list | status | pause | resume | cancel: campaigns in a store,
// from any process. A running `arena serve` on the same store reads it on its
// next scheduling pass (within 0.2 s).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "arena/db/store.hpp"
#include "arena/orchestrator/adaptive.hpp"
#include "arena/orchestrator/campaign.hpp"
#include "arena/orchestrator/scene_facts.hpp"
#include "arena/orchestrator/submit.hpp"
#include "boundary_report.hpp"
#include "campaign_input.hpp"
#include "commands.hpp"
#include "deadline_report.hpp"
#include "failure_reasons.hpp"
#include "progress.hpp"
#include "signals.hpp"
#include "status_cells.hpp"
#include "status_suspensions.hpp"
#include "store_errors.hpp"

namespace arena::cli {
namespace {

std::unique_ptr<db::Store> OpenStore(const std::string& path, bool read_only) {
  try {
    db::StoreOptions o;
    o.scene_facts = orchestrator::SceneFactsOfJson;  // an older store's migration reads scenes
    o.read_only = read_only;
    o.create = !read_only;
    return db::Store::Open(path, o);
  } catch (const db::StoreError& e) {
    throw CommandError(
        ExitCodeFor(e),
        std::string(e.what()) +
            (read_only ? " (is --db the store `arena serve` or `arena run` uses?)" : ""));
  }
}

// The store's suspensions, newest first (issue 29).
std::vector<db::Suspension> Suspensions(const db::Store& store) {
  return store.ListSuspensions(false, 200);
}

// A service beat within this long counts as running (it beats every second).
constexpr double kServiceRecent_s = 10.0;

// "" when a service beat recently; otherwise a warning saying so.
std::string NoServiceWarning(const db::Store& store, const std::string& db_path) {
  std::optional<db::ServiceRecord> latest;
  try {
    latest = store.LatestService();
  } catch (const db::StoreError&) {
    return "";  // an older store without the services table: say nothing
  }
  const double now = store.Now();
  if (latest && !latest->stopped_at && now - latest->last_beat <= kServiceRecent_s) return "";
  std::string last = "no service has ever run on it";
  if (latest) {
    last = "the last one (pid " + std::to_string(latest->pid) + " on " + latest->host + ") " +
           (latest->stopped_at ? "stopped " : "last beat ") +
           FormatDuration(now - latest->last_beat) + " ago";
  }
  return "no `arena serve` has a heartbeat on " + db_path + " in the last " +
         std::to_string(static_cast<int>(kServiceRecent_s)) + " s (" + last +
         "); trials wait until one runs";
}

int Submit(const std::string& campaign_path, const std::string& db_path) {
  // Before any thread. Ctrl-C (or SIGTERM) ends the submit at once, exit 130:
  // the campaign is written in one transaction, and a process that ends
  // before its commit leaves nothing of it (SQLite rolls it back, as after
  // SIGKILL); validating a big campaign can take a while, so do not wait.
  SignalWatcher signals([](int) {
    std::fputs("arena: submit interrupted; nothing was stored\n", stderr);
    std::_Exit(kExitInterrupted);
  });
  const orchestrator::Campaign campaign = LoadValidCampaign(campaign_path);
  auto store = OpenStore(db_path, false);
  {
    const std::int64_t id =
        orchestrator::SubmitCampaign(*store, campaign, [&] { return signals.received() != 0; });
    if (signals.received()) throw orchestrator::SubmitInterrupted();
    std::printf("%lld\n", static_cast<long long>(id));
    if (campaign.adaptive) {
      std::fprintf(stderr,
                   "campaign %lld '%s': adaptive %s sampler, %lld trials planned in round 0 in %s "
                   "(the service plans the next rounds from their outcomes)\n",
                   static_cast<long long>(id), campaign.name.c_str(),
                   orchestrator::ToString(campaign.adaptive->kind),
                   static_cast<long long>(store->ListTrials(id).size()), db_path.c_str());
    } else {
      std::fprintf(stderr, "campaign %lld '%s': %lld trials planned in %s\n",
                   static_cast<long long>(id), campaign.name.c_str(),
                   static_cast<long long>(orchestrator::TrialCount(campaign)), db_path.c_str());
    }
    if (const std::string w = NoServiceWarning(*store, db_path); !w.empty())
      std::fprintf(stderr, "warning: %s\n", w.c_str());
  }
  return kExitOk;
}

int List(const std::string& db_path, bool as_json) {
  auto store = OpenStore(db_path, true);
  const auto campaigns = store->ListCampaigns();
  if (as_json) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& c : campaigns)
      out.push_back({{"id", c.id},
                     {"name", c.name},
                     {"state", db::ToString(c.state)},
                     {"priority", c.priority},
                     {"created", IsoTime(c.created_at)}});
    std::printf("%s\n", out.dump().c_str());
    return kExitOk;
  }
  std::printf("%-6s %-24s %-10s %8s  %s\n", "id", "name", "state", "priority", "created");
  for (const auto& c : campaigns)
    std::printf("%-6lld %-24s %-10s %8d  %s\n", static_cast<long long>(c.id), c.name.c_str(),
                db::ToString(c.state), c.priority, IsoTime(c.created_at).c_str());
  return kExitOk;
}

// Everything `arena status` reads, once.
struct StatusView {
  db::StatusSummary summary;
  std::optional<db::ServiceRecord> service;
  std::string no_service;  // why no service runs ("" = one does)
  std::vector<CellActivity> activity;
  std::map<std::int64_t, db::CampaignWait> waits;  // the claim gate's (issue 26)
};

nlohmann::json CampaignJson(const db::Store& store, const db::CampaignStatus& c,
                            const StatusView& v) {
  nlohmann::json j = {{"id", c.id},
                      {"name", c.name},
                      {"state", db::ToString(c.state)},
                      {"planned", c.planned},
                      {"done", c.done},
                      {"failed", c.failed},
                      {"running", c.running},
                      {"awaiting_prediction", c.awaiting_prediction},
                      {"pending", c.pending},
                      {"cancelled", c.cancelled},
                      {"rate_per_hour", c.rate_per_hour}};
  j["eta_s"] = c.eta_s ? nlohmann::json(*c.eta_s) : nlohmann::json();
  j["waits"] = nullptr;
  if (auto w = v.waits.find(c.id); w != v.waits.end())
    j["waits"] = {{"kind", w->second.kind},
                  {"reason", w->second.reason},
                  {"rule", w->second.rule},
                  {"since", IsoTime(w->second.since)}};
  if (const auto a = orchestrator::ReadAdaptiveProgress(store.GetCampaign(c.id))) {
    j["adaptive"] = {{"sampler", a->sampler},   {"round", a->round},
                     {"open", a->open},         {"refining", a->refining},
                     {"progress", a->progress}, {"fraction", a->fraction}};
    if (const auto b = FindBoundary(store, c.id)) {
      nlohmann::json crossings = nlohmann::json::array();
      for (const auto& x : b->crossings) crossings.push_back({{"at", x.at}, {"half", x.half}});
      j["adaptive"]["boundary"] = {{"parameters", b->parameters},
                                   {"classes", {b->positive, b->negative}},
                                   {"classified", b->classified},
                                   {"crossings", crossings}};
    }
  }
  // What its model errors are measured against (executors/README.md, "Backends").
  j["truth"] = nlohmann::json::array();
  for (const auto& t : store.CampaignTruths(c.id))
    j["truth"].push_back({{"truth", t.truth}, {"backend", t.backend}, {"trials", t.trials}});
  j["failures"] = FailuresJson(CampaignFailures(store, c.id));
  if (const auto d = CampaignDeadlines(store, c.id); d.runs > 0)
    j["closed_loop"] = DeadlinesJson(d);
  return j;
}

void PrintStatusJson(const db::Store& store, const StatusView& v) {
  const auto& s = v.summary;
  nlohmann::json out = {{"campaigns", nlohmann::json::array()},
                        {"cells", nlohmann::json::array()},
                        {"drift", nlohmann::json::array()}};
  for (const auto& c : s.campaigns) out["campaigns"].push_back(CampaignJson(store, c, v));
  // JSON lists every cell (scripts filter); the text view folds old gone ones.
  for (size_t k = 0; k < s.cells.size(); ++k) {
    const auto& c = s.cells[k];
    const auto& a = v.activity[k];
    out["cells"].push_back(
        {{"id", c.id},
         {"state", db::ToString(c.state)},
         {"last_seen", IsoTime(c.last_seen)},
         {"consecutive_failures", c.consecutive_failures},
         {"quarantine_reason", c.quarantine_reason},
         {"serving", c.serving},
         {"backend", a.backend},
         {"phase", a.phase},
         {"trial", a.trial_id ? nlohmann::json(a.trial_id) : nlohmann::json()},
         {"in_phase_s", a.trial_id ? nlohmann::json(a.in_phase_s) : nlohmann::json()}});
  }
  out["service"] = nullptr;
  if (const auto& service = v.service) {
    out["service"] = {{"session", service->session},
                      {"pid", service->pid},
                      {"host", service->host},
                      {"domain", service->domain},
                      {"started", IsoTime(service->started_at)},
                      {"last_beat", IsoTime(service->last_beat)},
                      {"stopped", service->stopped_at ? IsoTime(*service->stopped_at) : ""},
                      {"running", v.no_service.empty()}};
  }
  for (const auto& d : s.drift)
    out["drift"].push_back({{"campaign", d.campaign_id},
                            {"cell", d.cell_id},
                            {"trials", d.trials},
                            {"mean_offset_m", {d.mean_dx, d.mean_dy, d.mean_dz}},
                            {"mean_position_error_m", d.mean_position_error},
                            {"max_position_error_m", d.max_position_error},
                            {"mean_angle_error_rad", d.mean_angle_error}});
  out["suspensions"] = SuspensionsJson(Suspensions(store));
  std::printf("%s\n", out.dump().c_str());
}

const char* TruthNote(const std::string& truth) {
  return truth == "self-consistency" ? ": errors are self-consistency, not accuracy"
         : truth == "measured" ? ": the observed streams are the truth (no separate true stream)"
         : truth == db::kTruthMeasuredNoForces
             ? ": measured poses, forces not measured or failed their import check (not scored)"
             : "";
}

// The campaign table, then per campaign: why it waits, its truth, its failures.
void PrintCampaigns(const db::Store& store, const StatusView& v) {
  const auto& campaigns = v.summary.campaigns;
  std::printf("%-5s %-20s %-9s %7s %7s %7s %7s %9s %8s\n", "id", "campaign", "state", "planned",
              "done", "failed", "running", "rate/h", "ETA");
  for (const auto& c : campaigns)
    std::printf("%-5lld %-20s %-9s %7lld %7lld %7lld %7lld %9.1f %8s\n",
                static_cast<long long>(c.id), c.name.c_str(), db::ToString(c.state),
                static_cast<long long>(c.planned), static_cast<long long>(c.done),
                static_cast<long long>(c.failed), static_cast<long long>(c.running),
                c.rate_per_hour, c.eta_s ? FormatDuration(*c.eta_s).c_str() : "-");
  for (const auto& c : campaigns) {
    if (c.awaiting_prediction > 0)
      std::printf("      campaign %lld: %lld of its running trials await their prediction\n",
                  static_cast<long long>(c.id), static_cast<long long>(c.awaiting_prediction));
    if (auto w = v.waits.find(c.id); w != v.waits.end())
      std::printf("      campaign %lld waits: %s (since %s)\n", static_cast<long long>(c.id),
                  w->second.reason.c_str(), IsoTime(w->second.since).c_str());
    for (const auto& t : store.CampaignTruths(c.id)) {
      std::printf("      truth of %lld: %s (%s backend), %lld trials%s\n",
                  static_cast<long long>(c.id), t.truth.empty() ? "unreported" : t.truth.c_str(),
                  t.backend.empty() ? "?" : t.backend.c_str(), static_cast<long long>(t.trials),
                  TruthNote(t.truth));
    }
    const std::string failures = FormatFailures(CampaignFailures(store, c.id), "      ") +
                                 FormatDeadlines(CampaignDeadlines(store, c.id), "      ");
    if (!failures.empty())
      std::printf("      campaign %lld:\n%s", static_cast<long long>(c.id), failures.c_str());
  }
}

void PrintAdaptive(const db::Store& store, const StatusView& v) {
  bool header = false;
  for (const auto& c : v.summary.campaigns) {
    const auto a = orchestrator::ReadAdaptiveProgress(store.GetCampaign(c.id));
    if (!a) continue;
    if (!header) std::printf("\nadaptive sampling:\n");
    header = true;
    std::printf("%-5lld %-10s round %-3d %3.0f %%  refining %s\n      %s\n",
                static_cast<long long>(c.id), a->sampler.c_str(), a->round, a->fraction * 100,
                a->refining.c_str(), a->progress.c_str());
    if (const auto b = FindBoundary(store, c.id))
      std::fputs(FormatBoundary(*b, "      ").c_str(), stdout);
  }
}

void PrintService(const StatusView& v) {
  const auto& service = v.service;
  if (!service) {
    std::printf("\nservice: none has run on this store\n");
    return;
  }
  std::printf("\nservice: pid %lld on %s, DDS domain %d, session %s, started %s, %s\n",
              static_cast<long long>(service->pid), service->host.c_str(), service->domain,
              service->session.c_str(), IsoTime(service->started_at).c_str(),
              service->stopped_at ? ("stopped " + IsoTime(*service->stopped_at)).c_str()
                                  : ("last beat " + IsoTime(service->last_beat) +
                                     (v.no_service.empty() ? " (running)" : " (not running)"))
                                        .c_str());
}

void PrintDrift(const std::vector<db::StartStateDrift>& drift) {
  if (drift.empty()) return;
  std::printf(
      "\nstart-state drift (the start each trial's cell measured - nominal):\n%-5s %-16s %6s %28s "
      "%10s %10s\n",
      "camp", "cell", "trials", "mean offset x,y,z (mm)", "mean |e| mm", "mean deg");
  for (const auto& d : drift)
    std::printf("%-5lld %-16s %6lld %9.3f,%8.3f,%8.3f %10.3f %10.3f\n",
                static_cast<long long>(d.campaign_id), d.cell_id.c_str(),
                static_cast<long long>(d.trials), d.mean_dx * 1e3, d.mean_dy * 1e3, d.mean_dz * 1e3,
                d.mean_position_error * 1e3, d.mean_angle_error * 180 / M_PI);
}

int Status(const std::string& db_path, std::int64_t only, bool as_json, bool all_cells) {
  auto store = OpenStore(db_path, true);
  StatusView v;
  v.summary = store->Status();
  v.service = store->LatestService();
  v.no_service = NoServiceWarning(*store, db_path);
  v.activity = ReadCellActivity(*store, v.summary.cells);
  for (auto& w : store->ListCampaignWaits()) v.waits[w.campaign_id] = std::move(w);
  auto& s = v.summary;
  // The warning says trials wait: only when some do (an active campaign with
  // trials not yet finished), not on a store whose campaigns are all done.
  std::int64_t waiting = 0;
  for (const auto& c : s.campaigns)
    if (c.state == db::CampaignState::kActive) waiting += c.pending + c.running;
  if (!v.no_service.empty() && waiting > 0)
    std::fprintf(stderr, "warning: %s\n", v.no_service.c_str());
  if (only > 0) {
    std::erase_if(s.campaigns, [&](const db::CampaignStatus& c) { return c.id != only; });
    if (s.campaigns.empty())
      throw CommandError(kExitBadInput, "no campaign " + std::to_string(only) + " in " + db_path +
                                            " (see `arena list`)");
  }
  if (as_json) {
    PrintStatusJson(*store, v);
    return kExitOk;
  }
  PrintCampaigns(*store, v);
  PrintAdaptive(*store, v);
  PrintService(v);
  std::fputs(FormatCellTable(s.cells, v.activity, store->Now(), all_cells).c_str(), stdout);
  for (const auto& c : s.cells)
    if (!c.serving.empty()) std::printf("cell %s is %s\n", c.id.c_str(), c.serving.c_str());
  PrintDrift(s.drift);
  std::fputs(FormatSuspensions(Suspensions(*store), store->Now()).c_str(), stdout);
  return kExitOk;
}

int Control(const std::string& verb, std::int64_t id, const std::string& db_path,
            const std::optional<std::string>& cell) {
  auto store = OpenStore(db_path, false);
  if (verb == "pause") {
    store->PauseCampaign(id);
  } else if (verb == "resume") {
    // Also lifts its suspensions (and the service's, and --cell's) and
    // resets their hold: the service sees it on its next pass (1 s).
    for (const auto& s : store->ResumeSuspended(id, cell))
      std::fprintf(stderr, "lifted: %s suspension of %s (%s)\n", s.condition.c_str(),
                   s.scope == "cell"       ? ("cell " + s.cell_id).c_str()
                   : s.scope == "campaign" ? ("campaign " + std::to_string(s.campaign_id)).c_str()
                                           : "every campaign",
                   s.evidence.c_str());
  } else {
    store->CancelCampaign(id);
  }
  std::fprintf(stderr, "campaign %lld: %s\n", static_cast<long long>(id),
               db::ToString(store->GetCampaign(id).state));
  return kExitOk;
}

}  // namespace

void AddCampaignCommands(CLI::App& app, Action* action) {
  {
    struct O {
      std::string campaign, db;
    };
    auto o = std::make_shared<O>();
    auto* cmd =
        app.add_subcommand("submit", "Validate a campaign and store it with its planned trials");
    cmd->footer(
        "Example:\n  arena submit examples/campaigns/smoke.json --db lab.db\n"
        "Prints the campaign id; a running `arena serve --db lab.db` picks it up at once.");
    cmd->add_option("campaign", o->campaign, "Campaign JSON (orchestrator/README.md)")->required();
    cmd->add_option("--db", o->db, "SQLite store (created if missing)")->required();
    cmd->callback([o, action] { *action = [o] { return Submit(o->campaign, o->db); }; });
  }
  {
    struct O {
      std::string db;
      bool json = false;
    };
    auto o = std::make_shared<O>();
    auto* cmd = app.add_subcommand("list", "List the campaigns in a store");
    cmd->footer("Example:\n  arena list --db lab.db\n");
    cmd->add_option("--db", o->db, "SQLite store")->required();
    cmd->add_flag("--json", o->json, "JSON instead of a table");
    cmd->callback([o, action] { *action = [o] { return List(o->db, o->json); }; });
  }
  {
    struct O {
      std::string db;
      std::int64_t id = 0;
      bool json = false;
      bool all = false;
    };
    auto o = std::make_shared<O>();
    auto* cmd =
        app.add_subcommand("status", "Campaign progress, cell health and start-state drift");
    cmd->footer(
        "Example:\n  arena status --db lab.db 3\n  arena status --db lab.db --json\n"
        "Works from any process or host that can open the store file (README: remote hosts).\n");
    auto* id = cmd->add_option("id", o->id, "Only this campaign");
    cmd->add_option("--db", o->db, "SQLite store")->required();
    cmd->add_flag("--json", o->json, "JSON for scripts");
    cmd->add_flag("--all", o->all,
                  "List every cell, also those gone for more than a day (otherwise counted)");
    cmd->callback([o, id, action] {
      const bool given = id->count() > 0;
      *action = [o, given] {
        if (given && o->id < 1)
          throw CommandError(kExitBadInput, "id: must be a campaign id (>= 1), got " +
                                                std::to_string(o->id) + " (see `arena list`)");
        return Status(o->db, o->id, o->json, o->all);
      };
    });
  }
  for (const char* verb : {"pause", "resume", "cancel"}) {
    struct O {
      std::string db;
      std::int64_t id = 0;
      std::string verb;
      std::string cell;
    };
    auto o = std::make_shared<O>();
    o->verb = verb;
    const std::string help = std::string(
        verb == std::string("pause")    ? "Pause a campaign (its running trials finish)"
        : verb == std::string("resume") ? "Resume a paused campaign"
                                        : "Cancel a campaign (planned trials are dropped)");
    auto* cmd = app.add_subcommand(verb, help);
    cmd->footer(std::string("Example:\n  arena ") + verb + " 3 --db lab.db\n" +
                (verb == std::string("resume")
                     ? "  arena resume 3 --cell c2 --db lab.db\n"
                       "Lifts the campaign's suspensions (and the service's; with --cell, that "
                       "cell's) and resets their hold (docs/operations.md).\n"
                     : ""));
    cmd->add_option("id", o->id, "Campaign id (see `arena list`)")->required();
    cmd->add_option("--db", o->db, "SQLite store")->required();
    CLI::Option* cell = nullptr;
    if (verb == std::string("resume"))
      cell = cmd->add_option("--cell", o->cell, "Also lift this cell's suspensions");
    cmd->callback([o, action, cell] {
      const bool with_cell = cell && cell->count() > 0;
      *action = [o, with_cell] {
        return Control(o->verb, o->id, o->db,
                       with_cell ? std::optional<std::string>(o->cell) : std::nullopt);
      };
    });
  }
}

}  // namespace arena::cli
