#!/usr/bin/env bash
# The real-data study (issue 30; docs/real_data.md "Results"): imports the MIT
# push dataset, runs its trials on replay cells, evaluates arena at several
# settings and MuJoCo against the measured pushes, calibrates the frictions
# on every trial and by shape (fit on three shapes, score on the fourth),
# evaluates again with the fit, and prints the tables.
#
#   scripts/real_data_study.sh [--data DIR] [--arena BIN] [--work DIR] [--check FILE]
#
# --data   the dataset folder (default: ../shared/data/mit-push beside the repo);
#          absent: the study is skipped, saying why (exit 77)
# --arena  the arena binary (default: build/bin/arena)
# --work   where the dataset, store and reports go (default: a new temporary folder)
# The plot of where the model is far from the data: WORK/real_data_errors.svg.
# --check  compare the tables with the block between the markers
#          <!-- real-data-study:begin --> and <!-- real-data-study:end --> in FILE
#          (every figure but wall times); exit 1 on a difference; repeatable
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
data="$here/../shared/data/mit-push"
arena="$here/build/bin/arena"
work=""
check=()
while (($#)); do
  case "$1" in
    --data) data="$2"; shift 2 ;;
    --arena) arena="$2"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    --check) check+=(--check "$2"); shift 2 ;;
    -h|--help) sed -n '2,18p' "$0"; exit 0 ;;
    *) echo "real_data_study: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
if [[ ! -d "$data" || ! -f "$data/shapes.json" ]]; then
  echo "real_data_study: SKIPPED: no push dataset at $data (a folder with shapes.json and the" \
       "pushes' .h5 files; bring your own copy: docs/real_data.md)"
  exit 77
fi
if [[ ! -x "$arena" ]]; then
  echo "real_data_study: no arena binary at $arena (build it, or give --arena)" >&2
  exit 2
fi
if [[ -z "$work" ]]; then
  work="$(mktemp -d "${TMPDIR:-/tmp}/real_data_study.XXXXXX")"
  trap 'rm -rf "$work"' EXIT
fi
mkdir -p "$work"
ds="$work/dataset"
db="$work/real.db"
rm -rf "$ds" "$db" "$db"-* "$work"/*.json
log="$work/study.log"
: > "$log"

# The settings the study compares (docs/real_data.md "Results").
arena_dt="0.016,0.008"
mujoco_ts="0.002"
fit_params="mu_pusher,pressure_rim"
fit_model='{"dt": 0.016}'

start=$(date +%s.%N)
step() {  # step NAME COMMAND...: runs it, logging its output and its time
  local name="$1"; shift
  local t0; t0=$(date +%s.%N)
  echo "== $name: $*" >> "$log"
  local rc=0
  "$@" >> "$log" 2>&1 || rc=$?
  printf '%s %.1f\n' "$name" "$(echo "$(date +%s.%N) - $t0" | bc)" >> "$work/times.txt"
  return $rc
}
: > "$work/times.txt"
fail() { echo "real_data_study: $1 failed (exit $2); its output is in $log:" >&2; tail -20 "$log" >&2; exit 1; }

step import "$arena" import push-dataset "$data" --shapes "$data/shapes.json" --out "$ds" \
  || fail import $?
rc=0
step run "$arena" run "$ds/campaign.json" --backend "replay:$ds" --db "$db" --quiet || rc=$?
done_trials=$(sqlite3 "$db" "SELECT count(*) FROM trials WHERE state = 'done'" 2>/dev/null || echo 0)
planned=$(sqlite3 "$db" "SELECT count(*) FROM trials" 2>/dev/null || echo 0)
if ((rc != 0)); then
  # The figures are over the trials that ran; the tables' "scored" column says how many.
  ((done_trials >= 4)) || fail run $rc
  echo "real_data_study: arena run exit $rc: $done_trials of $planned trials done; the study" \
       "goes on with those (arena status --db $db)" >&2
fi
common=(--db "$db" --campaign 1 --group-by shape --trial-parameters "$ds/trials.csv"
        --convergence-trials 0 --json)
step evaluate "$arena" evaluate "${common[@]}" --predictors arena,mujoco --facets 8 --dt "$arena_dt" \
  --mujoco-timestep "$mujoco_ts" --out "$work/evaluate_before.json" || fail evaluate $?
# The reference's protocol: fit every trial, score the same trials.
cal=(--db "$db" --campaign 1 --params "$fit_params" --loss nmse --bootstrap 0 --profile-points 0
     --max-evaluations 20 --lower 0.05
     --predictor-settings "$fit_model" --threads 2 --json)
rc=0
step calibrate_all "$arena" calibrate "${cal[@]}" --holdout 0 --out "$work/calibrate_all.json" || rc=$?
((rc <= 1)) || fail calibrate_all $rc  # 1: stored, not improved (the tables say so)
rc=0
step calibrate_by_shape "$arena" calibrate "${cal[@]}" --holdout-by shape \
  --trial-parameters "$ds/trials.csv" --out "$work/calibrate_by_shape.json" || rc=$?
((rc <= 1)) || fail calibrate_by_shape $rc
fitted=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["id"])' \
  "$work/calibrate_all.json")
step evaluate_calibrated "$arena" evaluate "${common[@]}" --predictors arena --facets 8 \
  --dt "$arena_dt" --calibration "$fitted" --out "$work/evaluate_after.json" \
  || fail evaluate_calibrated $?
# MuJoCo spreads the support's load by its own contacts (uniform pressure; it
# refuses weighted points): it takes the fitted pusher friction alone.
mu_scale=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["params"]["mu_pusher"]["scale"])' \
  "$work/calibrate_all.json")
step evaluate_calibrated_mujoco "$arena" evaluate "${common[@]}" --predictors mujoco \
  --mujoco-timestep "$mujoco_ts" --scale "mu_pusher=$mu_scale" \
  --out "$work/evaluate_after_mujoco.json" || fail evaluate_calibrated_mujoco $?
total=$(echo "$(date +%s.%N) - $start" | bc)

python3 "$here/scripts/real_data_tables.py" --work "$work" --total "$total" \
  --settings "arena dt $arena_dt; mujoco timestep $mujoco_ts; fitted $fit_params at $fit_model" \
  --plot "$work/real_data_errors.svg" "${check[@]}"
