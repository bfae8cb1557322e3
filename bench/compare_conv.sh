#!/usr/bin/env bash
# Convolution throughput through our dispatch vs a raw oneDNN primitive in its best layout
# (bench/bench_conv.cpp): runs the benchmark with repetitions in random interleaving (fairer on a
# noisy machine) and prints one row per shape and pass with the median GFLOP/s:
#   shape pass ours raw ratio [variants...]
# where ratio = ours / raw (the issue asks for >= 0.90). Extra columns, when measured: nochunk
# (no batch chunking), nowcache (weights reordered every call), onednn (depthwise on oneDNN),
# blocked / portable (depthwise on our channel-interleaved AVX-512 / our portable kernel), sgemm
# (pointwise shapes on oneDNN's sgemm instead of our AVX-512 kernel), matmul (pointwise shapes
# with every pass on oneDNN's matmul primitive, no sgemm), conv (pointwise
# shapes on oneDNN's convolution with its reorders, neither matmul nor sgemm).
#
# usage: bench/compare_conv.sh [path/to/bench_conv] [extra benchmark flags, e.g. --benchmark_filter=dw5]
# env:   OMP_NUM_THREADS (default 2), REPS (default 3), MIN_TIME (seconds per run, default 0.5)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
bin="${1:-$here/../build/bench/bench_conv}"
[[ $# -gt 0 ]] && shift
[[ -x "$bin" ]] || { echo "compare_conv.sh: benchmark binary '$bin' not found or not executable" >&2; exit 2; }
command -v jq >/dev/null || { echo "compare_conv.sh: jq is required to read the benchmark's JSON" >&2; exit 2; }
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-2}"
json="$(mktemp)"
order="$(mktemp)"
trap 'rm -f "$json" "$order"' EXIT
# Rows in registration order (the runs themselves are interleaved at random).
"$bin" --benchmark_list_tests "$@" | awk -F/ '{print $3, $4}' > "$order"

echo "# $(date -u '+%Y-%m-%d %H:%M UTC'), $(lscpu | sed -n 's/^Model name: *//p'), OMP_NUM_THREADS=$OMP_NUM_THREADS, load $(cut -d' ' -f1-3 /proc/loadavg)"
"$bin" --benchmark_repetitions="${REPS:-3}" --benchmark_enable_random_interleaving=true \
  --benchmark_report_aggregates_only=true --benchmark_min_time="${MIN_TIME:-0.5}" \
  --benchmark_out="$json" --benchmark_out_format=json "$@" >&2

# "shape pass variant gflops" for every median, then one row per (shape, pass).
# With a single repetition there are no aggregates: take the runs themselves.
jq -r --arg reps "${REPS:-3}" '.benchmarks[]
       | select(.aggregate_name == "median" or ($reps == "1" and .run_type == "iteration"))
       | (.run_name | split("/")) as $p | "\($p[2]) \($p[3]) \($p[1]) \(.GFLOPS)"' "$json" |
  awk -v order_file="$order" '
    BEGIN { while ((getline line < order_file) > 0) if (!(line in seen)) { seen[line] = 1; order[n++] = line } }
    { g[$1 " " $2, $3] = $4 }
    END {
      printf "%-20s %-10s %8s %8s %6s %8s %8s %8s %8s %8s %8s %8s %8s\n", "shape", "pass", "ours", "raw", "ratio",
             "nochunk", "nowcache", "onednn", "blocked", "portable", "sgemm", "matmul", "conv"
      for (i = 0; i < n; i++) {
        k = order[i]; split(k, f, " ")
        ours = g[k, "ours"]; raw = g[k, "raw"]
        ratio = (ours != "" && raw > 0) ? sprintf("%.2f", ours / raw) : "-"
        printf "%-20s %-10s %8s %8s %6s %8s %8s %8s %8s %8s %8s %8s %8s\n", f[1], f[2], fmt(ours), fmt(raw), ratio,
               fmt(g[k, "ours_nochunk"]), fmt(g[k, "ours_nowcache"]), fmt(g[k, "ours_onednn"]),
               fmt(g[k, "ours_blocked"]), fmt(g[k, "ours_portable"]), fmt(g[k, "ours_sgemm"]),
               fmt(g[k, "ours_matmul"]),
               fmt(g[k, "ours_conv"])
      }
    }
    function fmt(v) { return v == "" ? "-" : sprintf("%.1f", v) }'
