#pragma once

namespace arena {
// The release version (CMake project version) and the git commit the binary
// was built from ("-dirty" when the tree had uncommitted changes).
const char* Version();
const char* GitCommit();
}  // namespace arena
