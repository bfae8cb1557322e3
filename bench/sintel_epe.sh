#!/usr/bin/env bash
# End-point error of `cvd flow` on the MPI-Sintel pairs in ../shared/data/sintel_flow: one row per
# scene x pass x DIS preset x homography pre-warp. EPE "all" excludes Sintel's invalid pixels,
# "noc" also excludes occluded ones (frame_0002 -> frame_0003, the only pair with ground truth).
#
# usage: bench/sintel_epe.sh [path/to/cvd] [path/to/sintel_flow]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd="${1:-$here/../build/cvd}"
data="${2:-$here/../../shared/data/sintel_flow}"
[[ -x "$cvd" ]] || { echo "sintel_epe.sh: cvd binary '$cvd' not found or not executable" >&2; exit 2; }
[[ -d "$data" ]] || { echo "sintel_epe.sh: Sintel data '$data' not found" >&2; exit 2; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

printf '%-8s %-5s %-9s %-5s %9s %9s %8s %8s %7s\n' scene pass preset homog epe_all epe_noc valid_fw '>3px' seconds
for scene in alley_1 cave_2; do
  gt="$data/$scene/gt"
  for pass in clean final; do
    for preset in ultrafast fast medium; do
      for homog in on off; do
        extra=()
        [[ $homog == off ]] && extra+=(--no-homography)
        out="$("$cvd" flow "$data/$scene/$pass/frame_0002.png" "$data/$scene/$pass/frame_0003.png" \
          -o "$tmp/f.flo" --preset "$preset" "${extra[@]}" --gt "$gt/frame_0002.flo" \
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
