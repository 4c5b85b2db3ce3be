#!/usr/bin/env bash
# Issue 29: trials per hour with and without change-aware scheduling, on
# simulated cells at real speed (--speed 1), and the fixture-change time each
# run paid (from the store's fixture_changes table).
#
#   bench/change_scheduling.sh ARENA_BIN OUT_DIR [CELLS] [TRIALS]
#
# Runs bench/change_campaign.json (finger type, pusher type and object mass
# drawn at random) twice on CELLS simulated cells (default 2) with the cell
# profile bench/change_cell.json: once in plan order ("scheduling":
# {"change_aware": false}) and once as submitted (change-aware, the default
# window). TRIALS (default: the campaign's 96) cuts the plan for a shorter run.
# Prints one Markdown table row per run.
set -euo pipefail
arena="$1"
out="$2"
cells="${3:-2}"
trials="${4:-96}"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
mkdir -p "$out"

for mode in plan_order change_aware; do
  python3 - "$here/change_campaign.json" "$out/$mode.json" "$mode" "$trials" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
c["conditions"] = int(sys.argv[4])
if sys.argv[3] == "plan_order":
    c["scheduling"] = {"change_aware": False}
json.dump(c, open(sys.argv[2], "w"), indent=1)
PY
done

echo "| scheduling | cells | trials done | wall time (min) | trials per hour | fixture changes | change time (s) |"
echo "|---|---|---|---|---|---|---|"
for mode in plan_order change_aware; do
  db="$out/$mode.db"
  rm -f "$db" "$db-wal" "$db-shm" "$db.log"
  "$arena" run "$out/$mode.json" --db "$db" --cells "$cells" --speed 1 \
    --cell-defects "$here/change_cell.json" --quiet > "$out/$mode.out" 2>&1
  sqlite3 -separator ' ' "$db" "
    SELECT (SELECT count(*) FROM trials WHERE state = 'done'),
           (SELECT max(finished_at) FROM trials) -
             (SELECT min(at) FROM trial_transitions WHERE to_state = 'dispatched'),
           (SELECT count(*) FROM fixture_changes),
           (SELECT coalesce(sum(seconds), 0) FROM fixture_changes)" |
    while read -r done span changes change_s; do
      awk -v m="$mode" -v c="$cells" -v d="$done" -v s="$span" -v n="$changes" -v cs="$change_s" \
        'BEGIN { printf "| %s | %d | %d | %.1f | %.0f | %d | %.0f |\n", m, c, d, s / 60, d / s * 3600, n, cs }'
    done
done
