// Turning a store error into the user's message and exit code (README: exit codes).
#pragma once

#include <string>

#include "arena/db/store.hpp"
#include "commands.hpp"

namespace arena::cli {

// kBadInput / kNotFound / kIllegalTransition / kStaleAttempt are the user's
// input (exit 2); a read-only, busy, too new, corrupt, full or unreadable
// store is the store's problem (exit 3).
inline int ExitCodeFor(const db::StoreError& e) {
  using K = db::StoreError::Kind;
  switch (e.kind()) {
    case K::kBadInput:
    case K::kNotFound:
    case K::kIllegalTransition:
    case K::kStaleAttempt:
      return kExitBadInput;
    default:
      return kExitStore;
  }
}

inline CommandError StoreCommandError(const db::StoreError& e) {
  return CommandError(ExitCodeFor(e), e.what());
}

}  // namespace arena::cli
