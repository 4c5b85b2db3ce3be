// A campaign trial's parameters by name, for grouping and splitting
// (`arena evaluate --group-by`, `arena calibrate --holdout-by`): the trial's
// own stored parameters (trials.params_json), and for a name they lack, a
// table with a `seed` column whose row of the trial's seed holds it -- an
// arena dataset's trials.csv, e.g. an import's, which carries each recorded
// trial's parameters (shape, push angle, speed) under the seed the campaign
// it wrote gives the trial.
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include "arena/db/store.hpp"

namespace arena::cli {

class TrialParameters {
 public:
  // `csv_path` empty: the stored parameters alone.
  // @throws CommandError (bad input) naming `flag` and the file for a file that
  //   cannot be read, is not CSV, has no `seed` column or repeats a seed.
  TrialParameters(const std::string& csv_path, const std::string& flag);

  // The trial's value of `name` as text (a stored string as is, a number as
  // JSON writes it). @throws CommandError (bad input) naming `option`, the
  // trial and the parameter when neither source holds it.
  std::string Value(const db::Trial& trial, const std::string& name,
                    const std::string& option) const;

 private:
  std::string csv_path_, flag_;
  std::map<std::string, std::map<std::string, std::string>> by_seed_;  // seed -> column -> value
};

}  // namespace arena::cli
