#!/usr/bin/env bash
# Times the README's two quick-start commands on a fresh Debian 12: a
# minimal bookworm (debootstrap --variant=minbase) with a clone of this
# repository at COMMIT, nothing else installed. `run` first (install, build
# the arena binary, the smoke campaign), then `.ci/run` on the same machine
# (format check, the whole build, the suite), as a newcomer would.
#
#   sudo scripts/fresh_machine_time.sh [COMMIT] [WORK_DIR]
#
# Needs root (debootstrap, chroot, mounts) and a Debian mirror. Prints each
# command's wall time; the logs stay in WORK_DIR (default /tmp/arena-fresh).
# In a chroot the tests that need network namespaces or private mounts skip
# with their reason (the host's suite runs them).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
commit="${1:-HEAD}"
work="${2:-/tmp/arena-fresh}"
mirror="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
if [ "$(id -u)" -ne 0 ]; then
  echo "fresh_machine_time: needs root (debootstrap, chroot, mount)" >&2
  exit 2
fi
command -v debootstrap >/dev/null || apt-get install -y -qq debootstrap >/dev/null
root="$work/root"
cleanup() { umount -R "$root/proc" "$root/dev" "$root/sys" 2>/dev/null || true; }
trap cleanup EXIT
cleanup
rm -rf "$root"
mkdir -p "$work"
debootstrap --variant=minbase bookworm "$root" "$mirror" >"$work/debootstrap.log" 2>&1
cp /etc/resolv.conf "$root/etc/resolv.conf"
git clone -q "$here" "$root/root/arena"
git -C "$root/root/arena" checkout -q "$commit"
mount -t proc proc "$root/proc"
mount --rbind /dev "$root/dev"
mount --rbind /sys "$root/sys"
echo "fresh Debian $(cat "$root/etc/debian_version"), arena $(git -C "$root/root/arena" log --oneline -1 | cut -c1-60)"
for cmd in "scripts/quickstart.sh run" ".ci/run"; do
  log="$work/$(echo "$cmd" | tr -c 'a-z' '_').log"
  start=$(date +%s)
  status=0
  chroot "$root" bash -c "cd /root/arena && $cmd" >"$log" 2>&1 || status=$?
  echo "$cmd: $(($(date +%s) - start)) s, exit $status, load $(cut -d' ' -f1-3 /proc/loadavg) (log $log)"
  tail -3 "$log" | sed 's/^/  /'
  [ "$status" -eq 0 ] || exit "$status"
done
