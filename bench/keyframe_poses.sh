#!/usr/bin/env bash
# Poses on a long generated clip (issue 23): COLMAP on keyframes (`--colmap-keyframes auto`, the
# default) against COLMAP mapping every frame (`all`), same clip, same settings, one after the
# other. Prints per setting: the pose stage's time (run.json timings_s.poses), registered frames,
# ATE / RPE against the scene's exact poses and the final depth AbsRel (`cvd eval`).
# The clip is `cvd scene` (the demo's textured room, exact depth and poses), intrinsics given.
#
# usage: bench/keyframe_poses.sh [path/to/cvd] [output dir]
# environment: FRAMES=600 WIDTH_PX=320 HEIGHT_PX=240 DEPTH_SIZE=192 EPOCHS=2 MODES="auto all"
#   STEPS=0 (a training step budget, `cvd run --steps`; 0: every pair each epoch)
#   LIMIT_S=0 (stop a run after this many seconds and report how far it got; 0: no limit)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd="${1:-$here/../build/cvd}"
out="${2:-$(mktemp -d /tmp/cvd-keyframe-poses.XXXXXX)}"
[[ -x "$cvd" ]] || { echo "keyframe_poses.sh: cvd binary '$cvd' not found" >&2; exit 2; }
command -v jq >/dev/null || { echo "keyframe_poses.sh: needs jq" >&2; exit 2; }
command -v colmap >/dev/null || { echo "keyframe_poses.sh: needs colmap on PATH" >&2; exit 2; }
FRAMES="${FRAMES:-600}" WIDTH_PX="${WIDTH_PX:-320}" HEIGHT_PX="${HEIGHT_PX:-240}"
DEPTH_SIZE="${DEPTH_SIZE:-192}" EPOCHS="${EPOCHS:-2}" MODES="${MODES:-auto all}"
STEPS="${STEPS:-0}" LIMIT_S="${LIMIT_S:-0}"
echo "keyframe_poses: $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores ($(lscpu | sed -n 's/^Model name: *//p')), load $(cut -d' ' -f1 /proc/loadavg), outputs in $out" >&2
mkdir -p "$out"
scene="$out/scene"
[[ -d "$scene/rgb" ]] || "$cvd" -q scene --out "$scene" --frames "$FRAMES" --width "$WIDTH_PX" \
  --height "$HEIGHT_PX" > /dev/null
K=$(jq -r '"\(.fx),\(.fy),\(.cx),\(.cy)"' "$scene/intrinsics.json")

printf "| %s | %s | %s | %s | %s | %s | %s | %s |\n" "--colmap-keyframes" "mapped by the mapper" \
  "pose stage" "registered" "ATE" "RPE rot @1 / @10" "AbsRel per frame / video" "total"
echo "|---|---|---|---|---|---|---|---|"
for mode in $MODES; do
  run="$out/$mode"
  t0=$(date +%s) rc=0
  timeout "$LIMIT_S" "$cvd" run "$scene/rgb" -o "$run" --intrinsics "$K" --poses-source colmap \
    --colmap-keyframes "$mode" --depth-size "$DEPTH_SIZE" --epochs "$EPOCHS" --steps "$STEPS" \
    --no-videos --no-ply --formats pfm > "$out/$mode.log" 2>&1 || rc=$?
  if [[ $rc -eq 124 ]]; then
    # The time limit: say which stage the run was in (its last progress line) and go on.
    printf "| %s | stopped after %s s, in: %s | | | | | | |\n" "$mode" "$(( $(date +%s) - t0 ))" \
      "$(grep -v '^\s*$' "$out/$mode.log" | tail -1 | cut -c1-100 | tr '|' '/')"
    continue
  fi
  [[ $rc -eq 0 ]] ||
    { echo "keyframe_poses.sh: cvd run ($mode) failed; see $out/$mode.log" >&2; tail -5 "$out/$mode.log" >&2; exit 1; }
  "$cvd" -q eval --pred "$run" --gt "$scene" --out "$run/eval" >> "$out/$mode.log" 2>&1
  m="$run/eval/metrics.json" r="$run/run.json"
  printf "| %s | %s | %.0f s | %s/%s | %.2f cm | %s | %s | %.0f s |\n" "$mode" \
    "$(jq -r '.poses.details.keyframes.mapped' "$r") mapped, $(jq -r '.poses.details.keyframes.matched_pairs' "$r") pairs matched" \
    "$(jq '.timings_s.poses' "$r")" "$(jq '.frame_stats.registered' "$r")" "$FRAMES" \
    "$(jq '.pose.ate_rmse * 100' "$m")" \
    "$(jq -r '[.pose.rpe[0], .pose.rpe[-1]] | map("\(.rot_mean_deg * 1000 | round / 1000) deg @\(.delta)") | join(" / ")' "$m")" \
    "$(jq -r '[.depth.median_frame.depth.abs_rel, .depth.median_video.depth.abs_rel] | map(. * 1000 | round / 1000 | tostring) | join(" / ")' "$m")" \
    "$(jq '.timings_s.total' "$r")"
done
echo
echo "settings: $FRAMES frames of ${WIDTH_PX}x${HEIGHT_PX} (cvd scene), intrinsics given, depth $DEPTH_SIZE px, $EPOCHS epochs, --steps $STEPS, time limit ${LIMIT_S} s, other flags at their defaults"
