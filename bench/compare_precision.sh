#!/usr/bin/env bash
# `cvd demo` in f32 and in bf16 (--precision bf16) on the same cameras and flow: the f32 run goes
# first (default settings, COLMAP poses), then the bf16 run reuses its pose and flow caches, so
# the two differ only in the arithmetic of the warm-up, training and inference. Prints both demo
# tables' AbsRel, the stage timings, peak RSS and the per-pixel relative difference between the
# two runs' final depth maps (median, 99th percentile, max).
#
#   bench/compare_precision.sh CVD_BINARY [OUT_DIR] [extra cvd demo flags]   (default OUT_DIR /tmp/cvd-precision)
set -euo pipefail
CVD=${1:?usage: compare_precision.sh CVD_BINARY [OUT_DIR] [demo flags]}
OUT=${2:-/tmp/cvd-precision}
shift $(( $# >= 2 ? 2 : 1 ))
rm -rf "$OUT"
mkdir -p "$OUT/bf16/run"
echo "# $(date -u +%Y-%m-%dT%H:%MZ) $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores"
/usr/bin/time -v "$CVD" demo --out "$OUT/f32" "$@" > "$OUT/f32.log" 2> "$OUT/f32.time"
cp -r "$OUT/f32/run/cache" "$OUT/bf16/run/"
rm -rf "$OUT/bf16/run/cache/training"
/usr/bin/time -v "$CVD" demo --out "$OUT/bf16" --precision bf16 "$@" > "$OUT/bf16.log" 2> "$OUT/bf16.time"
/usr/bin/python3 - "$OUT" <<'PYEOF'
import json, pathlib, re, sys
import numpy as np

out = pathlib.Path(sys.argv[1])

def pfm(p):
    with open(p, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    return data.reshape(h, w)[::-1]

def rss_mib(p):
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.read_text())
    return int(m.group(1)) / 1024

for run in ("f32", "bf16"):
    s = json.loads((out / run / "demo_summary.json").read_text())
    t = s["timings_s"]
    info = json.loads((out / run / "run" / "run.json").read_text())
    print(f"{run:5s} AbsRel per-frame {s['abs_rel_median_frame']['initial']:.4f} -> {s['abs_rel_median_frame']['final']:.4f}"
          f"  static {s.get('abs_rel_static_scene', {}).get('final', float('nan')):.4f}"
          f"  loss {s['geometric_loss']['initial']:.4f} -> {s['geometric_loss']['final']:.4f}"
          f"  warm-up+initial {t['initial_depth']:.0f} s  training {t['training']:.0f} s  total {t['total']:.0f} s"
          f"  peak RSS {rss_mib(out / (run + '.time')):.0f} MiB  ({info['training']['precision']}, {info['training']['precision_unit']})")
d = []
for p in sorted((out / "f32" / "run" / "depth").glob("*.pfm")):
    a, b = pfm(p), pfm(out / "bf16" / "run" / "depth" / p.name)
    d.append((np.abs(b - a) / np.maximum(np.abs(a), 1e-6)).ravel())
d = np.concatenate(d)
print(f"bf16 vs f32 final depth, relative difference over {d.size} pixels: median {np.median(d):.2e}, "
      f"p99 {np.quantile(d, 0.99):.2e}, max {d.max():.2e}")
PYEOF
