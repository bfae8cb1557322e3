#!/usr/bin/env bash
# The full pipeline on the real 7-Scenes kitchen clip (../shared/data/7scenes_redkitchen_f000000-000149),
# twice: with its ground-truth poses, and with COLMAP's; each evaluated against the measured depth.
# Prints one table: the network before test-time training (the default network after its sparse
# warm-up, or --model's output), cvd after training, and the sparse points the run started from
# (COLMAP's, or triangulated from flow when the poses were given): density and AbsRel on their
# pixels. Depth errors align each frame by its median ("per frame", the paper's protocol) and the
# whole video by one median scale ("per video": rewards consistency).
#
# usage: bench/eval_7scenes.sh [path/to/cvd] [output dir]
# environment (defaults sized for a 2-core machine, ~30 min in all):
#   FRAMES=40 FRAME_STEP=1 DEPTH_SIZE=192 WIDTH=0.125 EPOCHS=4 WARMUP=60
#   INTRINSICS=525,525,320,240 (empty: estimated; ground-truth-pose runs then need --fov, skipped)
#   EXTRA="--flag value ..." (more cvd run flags for every run)
#   MODEL=weights.cvdw ARCH=mannequin|midas_small|midas_v2 (converted pretrained weights, optional)
#   POSES="gt colmap" (which runs: gt, colmap, flow (cameras from optical flow, --poses-source
#   flow); suffixes: "+all" gives COLMAP's mapper every frame
#   (--colmap-keyframes all) instead of keyframes; "+colmappts" (gt only) triangulates the sparse
#   points with COLMAP on the given poses (--sparse-points colmap); "+adjusted" (gt only) adjusts
#   the given poses and their points on flow tracks (--given-poses adjusted), "+fixed" (gt only)
#   uses them as they are (--given-poses fixed; plain "gt" lets cvd choose, the default auto);
#   "+refine", last, adds
#   --refine-poses $REFINE (default full) and reuses the cache of the run without it, so both start from the same poses
#   and flow)
# Needs jq; colmap on PATH for the COLMAP run (skipped with a note when absent).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd="${1:-$here/../build/cvd}"
out="${2:-$(mktemp -d /tmp/cvd-eval-7scenes.XXXXXX)}"
data="$here/../../shared/data/7scenes_redkitchen_f000000-000149"
[[ -x "$cvd" ]] || { echo "eval_7scenes.sh: cvd binary '$cvd' not found or not executable" >&2; exit 2; }
[[ -d "$data/rgb" ]] || { echo "eval_7scenes.sh: 7-Scenes data '$data' not found" >&2; exit 2; }
command -v jq >/dev/null || { echo "eval_7scenes.sh: needs jq (apt-get install jq)" >&2; exit 2; }
FRAMES="${FRAMES:-40}" FRAME_STEP="${FRAME_STEP:-1}" DEPTH_SIZE="${DEPTH_SIZE:-192}"
WIDTH="${WIDTH:-0.125}" EPOCHS="${EPOCHS:-4}" WARMUP="${WARMUP:-60}" POSES="${POSES:-gt colmap}"
common=(--max-frames "$FRAMES" --frame-step "$FRAME_STEP" --depth-size "$DEPTH_SIZE"
  --epochs "$EPOCHS" --gt "$data" --no-videos)
# EXTRA: more cvd run flags for every run (word-split), e.g. EXTRA="--warmup-scale video".
read -r -a extra_flags <<<"${EXTRA:-}"
common+=("${extra_flags[@]}")
# INTRINSICS= (empty) leaves the focal to the pipeline's estimate (the run then needs no --intrinsics).
INTRINSICS="${INTRINSICS-525,525,320,240}"
[[ -n "$INTRINSICS" ]] && common+=(--intrinsics "$INTRINSICS")
if [[ -n "${MODEL:-}" ]]; then
  common+=(--model "$MODEL" --arch "${ARCH:?ARCH must name the architecture of MODEL}")
else
  common+=(--width "$WIDTH" --warmup "$WARMUP")
fi
mkdir -p "$out"
echo "eval_7scenes: $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores, outputs in $out" >&2

rows=()
for poses in $POSES; do
  run="$out/$poses"
  extra=()
  base="${poses%+refine}"
  if [[ $base == *+all ]]; then
    extra+=(--colmap-keyframes all)
  fi
  if [[ $base == *+colmappts ]]; then
    extra+=(--sparse-points colmap)
  fi
  if [[ $base == *+adjusted ]]; then
    extra+=(--given-poses adjusted)
  fi
  if [[ $base == *+fixed ]]; then
    extra+=(--given-poses fixed)
  fi
  if [[ $base != "$poses" ]]; then
    extra+=(--refine-poses "${REFINE:-full}")
    if [[ -d "$out/$base/cache" ]]; then
      rm -rf "$run" && mkdir -p "$run" && cp -r "$out/$base/cache" "$run/cache"
      rm -rf "$run/cache/training"
    fi
  fi
  if [[ ${base%%+*} == gt ]]; then
    extra+=(--poses "$data/groundtruth_rgb.txt" --poses-format tum)
  elif [[ ${base%%+*} == flow ]]; then
    extra+=(--poses-source flow)
  elif ! command -v colmap >/dev/null; then
    echo "eval_7scenes: colmap not on PATH, COLMAP run skipped" >&2
    continue
  fi
  start=$(date +%s)
  "$cvd" --quiet run "$data/rgb" -o "$run" "${common[@]}" "${extra[@]}" >"$out/$poses.log" 2>&1 ||
    { echo "eval_7scenes: cvd run ($poses poses) failed; see $out/$poses.log" >&2; tail -5 "$out/$poses.log" >&2; exit 1; }
  # The pipeline's own total (a rerun that resumed from the cache reports only what it redid).
  secs=$(jq -r '.timings_s.total | round' "$run/run.json" 2>/dev/null || echo $(($(date +%s) - start)))
  "$cvd" eval --pred "$run" --gt "$data" --depth-dir depth_initial --out "$run/eval_initial" \
    >>"$out/$poses.log" 2>&1
  final="$run/eval/metrics.json" initial="$run/eval_initial/metrics.json"
  ate=$(jq -r 'if .pose then (.pose.ate_rmse * 100 | . * 10 | round / 10 | tostring) else "-" end' "$final")
  # Rotation error between frames (RPE, mean degrees) at the smallest and largest frame step.
  rpe=$(jq -r 'if .pose and (.pose.rpe | length) > 0 then ([.pose.rpe[0], .pose.rpe[-1]] |
    map("\(.rot_mean_deg * 1000 | round / 1000) deg @\(.delta)") | join(", ")) else "-" end' "$final")
  # Direction of the motion in the cameras' frames (RPE, mean degrees) at the largest frame step:
  # what ATE's similarity fit can hide on a short path.
  dir=$(jq -r 'if .pose and (.pose.rpe | length) > 0 and (.pose.rpe[-1].dir_mean_deg != null) then
    (.pose.rpe[-1] | "\(.dir_mean_deg * 10 | round / 10) deg @\(.delta)") else "-" end' "$final")
  registered=$(jq -r '.frame_stats.registered' "$run/run.json")
  # Peak resident memory of cvd itself (run.json; absent from runs of older builds).
  rss=$(jq -r 'if .peak_rss_mb then ", peak RSS \(.peak_rss_mb.process | round) MB" else "" end' "$run/run.json")
  focal=""
  [[ -z "$INTRINSICS" ]] && focal=", focal $(jq -r '.poses.details.intrinsics.fx | round' "$run/run.json") px"
  label="$poses ($registered/$FRAMES frames, ATE ${ate} cm, RPE rot ${rpe}, motion direction ${dir}${focal}, ${secs} s${rss})"
  row() {  # label, what, metrics file
    jq -r --arg l "$1" --arg w "$2" '[$l, $w,
      (.depth.median_frame.depth.abs_rel | . * 1000 | round / 1000 | tostring),
      (.depth.median_video.depth.abs_rel | . * 1000 | round / 1000 | tostring),
      (.depth.median_frame.depth.delta1 | . * 1000 | round / 1000 | tostring), "100%"] | join(" | ")' "$3"
  }
  rows+=("$(row "$label" "network before training" "$initial")")
  rows+=("$(row "$label" "cvd after training" "$final")")
  src=$(jq -r '.sparse_points.source' "$run/run.json")
  rows+=("$(jq -r --arg l "$label" --arg w "sparse points ($src)" '[$l, $w,
      (.sparse.abs_rel | . * 1000 | round / 1000 | tostring),
      (.sparse.abs_rel_video | . * 1000 | round / 1000 | tostring),
      (.sparse.delta1 | . * 1000 | round / 1000 | tostring),
      ((.sparse.density * 10000 | round / 100 | tostring) + "%")] | join(" | ")' "$final")")
done

echo
echo "| poses | depth | AbsRel (per-frame median) | AbsRel (one scale per video) | delta<1.25 | pixels covered |"
echo "|---|---|---|---|---|---|"
for r in "${rows[@]}"; do echo "| $r |"; done
echo
echo "settings: frames $FRAMES (step $FRAME_STEP), depth $DEPTH_SIZE px long side, epochs $EPOCHS," \
  "${MODEL:+model $MODEL}${MODEL:-default network width $WIDTH, warm-up $WARMUP steps}"
