// The one error base of arena. Every room's typed error (SceneError,
// StoreError, DdsError, ...) derives from arena::Error and carries its
// category; the arena binary's main() turns a category into the process exit
// code in one place (README: exit codes, tested against kErrorCategories).
#pragma once

#include <stdexcept>
#include <string>

namespace arena {

// What kind of failure an error is, from the user's side. The enumerator's
// value IS the exit code (README: exit codes).
enum class ErrorCategory : int {
  kFailure = 1,        // the command ran and failed (solver failure, failed campaign, output)
  kBadInput = 2,       // arguments, scene, campaign, query, unknown id: the field is named
  kStore = 3,          // the store: missing, read-only, full, busy, corrupt, too new
  kCommunication = 4,  // DDS set-up failed, no cell answered in time
  kInterrupted = 130,  // SIGINT / SIGTERM before finishing
};

constexpr int ExitCode(ErrorCategory category) { return static_cast<int>(category); }

// The words the README's exit-code table uses for the category (its test
// finds each in the row of the category's code).
constexpr const char* ToString(ErrorCategory category) {
  switch (category) {
    case ErrorCategory::kFailure:
      return "failed";
    case ErrorCategory::kBadInput:
      return "bad input";
    case ErrorCategory::kStore:
      return "store error";
    case ErrorCategory::kCommunication:
      return "communication";
    case ErrorCategory::kInterrupted:
      return "interrupted";
  }
  return "failed";
}

inline constexpr ErrorCategory kErrorCategories[] = {
    ErrorCategory::kFailure, ErrorCategory::kBadInput, ErrorCategory::kStore,
    ErrorCategory::kCommunication, ErrorCategory::kInterrupted};

// The category whose exit code is `code`; kFailure for a code no category has.
constexpr ErrorCategory CategoryForExitCode(int code) {
  for (ErrorCategory c : kErrorCategories)
    if (ExitCode(c) == code) return c;
  return ErrorCategory::kFailure;
}

class Error : public std::runtime_error {
 public:
  Error(ErrorCategory category, const std::string& what)
      : std::runtime_error(what), category_(category) {}
  ErrorCategory category() const { return category_; }
  int exit_code() const { return ExitCode(category_); }

 private:
  ErrorCategory category_;
};

}  // namespace arena
