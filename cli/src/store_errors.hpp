// Turning a store error into the user's message and exit code (README: exit codes).
#pragma once

#include <regex>
#include <string>

#include "arena/db/store.hpp"
#include "command_error.hpp"

namespace arena::cli {

// kBadInput / kNotFound / kIllegalTransition / kStaleAttempt are the user's
// input (exit 2); a read-only, busy, too new, corrupt, full or unreadable
// store is the store's problem (exit 3); an output that cannot be written is
// a failure of the command (exit 1).
inline int ExitCodeFor(const db::StoreError& e) {
  using K = db::StoreError::Kind;
  switch (e.kind()) {
    case K::kBadInput:
    case K::kNotFound:
    case K::kIllegalTransition:
    case K::kStaleAttempt:
      return kExitBadInput;
    case K::kOutput:  // the command ran; its output could not be written (README: exit 1)
      return kExitFailure;
    default:
      return kExitStore;
  }
}

// The store's messages start with the function that refused ("GetCampaign:
// no campaign 9", "Store::Open 'x': ...", "'SELECT ...': disk I/O error"):
// right for a developer's log, noise for a user. Strips those leading
// contexts (repeatedly), keeping a file name the context held.
inline std::string UserMessage(std::string text) {
  static const std::regex kFunction(R"(^[A-Z][A-Za-z0-9]*(::[A-Z][A-Za-z0-9]*)*: )");
  static const std::regex kFunctionFile(R"(^[A-Z][A-Za-z0-9]*(::[A-Z][A-Za-z0-9]*)* ('[^']*'): )");
  static const std::regex kSql(
      R"(^(prepare )?'(SELECT|INSERT|UPDATE|DELETE|PRAGMA|BEGIN|CREATE|DROP|WITH)[^']*': )");
  static const std::regex kTransaction(R"(^(begin transaction|commit): )");
  for (int i = 0; i < 4; ++i) {
    std::string next = std::regex_replace(text, kFunctionFile,
                                          "store $2: ", std::regex_constants::format_first_only);
    next = std::regex_replace(next, kFunction, "", std::regex_constants::format_first_only);
    next = std::regex_replace(next, kSql, "", std::regex_constants::format_first_only);
    next = std::regex_replace(next, kTransaction, "", std::regex_constants::format_first_only);
    if (next == text) break;
    text = next;
  }
  return text;
}

inline CommandError StoreCommandError(const db::StoreError& e) {
  return CommandError(ExitCodeFor(e), UserMessage(e.what()));
}

}  // namespace arena::cli
