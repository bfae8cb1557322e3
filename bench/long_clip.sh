#!/usr/bin/env bash
# A long generated clip end to end (issue 19, item 3): `cvd scene --frames N` (the demo's room,
# exact poses and depth), then `cvd run` with the scene's poses, the training pairs streamed from
# the flow cache and a step budget (--steps), then `cvd eval`. Prints the frame and pair counts,
# every stage's time (run.json timings_s), peak RSS (GNU time, the whole process) and the depth
# error, for each clip length in FRAMES, so that the growth with the number of frames shows.
#
# usage: bench/long_clip.sh [path/to/cvd] [output dir]
# environment: FRAMES="300 2000" WIDTH_PX=160 HEIGHT_PX=120 DEPTH_SIZE=160 STEPS=2000 EPOCHS=4
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd="${1:-$here/../build/cvd}"
out="${2:-$(mktemp -d /tmp/cvd-long-clip.XXXXXX)}"
[[ -x "$cvd" ]] || { echo "long_clip.sh: cvd binary '$cvd' not found" >&2; exit 2; }
[[ -x /usr/bin/time ]] || { echo "long_clip.sh: needs GNU time (apt install time)" >&2; exit 2; }
command -v jq >/dev/null || { echo "long_clip.sh: needs jq" >&2; exit 2; }
FRAMES="${FRAMES:-300 2000}" WIDTH_PX="${WIDTH_PX:-160}" HEIGHT_PX="${HEIGHT_PX:-120}"
DEPTH_SIZE="${DEPTH_SIZE:-160}" STEPS="${STEPS:-2000}" EPOCHS="${EPOCHS:-4}"
echo "long_clip: $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores ($(lscpu | sed -n 's/^Model name: *//p')), load $(cut -d' ' -f1 /proc/loadavg), outputs in $out" >&2
mkdir -p "$out"
echo "| frames | pairs kept / tried | flow s | initial depth s | training s (steps) | outputs s | total s | peak RSS MB | AbsRel per frame before / after |"
echo "|---|---|---|---|---|---|---|---|---|"
for n in $FRAMES; do
  scene="$out/scene$n" run="$out/run$n"
  [[ -d "$scene/rgb" ]] || "$cvd" -q scene --out "$scene" --frames "$n" --width "$WIDTH_PX" \
    --height "$HEIGHT_PX" > /dev/null
  K=$(jq -r '"\(.fx),\(.fy),\(.cx),\(.cy)"' "$scene/intrinsics.json")
  /usr/bin/time -f "%M" -o "$out/rss$n" "$cvd" -q run "$scene/rgb" -o "$run" \
    --poses "$scene/poses.txt" --poses-format tum --intrinsics "$K" --depth-size "$DEPTH_SIZE" \
    --epochs "$EPOCHS" --steps "$STEPS" --pairs stream --no-videos --no-ply --formats pfm \
    > "$out/log$n" 2>&1 ||
    { echo "long_clip.sh: cvd run ($n frames) failed; see $out/log$n" >&2; tail -5 "$out/log$n" >&2; exit 1; }
  "$cvd" -q eval --pred "$run" --gt "$scene" --out "$run/eval" >> "$out/log$n" 2>&1
  "$cvd" -q eval --pred "$run" --gt "$scene" --depth-dir depth_initial --out "$run/eval_initial" \
    >> "$out/log$n" 2>&1
  r="$run/run.json"
  printf "| %s | %s / %s | %.0f | %.0f | %.0f (%s) | %.0f | %.0f | %.0f | %.3f / %.3f |\n" "$n" \
    "$(jq '.pairs.kept' "$r")" "$(jq '.pairs.kept + .pairs.dropped' "$r")" \
    "$(jq '.timings_s.flow' "$r")" "$(jq '.timings_s.initial_depth' "$r")" \
    "$(jq '.timings_s.training' "$r")" "$(jq '.training.steps_per_epoch * .training.epochs' "$r")" \
    "$(jq '.timings_s.outputs' "$r")" "$(jq '.timings_s.total' "$r")" \
    "$(echo "$(cat "$out/rss$n") / 1024" | bc -l)" \
    "$(jq '.depth.median_frame.depth.abs_rel' "$run/eval_initial/metrics.json")" \
    "$(jq '.depth.median_frame.depth.abs_rel' "$run/eval/metrics.json")"
done
echo
echo "settings: ${WIDTH_PX}x${HEIGHT_PX} cvd scene clips, the scene's poses and intrinsics given, depth $DEPTH_SIZE px, --steps $STEPS over $EPOCHS epochs, --pairs stream, other flags at their defaults"
