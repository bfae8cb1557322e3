#!/usr/bin/env bash
# Peak memory of `cvd run` with the training pairs in memory vs streamed from the flow cache
# (issue 19), on generated clips of several lengths (`cvd scene`, ground-truth poses given, so no
# COLMAP): peak RSS (GNU time), pair count, and the training time per epoch of both (the
# background prefetch should hide the reads). Each length runs the flow stage once; the second
# storage mode reuses its cache.
#
# usage: bench/pair_memory.sh [path/to/cvd] [output dir]
# environment: FRAMES="40 300" WIDTH_PX=320 HEIGHT_PX=240 DEPTH_SIZE=256 EPOCHS=1
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd="${1:-$here/../build/cvd}"
out="${2:-$(mktemp -d /tmp/cvd-pair-memory.XXXXXX)}"
[[ -x "$cvd" ]] || { echo "pair_memory.sh: cvd binary '$cvd' not found" >&2; exit 2; }
[[ -x /usr/bin/time ]] || { echo "pair_memory.sh: needs GNU time (apt install time)" >&2; exit 2; }
command -v jq >/dev/null || { echo "pair_memory.sh: needs jq" >&2; exit 2; }
FRAMES="${FRAMES:-40 300}" WIDTH_PX="${WIDTH_PX:-320}" HEIGHT_PX="${HEIGHT_PX:-240}"
DEPTH_SIZE="${DEPTH_SIZE:-256}" EPOCHS="${EPOCHS:-1}"
echo "pair_memory: $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores ($(lscpu | sed -n 's/^Model name: *//p')), load $(cut -d' ' -f1 /proc/loadavg)" >&2
printf "%-8s %-8s %7s %12s %10s\n" frames pairs count "peak RSS MB" "epoch s"
for n in $FRAMES; do
  scene="$out/scene$n"
  [[ -d "$scene/rgb" ]] || "$cvd" -q scene --out "$scene" --frames "$n" --width "$WIDTH_PX" --height "$HEIGHT_PX" > /dev/null
  K=$(jq -r '"\(.fx),\(.fy),\(.cx),\(.cy)"' "$scene/intrinsics.json")
  for mode in memory stream; do
    run="$out/run$n"
    rm -rf "$run/cache/training" "$run/run.json"
    /usr/bin/time -f "%M" -o "$out/rss" "$cvd" -q run "$scene/rgb" -o "$run" --poses "$scene/poses.txt" \
      --poses-format tum --intrinsics "$K" --depth-size "$DEPTH_SIZE" --epochs "$EPOCHS" \
      --width 0.125 --warmup 20 --no-videos --no-ply --formats pfm --pairs "$mode" > "$out/log$n.$mode" 2>&1
    printf "%-8s %-8s %7s %12.0f %10.1f\n" "$n" "$mode" "$(jq '.pairs.kept' "$run/run.json")" \
      "$(echo "$(tail -1 "$out/rss") / 1024" | bc -l)" "$(jq ".timings_s.training / $EPOCHS" "$run/run.json")"
  done
done
