#!/usr/bin/env bash
# Installs what is missing, configures and builds arena. Idempotent: when
# every package is there and nothing changed, it only asks ninja, which
# answers "no work to do".
#
#   scripts/setup.sh [--bench-peers] [--target T] [BUILD_DIR] [extra cmake args...]
#
# --target T builds only T (and what it needs) instead of every target: the
# quick start's `run` needs the arena binary alone, not the ~260 test and
# benchmark targets. May be given more than once.
# --bench-peers also installs the peer LCP solvers that only
# bench/lcp_solvers_bench compares against (Siconos numerics, Bullet, DART;
# benchmark-only, never runtime dependencies; bench/README.md "LCP solvers").
#
# Environment: ARENA_JOBS (default: one job per core, as many as memory
# holds at about 1.5 GB per compiler; 2 on the 2-core reference machine).
set -euo pipefail
bench_peers=0
targets=()
while (($#)); do
  case "$1" in
    --bench-peers) bench_peers=1; shift ;;
    --target) targets+=(--target "$2"); shift 2 ;;
    *) break ;;
  esac
done
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-$here/build}"
shift || true
# A fresh machine's first build is most of a newcomer's first run: use its
# cores (bench/README.md "Build time"), not a fixed 2.
cores="$(nproc 2>/dev/null || echo 2)"
mem_kb="$(awk '/^MemAvailable:/ {print $2}' /proc/meminfo 2>/dev/null || echo 0)"
by_memory=$((mem_kb / 1500000))
jobs_default=$((cores < by_memory ? cores : by_memory))
((jobs_default >= 1)) || jobs_default=1
jobs="${ARENA_JOBS:-$jobs_default}"

packages=(
  build-essential cmake ninja-build git pkg-config ccache
  libeigen3-dev libsqlite3-dev sqlite3
  libfastrtps-dev libfastcdr-dev fastddsgen fastdds-tools
  nlohmann-json3-dev libspdlog-dev libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev libhdf5-dev libtinyxml2-dev
  # libssl-dev: `arena certs` makes the lab CA, identities and signed
  # permissions with OpenSSL's libcrypto (the library Fast DDS's security
  # plugins use too).
  libssl-dev
  # libmujoco-dev: the independent physics engine behind the `mujoco` cell
  # backend and predictor; libnlopt-cxx-dev: derivative-free calibration.
  libmujoco-dev libnlopt-cxx-dev
  # clang-format: scripts/check_format.sh (run by .ci/run); python3-h5py
  # reads exported HDF5 datasets back in the export tests.
  clang-format python3-h5py
  iproute2 procps
)
if ((bench_peers)); then
  packages+=(libsiconos-numerics-dev libbullet-dev libdart-dev)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}" >&2
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -f "$build/build.ninja" ]; then
  cmake -S "$here" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
elif (($#)); then
  cmake "$build" "$@" >/dev/null
fi
cmake --build "$build" -j "$jobs" "${targets[@]}"
