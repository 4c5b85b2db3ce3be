#!/usr/bin/env bash
# Checks that no merge left conflict markers in a tracked file and that every
# tracked C++ file is formatted by .clang-format (Google style, 100 columns).
# Exit 1 lists what is not; `scripts/check_format.sh --fix` formats in place.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang-format >/dev/null 2>&1; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq && $sudo apt-get install -y -qq --no-install-recommends clang-format >/dev/null
fi
# A merge's leftover conflict markers (they compile in comments and README
# tables, so no build catches them).
if markers=$(git grep -nE '^(<<<<<<<|>>>>>>>) ' -- . ':!*.patch'); then
  echo "check_format: conflict markers left by a merge:" >&2
  echo "$markers" >&2
  exit 1
fi
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' '*.cc')
if [ "${1:-}" = "--fix" ]; then
  clang-format -i "${files[@]}"
  exit 0
fi
bad=()
for f in "${files[@]}"; do
  if ! clang-format --dry-run --Werror "$f" >/dev/null 2>&1; then bad+=("$f"); fi
done
if ((${#bad[@]})); then
  echo "check_format: ${#bad[@]} file(s) not formatted (run scripts/check_format.sh --fix):" >&2
  printf '  %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "check_format: ${#files[@]} files formatted"
