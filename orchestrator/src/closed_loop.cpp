#include "arena/orchestrator/closed_loop.hpp"

#include <cmath>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace arena::orchestrator {

namespace {

using nlohmann::json;

double Num(const json& j, const char* key, const std::string& at) {
  if (!j.contains(key) || !j[key].is_number())
    throw std::invalid_argument(at + "." + key + ": must be a number");
  return j[key].get<double>();
}

std::optional<double> OptNum(const json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return std::nullopt;
  return j[key].get<double>();
}

}  // namespace

std::optional<db::ClosedLoopRun> ClosedLoopFromDetail(std::int64_t trial_id, int attempt,
                                                      const std::string& failure,
                                                      const std::string& detail_json) {
  const json detail = json::parse(detail_json, nullptr, false);
  if (!detail.is_object() || !detail.contains("closed_loop")) return std::nullopt;
  const json& c = detail["closed_loop"];
  const std::string at = "detail_json.closed_loop";
  if (!c.is_object()) throw std::invalid_argument(at + ": must be an object");
  db::ClosedLoopRun run;
  run.trial_id = trial_id;
  run.attempt = attempt;
  run.failure = failure;
  if (!c.contains("controller") || !c["controller"].is_string())
    throw std::invalid_argument(at + ".controller: must be a string");
  run.controller = c["controller"].get<std::string>();
  run.lockstep = c.value("lockstep", false);
  const json& ctx = c.contains("context") ? c["context"] : json::object();
  run.target = Num(ctx, "target", at + ".context");
  run.gain = Num(ctx, "gain", at + ".context");
  run.tolerance = Num(ctx, "tolerance", at + ".context");
  run.hold_s = Num(ctx, "hold_s", at + ".context");
  run.held = static_cast<int>(c.value("held", 0));
  if (c.contains("loop_ms")) {
    run.loop_p50_ms = OptNum(c["loop_ms"], "p50");
    run.loop_p99_ms = OptNum(c["loop_ms"], "p99");
  }
  if (c.contains("outcome") && c["outcome"].is_object()) {
    const json& o = c["outcome"];
    if (o.contains("reached") && o["reached"].is_boolean()) run.reached = o["reached"].get<bool>();
    run.final_error = OptNum(o, "final_error");
    run.settle_time_s = OptNum(o, "settle_time_s");
  }
  if (!c.contains("commands") || !c["commands"].is_array())
    throw std::invalid_argument(at + ".commands: must be an array");
  for (std::size_t i = 0; i < c["commands"].size(); ++i) {
    const json& row = c["commands"][i];
    const std::string where = at + ".commands[" + std::to_string(i) + "]";
    if (!row.is_array() || row.size() != 9)
      throw std::invalid_argument(where + ": must be 9 values");
    for (std::size_t k = 0; k < 8; ++k) {
      if (!row[k].is_number() || !std::isfinite(row[k].get<double>()))
        throw std::invalid_argument(where + ": not a finite number");
    }
    db::ClosedLoopCommand cmd;
    cmd.sample = row[0].get<int>();
    cmd.t = row[1].get<double>();
    for (int k = 0; k < 3; ++k) {
      cmd.commanded[k] = row[2 + k].get<double>();
      cmd.applied[k] = row[5 + k].get<double>();
    }
    if (row[8].is_number() && row[8].get<double>() >= 0) cmd.loop_ms = row[8].get<double>();
    run.commands.push_back(cmd);
  }
  return run;
}

}  // namespace arena::orchestrator
