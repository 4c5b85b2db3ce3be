#include "failure_reasons.hpp"

#include <algorithm>
#include <cctype>
#include <map>
#include <set>
#include <string>
#include <variant>

#include "arena/db/query.hpp"

namespace arena::cli {
namespace {

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string Text(const db::Value& v) {
  if (const auto* s = std::get_if<std::string>(&v)) return *s;
  return "";
}

std::int64_t Int(const db::Value& v) {
  if (const auto* i = std::get_if<std::int64_t>(&v)) return *i;
  if (const auto* d = std::get_if<double>(&v)) return static_cast<std::int64_t>(*d);
  return 0;
}

// Groups by count (largest first), ties by the first trial that met them: not
// by the order the rows were written, which depends on timing.
class Grouper {
 public:
  // kind "": grouped by the reason's text (a row written before rules were).
  void Add(const std::string& source, const std::string& kind, const std::string& label,
           const std::string& reason, const std::string& cell_id, std::int64_t trial_id) {
    const std::string text = ReasonKey(reason, cell_id);
    const std::string key = source + "\n" + (kind.empty() ? "\n" + text : kind);
    auto [it, fresh] = index_.try_emplace(key, groups_.size());
    if (fresh) groups_.push_back({source, kind, label, reason, 0, trial_id, 0});
    ReasonGroup& g = groups_[it->second];
    ++g.count;
    g.first_trial = std::min(g.first_trial, trial_id);
    if (texts_[it->second].insert(text).second) ++g.texts;
  }
  std::vector<ReasonGroup> Take() {
    std::stable_sort(
        groups_.begin(), groups_.end(), [](const ReasonGroup& a, const ReasonGroup& b) {
          return a.count != b.count ? a.count > b.count : a.first_trial < b.first_trial;
        });
    return std::move(groups_);
  }

 private:
  std::map<std::string, size_t> index_;
  std::map<size_t, std::set<std::string>> texts_;
  std::vector<ReasonGroup> groups_;
};

std::string FormatGroups(const std::vector<ReasonGroup>& groups, const std::string& indent) {
  std::string out;
  constexpr size_t kShown = 8;  // the rest are counted, not listed
  for (size_t i = 0; i < groups.size() && i < kShown; ++i) {
    const auto& g = groups[i];
    // "18 x driver, the cell's backend failed [execute.cell_failure]: driver: ... (e.g. trial 3)"
    std::string head = std::to_string(g.count) + " x " + g.source;
    if (!g.kind.empty()) head += ", " + g.label + " [" + g.kind + "]";
    std::string more;
    if (g.texts > 1) more = "; " + std::to_string(g.texts) + " different texts";
    out += indent + "  " + head + ": " + g.example + " (e.g. trial " +
           std::to_string(g.first_trial) + more + ")\n";
  }
  if (groups.size() > kShown) {
    std::int64_t rest = 0;
    for (size_t i = kShown; i < groups.size(); ++i) rest += groups[i].count;
    out += indent + "  " + std::to_string(rest) + " more with " +
           std::to_string(groups.size() - kShown) + " other reasons\n";
  }
  return out;
}

nlohmann::json GroupsJson(const std::vector<ReasonGroup>& groups) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& g : groups)
    out.push_back({{"source", g.source},
                   {"kind", g.kind},
                   {"label", g.label},
                   {"reason", g.example},
                   {"count", g.count},
                   {"first_trial", g.first_trial},
                   {"texts", g.texts}});
  return out;
}

}  // namespace

std::string ReasonSource(const std::string& reason) {
  const std::string r = Lower(reason);
  if (r.find("driver") != std::string::npos) return "driver";
  if (r.find("cell") != std::string::npos) return "cell";
  return "service";
}

FailureKind KindOfRule(const std::string& rule, const std::string& backend) {
  // The rules of orchestrator's trial policy and the store's own edges.
  struct Row {
    const char* kind;
    const char* source;
    const char* label;
  };
  static constexpr Row kRows[] = {
      {"execute.simulation_failure", "cell", "the simulation failed (a re-run fails alike)"},
      {"execute.controller_fault", "controller", "the closed-loop controller failed"},
      {"execute.cell_deadline", "cell", "the cell's own deadline passed"},
      {"execute.cell_interrupted", "cell", "the cell shut down mid-trial"},
      {"execute.cell_failure_typed_as_reset", "cell", "the cell failed (typed as a reset)"},
      {"execute.cell_failure", "cell", "the cell's backend failed"},
      {"execute.cell_failure_untyped", "cell", "the cell failed (untyped)"},
      {"execute.refused_by_cell", "cell", "the cell refused the trial"},
      {"execute.deadline_missed", "service", "no result by the execute deadline"},
      {"execute.stream_incomplete", "cell", "the ground truth stream was incomplete"},
      {"execute.stream_malformed", "cell", "the ground truth stream was malformed"},
      {"execute.command_not_sent", "service", "the command could not be sent"},
      {"execute.store_refused_truth", "store", "the store refused the ground truth"},
      {"execute.cell_lost", "cell", "the cell went away"},
      {"execute.cell_restarted", "cell", "the cell restarted"},
      {"execute.cell_claimed_elsewhere", "cell", "the cell serves another service"},
      {"reset.failed", "cell", "the reset failed"},
      {"reset.deadline_missed", "cell", "no reset result by its deadline"},
      {"reset.command_not_sent", "service", "the reset command could not be sent"},
      {"reset.cell_lost", "cell", "the cell went away while resetting"},
      {"reset.cell_restarted", "cell", "the cell restarted while resetting"},
      {"reset.cell_claimed_elsewhere", "cell", "the cell serves another service"},
      {"dispatch.invalid_scene", "scene", "the scene is invalid"},
      {"recover.execute_unconfirmed", "service", "the service restarted mid-trial"},
      {"recover.reset_unconfirmed", "service", "the service restarted mid-reset"},
      {"operator.cancel_campaign", "operator", "the campaign was cancelled"},
  };
  FailureKind out;
  out.kind = rule.substr(0, rule.find(' '));
  for (const Row& r : kRows) {
    if (out.kind != r.kind) continue;
    out.source = r.source;
    out.label = r.label;
    // A backend that is an external robot driver: its failures are the driver's.
    if (out.source == "cell" && backend.rfind("exec:", 0) == 0 &&
        (out.kind == "execute.cell_failure" || out.kind == "execute.refused_by_cell" ||
         out.kind == "execute.cell_deadline" || out.kind == "reset.failed"))
      out.source = "driver";
    return out;
  }
  // An unknown rule (or "fail.unnamed", or a retry verdict alone) names no
  // cause: such rows are grouped by their text.
  out.kind.clear();
  return out;
}

std::string ReasonKey(const std::string& reason, const std::string& cell_id) {
  std::string r = reason;
  if (!cell_id.empty()) {
    for (size_t at = r.find(cell_id); at != std::string::npos; at = r.find(cell_id, at))
      r.replace(at, cell_id.size(), "<cell>");
  }
  // Numbers (with signs, decimals, exponents) vary from trial to trial.
  std::string key;
  for (size_t i = 0; i < r.size();) {
    if (std::isdigit(static_cast<unsigned char>(r[i]))) {
      while (i < r.size() &&
             (std::isdigit(static_cast<unsigned char>(r[i])) || r[i] == '.' || r[i] == 'e' ||
              r[i] == 'E' ||
              ((r[i] == '-' || r[i] == '+') && i > 0 && (r[i - 1] == 'e' || r[i - 1] == 'E'))))
        ++i;
      key += '#';
    } else {
      key += r[i++];
    }
  }
  return key;
}

FailureReport CampaignFailures(const db::Store& store, std::int64_t campaign_id) {
  FailureReport report;
  db::QueryFilter filter;
  filter.campaign_id = campaign_id;
  // A trial's failure is its last transition into failed; a retry is an
  // attempt sent back to planned (or a reset that failed and is retried).
  const db::QueryResult moves = db::RunQuery(
      store,
      "SELECT t.campaign_id, tr.to_state, tr.reason, tr.cell_id, tr.trial_id, tr.rule, "
      "coalesce(t.backend, '') "
      "FROM trial_transitions tr JOIN trials t ON t.id = tr.trial_id "
      "WHERE tr.from_state <> '' AND (tr.to_state IN ('planned', 'reset_failed') OR "
      "(tr.to_state = 'failed' AND t.state = 'failed' AND tr.id = (SELECT max(id) FROM "
      "trial_transitions WHERE trial_id = tr.trial_id AND to_state = 'failed'))) "
      "ORDER BY tr.id",
      filter);
  Grouper failures, retries, predictions;
  for (const auto& row : moves.rows) {
    const std::string to = Text(row[1]);
    std::string reason = Text(row[2]);
    if (reason.empty()) reason = "no reason recorded";
    const std::string cell = Text(row[3]);
    const std::int64_t trial = Int(row[4]);
    FailureKind kind = KindOfRule(Text(row[5]), Text(row[6]));
    if (kind.source.empty()) kind.source = ReasonSource(reason);  // no rule or an unknown one
    if (to == "failed") {
      failures.Add(kind.source, kind.kind, kind.label, reason, cell, trial);
      ++report.failed_trials;
    } else {
      retries.Add(kind.source, kind.kind, kind.label,
                  to == "reset_failed" ? "reset failed: " + reason : reason, cell, trial);
      ++report.retried_attempts;
    }
  }
  const db::QueryResult preds = db::RunQuery(
      store,
      "SELECT t.campaign_id, p.status, json_extract(p.detail_json, '$.error'), p.trial_id "
      "FROM predictions p JOIN trials t ON t.id = p.trial_id "
      "WHERE p.status <> 'ok' ORDER BY p.id",
      filter);
  for (const auto& row : preds.rows) {
    const std::string status = Text(row[1]);
    const std::string error = Text(row[2]);
    // The status is the prediction's typed outcome (assessment::PredictionOutcome).
    predictions.Add("predictor", status, "the prediction " + status, error.empty() ? status : error,
                    "", Int(row[3]));
    ++report.failed_predictions;
  }
  report.failures = failures.Take();
  report.retries = retries.Take();
  report.predictions = predictions.Take();
  return report;
}

std::string FormatFailures(const FailureReport& r, const std::string& indent) {
  std::string out;
  if (r.failed_trials > 0) {
    out += indent + "failed trials by reason (" + std::to_string(r.failed_trials) + "):\n";
    out += FormatGroups(r.failures, indent);
  }
  if (r.retried_attempts > 0) {
    out += indent + "retried attempts by reason (" + std::to_string(r.retried_attempts) + "):\n";
    out += FormatGroups(r.retries, indent);
  }
  if (r.failed_predictions > 0) {
    out +=
        indent + "failed predictions by reason (" + std::to_string(r.failed_predictions) + "):\n";
    out += FormatGroups(r.predictions, indent);
  }
  return out;
}

nlohmann::json FailuresJson(const FailureReport& r) {
  return {{"failed", GroupsJson(r.failures)},
          {"retried", GroupsJson(r.retries)},
          {"predictions", GroupsJson(r.predictions)}};
}

}  // namespace arena::cli
