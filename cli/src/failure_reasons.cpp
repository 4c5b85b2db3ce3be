#include "failure_reasons.hpp"

#include <algorithm>
#include <cctype>
#include <map>
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

// Groups in the order of their first appearance, then by count (largest first).
class Grouper {
 public:
  void Add(const std::string& source, const std::string& reason, const std::string& cell_id,
           std::int64_t trial_id) {
    const std::string key = source + "\n" + ReasonKey(reason, cell_id);
    auto [it, fresh] = index_.try_emplace(key, groups_.size());
    if (fresh) groups_.push_back({source, reason, 0, trial_id});
    ReasonGroup& g = groups_[it->second];
    ++g.count;
    g.first_trial = std::min(g.first_trial, trial_id);
  }
  std::vector<ReasonGroup> Take() {
    std::stable_sort(groups_.begin(), groups_.end(),
                     [](const ReasonGroup& a, const ReasonGroup& b) { return a.count > b.count; });
    return std::move(groups_);
  }

 private:
  std::map<std::string, size_t> index_;
  std::vector<ReasonGroup> groups_;
};

std::string FormatGroups(const std::vector<ReasonGroup>& groups, const std::string& indent) {
  std::string out;
  constexpr size_t kShown = 8;  // the rest are counted, not listed
  for (size_t i = 0; i < groups.size() && i < kShown; ++i) {
    const auto& g = groups[i];
    out += indent + "  " + std::to_string(g.count) + " x " + g.source + ": " + g.example +
           " (e.g. trial " + std::to_string(g.first_trial) + ")\n";
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
                   {"reason", g.example},
                   {"count", g.count},
                   {"first_trial", g.first_trial}});
  return out;
}

}  // namespace

std::string ReasonSource(const std::string& reason) {
  const std::string r = Lower(reason);
  if (r.find("driver") != std::string::npos) return "driver";
  if (r.find("cell") != std::string::npos) return "cell";
  return "service";
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
      "SELECT t.campaign_id, tr.to_state, tr.reason, tr.cell_id, tr.trial_id "
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
    if (to == "failed") {
      failures.Add(ReasonSource(reason), reason, cell, trial);
      ++report.failed_trials;
    } else {
      retries.Add(ReasonSource(reason), to == "reset_failed" ? "reset failed: " + reason : reason,
                  cell, trial);
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
    predictions.Add("predictor", error.empty() ? status : status + ": " + error, "", Int(row[3]));
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
