#!/usr/bin/env bash
# End-point error of `cvd flow` on the MPI-Sintel pairs in ../shared/data/sintel_flow: one row per
# scene x pass x method (DIS preset, or FlowNet2 when weights are given) x homography pre-warp.
# EPE "all" excludes Sintel's invalid pixels, "noc" also excludes occluded ones (frame_0002 ->
# frame_0003, the only pair with ground truth).
#
# usage: bench/sintel_epe.sh [path/to/cvd] [path/to/sintel_flow] [flownet2.cvdw]
#   flownet2.cvdw: FlowNet2 weights (e.g. from `cvd convert flownet2.onnx --arch flownet2`); adds
#   rows of method "flownet2" (cvd flow --method flownet2 --model ...).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd="${1:-$here/../build/cvd}"
data="${2:-$here/../../shared/data/sintel_flow}"
[[ -x "$cvd" ]] || { echo "sintel_epe.sh: cvd binary '$cvd' not found or not executable" >&2; exit 2; }
[[ -d "$data" ]] || { echo "sintel_epe.sh: Sintel data '$data' not found" >&2; exit 2; }
flownet2="${3:-}"
[[ -z "$flownet2" || -f "$flownet2" ]] || { echo "sintel_epe.sh: FlowNet2 weights '$flownet2' not found" >&2; exit 2; }
methods=(ultrafast fast medium)
[[ -n "$flownet2" ]] && methods+=(flownet2)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

printf '%-8s %-5s %-9s %-5s %9s %9s %8s %8s %7s\n' scene pass method homog epe_all epe_noc valid_fw '>3px' seconds
for scene in alley_1 cave_2; do
  gt="$data/$scene/gt"
  for pass in clean final; do
    for preset in "${methods[@]}"; do
      for homog in on off; do
        extra=(--preset "$preset")
        [[ $preset == flownet2 ]] && extra=(--method flownet2 --model "$flownet2")
        [[ $homog == off ]] && extra+=(--no-homography)
        out="$("$cvd" flow "$data/$scene/$pass/frame_0002.png" "$data/$scene/$pass/frame_0003.png" \
          -o "$tmp/f.flo" "${extra[@]}" --gt "$gt/frame_0002.flo" \
          --gt-invalid "$gt/invalid/frame_0002.png" --gt-occluded "$gt/occlusions/frame_0002.png")"
        all=$(awk '/^epe_all/ {print $2}' <<<"$out")
        above=$(awk '/^epe_all/ {gsub(/[(%]/, "", $7); print $7}' <<<"$out")
        noc=$(awk '/^epe_noc/ {print $2}' <<<"$out")
        valid=$(sed -n 's/.*: \([0-9.]*\)% valid forward.*/\1/p' <<<"$out")
        secs=$(sed -n 's/.*; \([0-9.]*\) s$/\1/p' <<<"$out")
        printf '%-8s %-5s %-9s %-5s %9s %9s %7s%% %7s%% %7s\n' "$scene" "$pass" "$preset" "$homog" \
          "$all" "$noc" "$valid" "$above" "$secs"
      done
    done
  done
done
