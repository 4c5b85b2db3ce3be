#include "trial_parameters.hpp"

#include <fstream>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "command_error.hpp"

namespace arena::cli {
namespace {

// RFC 4180 records: fields separated by commas, quoted fields may hold
// commas, newlines and doubled quotes. false at the end of the text.
bool NextRecord(const std::string& text, std::size_t* at, std::vector<std::string>* fields,
                bool* bad) {
  fields->clear();
  if (*at >= text.size()) return false;
  std::string field;
  bool quoted = false, was_quoted = false;
  std::size_t i = *at;
  for (; i < text.size(); ++i) {
    const char c = text[i];
    if (quoted) {
      if (c == '"') {
        if (i + 1 < text.size() && text[i + 1] == '"') {
          field += '"';
          ++i;
        } else {
          quoted = false;
        }
      } else {
        field += c;
      }
    } else if (c == '"') {
      if (!field.empty() || was_quoted) *bad = true;
      quoted = was_quoted = true;
    } else if (c == ',') {
      fields->push_back(std::move(field));
      field.clear();
      was_quoted = false;
    } else if (c == '\n' || c == '\r') {
      if (c == '\r' && i + 1 < text.size() && text[i + 1] == '\n') ++i;
      ++i;
      break;
    } else {
      field += c;
    }
  }
  if (quoted) *bad = true;
  fields->push_back(std::move(field));
  *at = i;
  return true;
}

}  // namespace

TrialParameters::TrialParameters(const std::string& csv_path, const std::string& flag)
    : csv_path_(csv_path), flag_(flag) {
  if (csv_path.empty()) return;
  std::ifstream in(csv_path, std::ios::binary);
  if (!in) throw CommandError(kExitBadInput, flag + ": cannot read '" + csv_path + "'");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  std::size_t at = 0;
  std::vector<std::string> header, row;
  bool bad = false;
  if (!NextRecord(text, &at, &header, &bad) || bad)
    throw CommandError(kExitBadInput, flag + ": '" + csv_path + "' has no CSV header");
  std::size_t seed_col = header.size();
  for (std::size_t i = 0; i < header.size(); ++i)
    if (header[i] == "seed") seed_col = i;
  if (seed_col == header.size())
    throw CommandError(kExitBadInput, flag + ": '" + csv_path +
                                          "' has no 'seed' column (an arena dataset's "
                                          "trials.csv has one)");
  for (int line = 2; NextRecord(text, &at, &row, &bad); ++line) {
    if (row.size() == 1 && row[0].empty()) continue;  // a blank line
    if (bad)
      throw CommandError(kExitBadInput, flag + ": '" + csv_path + "' record " +
                                            std::to_string(line) +
                                            ": a quote that does not open or close a field");
    if (row.size() != header.size())
      throw CommandError(kExitBadInput, flag + ": '" + csv_path + "' record " +
                                            std::to_string(line) + " has " +
                                            std::to_string(row.size()) + " fields, the header " +
                                            std::to_string(header.size()));
    auto& values = by_seed_[row[seed_col]];
    if (!values.empty())
      throw CommandError(kExitBadInput, flag + ": '" + csv_path + "' repeats seed " +
                                            row[seed_col] + " (record " + std::to_string(line) +
                                            "): a trial's row would be ambiguous");
    for (std::size_t i = 0; i < header.size(); ++i) values[header[i]] = row[i];
  }
}

std::string TrialParameters::Value(const db::Trial& trial, const std::string& name,
                                   const std::string& option) const {
  const auto stored = nlohmann::json::parse(trial.params_json, nullptr, false);
  if (stored.is_object() && stored.contains(name) && !stored[name].is_null()) {
    const auto& v = stored[name];
    return v.is_string() ? v.get<std::string>() : v.dump();
  }
  if (const auto row = by_seed_.find(std::to_string(trial.seed)); row != by_seed_.end()) {
    if (const auto v = row->second.find(name); v != row->second.end() && !v->second.empty())
      return v->second;
  }
  std::string where = "its stored parameters";
  if (!csv_path_.empty())
    where += " nor the row of its seed " + std::to_string(trial.seed) + " in '" + csv_path_ + "'";
  else
    where += " (give " + flag_ + " DATASET/trials.csv to read an imported trial's parameters)";
  throw CommandError(kExitBadInput, option + ": trial " + std::to_string(trial.id) +
                                        " has no parameter '" + name + "' in " + where);
}

}  // namespace arena::cli
