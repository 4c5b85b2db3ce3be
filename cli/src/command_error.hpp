// The error every command reports and the exit codes main() maps it to.
// Apart from the command-line parser (commands.hpp), so that helpers which
// only report errors (plots, result files) do not compile CLI11.
#pragma once

#include <string>

#include "arena/errors/error.hpp"

namespace arena::cli {

// Exit codes (documented in README.md): the error categories' (arena::Error).
enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = ::arena::ExitCode(ErrorCategory::kFailure),
  kExitBadInput = ::arena::ExitCode(ErrorCategory::kBadInput),
  kExitStore = ::arena::ExitCode(ErrorCategory::kStore),
  kExitCommunication = ::arena::ExitCode(ErrorCategory::kCommunication),
  kExitInterrupted = ::arena::ExitCode(ErrorCategory::kInterrupted),
};

// An error a command reports to the user: the message says what went wrong and
// what to do next; main() prints it to stderr and exits with exit_code.
class CommandError : public Error {
 public:
  CommandError(int exit_code, const std::string& message)
      : Error(CategoryForExitCode(exit_code), message) {}
};

}  // namespace arena::cli
