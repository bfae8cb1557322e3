#!/usr/bin/env bash
# Multi-process scaling of `cvd run` (issue 21) on the real 7-Scenes kitchen clip with its
# ground-truth poses (no COLMAP): the same run as ONE process with $THREADS threads and as
# `mpirun -np $RANKS` with THREADS/RANKS threads each, from empty output folders. Prints the flow
# stage and the training time per epoch of both, the speed-up, the bytes each rank all-reduces per
# training step, and the depth difference between the two runs (AbsRel per video of each, from
# cvd's own evaluation against the measured depth).
#
# usage: bench/mpi_scaling.sh [path/to/cvd] [output dir]
# environment: RANKS=2 THREADS=2 FRAMES=40 DEPTH_SIZE=192 WIDTH=0.125 EPOCHS=2 WARMUP=20
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd="${1:-$here/../build/cvd}"
out="${2:-$(mktemp -d /tmp/cvd-mpi-scaling.XXXXXX)}"
data="$here/../../shared/data/7scenes_redkitchen_f000000-000149"
[[ -x "$cvd" ]] || { echo "mpi_scaling.sh: cvd binary '$cvd' not found" >&2; exit 2; }
[[ -d "$data/rgb" ]] || { echo "mpi_scaling.sh: 7-Scenes data '$data' not found" >&2; exit 2; }
command -v mpirun >/dev/null || { echo "mpi_scaling.sh: mpirun not found (apt install openmpi-bin)" >&2; exit 2; }
command -v jq >/dev/null || { echo "mpi_scaling.sh: needs jq" >&2; exit 2; }
"$cvd" --version | grep -q "MPI: Open MPI" || { echo "mpi_scaling.sh: $cvd was built without MPI" >&2; exit 2; }
RANKS="${RANKS:-2}" THREADS="${THREADS:-2}" FRAMES="${FRAMES:-40}" DEPTH_SIZE="${DEPTH_SIZE:-192}"
WIDTH="${WIDTH:-0.125}" EPOCHS="${EPOCHS:-2}" WARMUP="${WARMUP:-20}"
per_rank=$(( THREADS / RANKS > 0 ? THREADS / RANKS : 1 ))
args=(--max-frames "$FRAMES" --depth-size "$DEPTH_SIZE" --epochs "$EPOCHS" --width "$WIDTH"
  --warmup "$WARMUP" --intrinsics 525,525,320,240 --poses "$data/groundtruth_rgb.txt"
  --poses-format tum --gt "$data" --no-videos --no-ply)
mkdir -p "$out"
echo "mpi_scaling: $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores ($(lscpu | sed -n 's/^Model name: *//p')), load $(cut -d' ' -f1 /proc/loadavg)" >&2
rm -rf "$out/one" "$out/ranks"
OMP_NUM_THREADS=$THREADS "$cvd" -q run "$data/rgb" -o "$out/one" "${args[@]}" > "$out/one.log" 2>&1
mpirun --oversubscribe --allow-run-as-root -np "$RANKS" -x OMP_NUM_THREADS=$per_rank \
  "$cvd" -q run "$data/rgb" -o "$out/ranks" "${args[@]}" > "$out/ranks.log" 2>&1
row() {  # label, run dir
  local j="$2/run.json"
  printf "%-32s %8.1f %10.1f %10s %9s\n" "$1" "$(jq '.timings_s.flow' "$j")" \
    "$(jq ".timings_s.training / $EPOCHS" "$j")" \
    "$(jq -r '.processes.allreduce_bytes_per_step // "-"' "$j")" \
    "$(jq '.depth.median_video.depth.abs_rel | . * 1000 | round / 1000' "$2/eval/metrics.json")"
}
printf "%-32s %8s %10s %10s %9s\n" "run ($FRAMES frames, ${DEPTH_SIZE}px)" "flow s" "epoch s" "bytes/step" "AbsRel"
row "1 process x $THREADS threads" "$out/one"
row "$RANKS ranks x $per_rank thread(s)" "$out/ranks"
jq -n --slurpfile a "$out/one/run.json" --slurpfile b "$out/ranks/run.json" \
  '"speed-up: flow \($a[0].timings_s.flow / $b[0].timings_s.flow | . * 100 | round / 100)x, training \($a[0].timings_s.training / $b[0].timings_s.training | . * 100 | round / 100)x; loss after \($a[0].training.geometric_loss_after) vs \($b[0].training.geometric_loss_after)"' -r
