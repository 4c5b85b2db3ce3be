#!/usr/bin/env bash
# Fuzz the scene and campaign readers and the ground-truth sample decoder with libFuzzer (clang from Debian) for a
# bounded time each. Not part of CI: run by hand, e.g. `scripts/fuzz.sh 120`.
# Crashers are copied to tests/fuzz/crashers/<target>/, where the unit tests
# replay them (tests/mechanics/scene_json_test.cpp, tests/orchestrator/campaign_test.cpp,
# tests/executors/ground_truth_codec_test.cpp).
set -euo pipefail
seconds="${1:-60}"
root="$(cd "$(dirname "$0")/.." && pwd)"
out="$root/build-fuzz"
mkdir -p "$out"
flags=(-std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-omit-frame-pointer
       -I"$root/mechanics/include" -I"$root/orchestrator/include" -I/usr/include/eigen3)

clang++ "${flags[@]}" -o "$out/scene_fuzz" "$root/tests/fuzz/scene_fuzz.cpp" \
  "$root/mechanics/src/scene_json.cpp"
clang++ "${flags[@]}" -o "$out/campaign_fuzz" "$root/tests/fuzz/campaign_fuzz.cpp" \
  "$root/mechanics/src/scene_json.cpp" "$root/orchestrator/src/campaign.cpp" "$root/orchestrator/src/sampler.cpp"
# The decoder's DDS types, generated from the IDL as the build does.
gen="$out/generated/arena/schemas"
mkdir -p "$gen"
fastddsgen -cs -replace -d "$gen" "$root/schemas/arena.idl" > /dev/null
clang++ "${flags[@]}" -I"$root/schemas/include" -I"$out/generated" -I"$gen" -o "$out/ground_truth_fuzz" \
  "$root/tests/fuzz/ground_truth_fuzz.cpp" "$root/schemas/src/ground_truth.cpp" "$gen/arena.cxx" \
  "$gen/arenaPubSubTypes.cxx" -lfastrtps -lfastcdr
mkdir -p "$out/seeds_ground_truth"
ARENA_GT_SEEDS="$out/seeds_ground_truth" "$out/ground_truth_fuzz" -runs=0 > /dev/null 2>&1

run() {  # target, seed dirs...
  local target="$1"; shift
  local corpus="$out/corpus_$target" crashes="$root/tests/fuzz/crashers/$target"
  mkdir -p "$corpus" "$crashes"
  for dir in "$@"; do cp -n "$dir"/*.json "$dir"/*.cdr "$corpus"/ 2>/dev/null || true; done
  # -rss_limit_mb: a reader that balloons on a 1 MiB input is a bug too.
  "$out/$target" "$corpus" -max_total_time="$seconds" -max_len=65536 -timeout=30 -rss_limit_mb=1024 \
    -artifact_prefix="$crashes/" -print_final_stats=1 || echo "$target: found a problem, see $crashes"
}
run scene_fuzz "$root/examples/scenes" "$root/tests/bad_inputs/scenes"
run campaign_fuzz "$root/examples/campaigns" "$root/tests/bad_inputs/campaigns"
run ground_truth_fuzz "$out/seeds_ground_truth"
