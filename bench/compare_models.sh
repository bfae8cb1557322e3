#!/usr/bin/env bash
# Depth networks, ours vs PyTorch on CPU, same weights and inputs: inference and one training
# step (forward in BN train mode + backward + Adam) with 8 images, MiDaS v2 and Mannequin at
# 384x224, MiDaS small at 256x160, Depth Anything V2 ViT-S at 518x392 (DA2_HEIGHT / DA2_WIDTH). Each configuration runs in its own process (one warm-up
# iteration, then ITERS timed) so that peak RSS is its own. Prints a table: seconds, the ratio
# PyTorch / ours (> 1: we are faster), peak RSS of each, MFU against PEAK_GFLOPS and, for a
# training step, the relative difference of the two losses (same weights and loss; the input
# images are drawn by each side's own seeded generator, so it shows a step of the same size, not
# bit parity: tests/test_models.cpp checks that; for inference, of the output sums). The training loss is the CVD geometric loss on 4
# synthetic pairs (LOSS=surrogate: mean(output * R)). PRECISION=bf16 runs ours with
# --precision bf16 (PyTorch stays f32).
#
#   bench/compare_models.sh BUILD_DIR [arch ...]
#     (env: ITERS=1 BATCH=8 PEAK_GFLOPS=256 THREADS=2 LOSS=geometric PRECISION=f32)
# Needs bench_models built (cmake -DCVD_BUILD_BENCH=ON) and /usr/bin/python3 with torch.
set -euo pipefail
BUILD=${1:?usage: compare_models.sh BUILD_DIR [arch ...]}
shift
ARCHS=("$@")
[ ${#ARCHS[@]} -eq 0 ] && ARCHS=(midas_v2 midas_small mannequin)
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN="$BUILD/bench/bench_models"
PY=(/usr/bin/python3 "$ROOT/tools/reference/bench_models_torch.py")
ITERS=${ITERS:-1}
BATCH=${BATCH:-8}
PEAK=${PEAK_GFLOPS:-256}
LOSS=${LOSS:-geometric}
PRECISION=${PRECISION:-f32}
export OMP_NUM_THREADS=${THREADS:-2}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
[ -x "$BIN" ] || { echo "compare_models.sh: $BIN not found (build target bench_models)" >&2; exit 1; }

echo "# $(date -u +%Y-%m-%dT%H:%MZ) $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores, OMP_NUM_THREADS=$OMP_NUM_THREADS, peak $PEAK GFLOP/s, loss $LOSS, ours in $PRECISION"
printf '%-12s %-6s %-8s %9s %9s %7s %10s %10s %8s %8s %9s\n' arch mode size ours_s torch_s ratio ours_MiB torch_MiB ours_mfu torch_mfu loss_rdiff
for arch in "${ARCHS[@]}"; do
  if [ "$arch" = midas_small ]; then H=160; W=256;
  elif [ "$arch" = depth_anything_v2 ]; then H=${DA2_HEIGHT:-392}; W=${DA2_WIDTH:-518};
  else H=224; W=384; fi
  weights="$TMP/$arch.cvdw"
  "$BIN" --arch "$arch" --save-weights "$weights"
  gmac=$("${PY[@]}" --arch "$arch" --height $H --width $W --weights "$weights" --gmac-only)
  for mode in infer train; do
    common=(--arch "$arch" --mode $mode --batch "$BATCH" --height $H --width $W --iters "$ITERS" --weights "$weights" --peak-gflops "$PEAK" --loss "$LOSS")
    ours=$("$BIN" "${common[@]}" --gmac "$gmac" --precision "$PRECISION" | tail -1)
    torch=$("${PY[@]}" "${common[@]}" | tail -1)
    echo "$ours" >> "$TMP/results.jsonl"
    echo "$torch" >> "$TMP/results.jsonl"
    /usr/bin/python3 - "$ours" "$torch" <<'PYEOF'
import json, sys
o, t = json.loads(sys.argv[1]), json.loads(sys.argv[2])
rdiff = abs(o['check'] - t['check']) / max(abs(t['check']), 1e-30)
print(f"{o['arch']:<12} {o['mode']:<6} {o['size']:<8} {o['seconds']:9.2f} {t['seconds']:9.2f} "
      f"{t['seconds'] / o['seconds']:7.2f} {o['peak_rss_mib']:10.0f} {t['peak_rss_mib']:10.0f} "
      f"{o['mfu']:8.1%} {t['mfu']:8.1%} {rdiff:9.1e}")
PYEOF
  done
done
