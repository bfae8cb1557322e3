#!/usr/bin/env bash
# Builds the libFuzzer targets of tests/fuzz/ with clang (ASan + UBSan) straight from the reader
# sources, seeds each from valid files (tests/data and small generated ones), runs each for
# SECONDS (default 20) and fails when any target finds a crash. Crash inputs are kept in
# $BUILD/crashes/<target>/ (turn each into a regression case in a test).
#
#   tests/fuzz/run_fuzzers.sh [SECONDS] [TARGET...]
#   env: BUILD (default build-fuzz), CXX (default clang++), JOBS (default 2),
#        RUNS (when set, each target runs until RUNS executions instead of SECONDS; the long
#        run of the README is RUNS=1000000)
set -euo pipefail
SECONDS_PER_TARGET=${1:-20}
shift || true
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BUILD=${BUILD:-$ROOT/build-fuzz}
CXX=${CXX:-clang++}
JOBS=${JOBS:-2}
ALL_TARGETS=(pfm flo npy onnx cvdw tum kitti intrinsics_json colmap_text)
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=("${ALL_TARGETS[@]}")

FLAGS=(-std=c++20 -g -O1 -fno-omit-frame-pointer -fsanitize=address,undefined
       -fno-sanitize-recover=undefined -I"$ROOT" -I"$ROOT/include" -isystem /usr/include/eigen3
       -isystem /usr/include/opencv4 -DCVD_VERSION=\"fuzz\" -DFMT_SHARED -DSPDLOG_COMPILED_LIB
       -DSPDLOG_FMT_EXTERNAL -DSPDLOG_SHARED_LIB -DONNX_ML=1 -DONNX_NAMESPACE=onnx
       -Wno-unknown-pragmas)
LIBS=(-lopencv_core -lfmt -lspdlog -lz -lpthread)

# The sources each target needs (the .cvdw and ONNX readers need the tensor engine, which links
# without any backend: cvd_engine depends on no other layer).
sources_for() {
  case $1 in
    pfm) echo engine/error.cpp pipeline/io/atomic_file.cpp pipeline/io/pfm_io.cpp ;;
    flo) echo engine/error.cpp pipeline/io/atomic_file.cpp pipeline/io/flow_io.cpp ;;
    npy) echo engine/error.cpp pipeline/io/atomic_file.cpp pipeline/io/npy_io.cpp ;;
    onnx) echo tools/convert/onnx_graph.cpp; (cd "$ROOT" && ls engine/*.cpp | tr '\n' ' ') ;;
    tum | kitti | intrinsics_json | colmap_text)
      echo engine/error.cpp pipeline/io/atomic_file.cpp pipeline/io/trajectory_io.cpp ;;
    cvdw) (cd "$ROOT" && ls engine/*.cpp | tr '\n' ' ') ;;
  esac
}

mkdir -p "$BUILD/obj" "$BUILD/seeds" "$BUILD/corpus" "$BUILD/crashes"

# ---- build (objects cached by source path; rebuilt when the source is newer) ----
object_for() { echo "$BUILD/obj/$(echo "$1" | tr '/' '_').o"; }
compile() {
  local src=$1 obj
  obj=$(object_for "$src")
  if [ ! -f "$obj" ] || [ "$ROOT/$src" -nt "$obj" ]; then
    "$CXX" "${FLAGS[@]}" -fsanitize=fuzzer-no-link -fopenmp -c "$ROOT/$src" -o "$obj.tmp" && mv "$obj.tmp" "$obj"
  fi
}
srcs=$(for t in "${TARGETS[@]}"; do sources_for "$t"; echo " tests/fuzz/fuzz_$t.cpp"; done | tr ' ' '\n' | grep . | sort -u)
echo "building $(echo "$srcs" | wc -l) sources with $CXX (${JOBS} jobs) ..."
pids=()
for src in $srcs; do
  compile "$src" &
  pids+=($!)
  if [ ${#pids[@]} -ge "$JOBS" ]; then wait "${pids[0]}"; pids=("${pids[@]:1}"); fi
done
for p in "${pids[@]}"; do wait "$p"; done
for t in "${TARGETS[@]}"; do
  objs=()
  for s in $(sources_for "$t") tests/fuzz/fuzz_$t.cpp; do objs+=("$(object_for "$s")"); done
  extra=()
  case $t in
    cvdw) extra=(-fopenmp) ;;
    onnx) extra=(-fopenmp -lonnx -lonnx_proto -lprotobuf) ;;
  esac
  "$CXX" "${FLAGS[@]}" -fsanitize=fuzzer "${objs[@]}" "${LIBS[@]}" "${extra[@]}" -o "$BUILD/fuzz_$t"
done

# ---- seeds ----
S=$BUILD/seeds
mkdir -p "$S"/{pfm,flo,npy,onnx,cvdw,tum,kitti,intrinsics_json,colmap_text}
printf 'Pf\n2 2\n-1\n' > "$S/pfm/gray.pfm"; head -c 16 /dev/zero >> "$S/pfm/gray.pfm"
printf 'PF\n1 2\n1.0\n' > "$S/pfm/rgb_be.pfm"; head -c 24 /dev/zero >> "$S/pfm/rgb_be.pfm"
printf 'PIEH\x02\x00\x00\x00\x01\x00\x00\x00' > "$S/flo/two.flo"; head -c 16 /dev/zero >> "$S/flo/two.flo"
npy_dict="{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 3), }"
npy_len=$(( (10 + ${#npy_dict} + 1 + 63) / 64 * 64 - 10 ))  # header padded to 64, ends in \n
{ printf '\x93NUMPY\x01\x00'; printf "\\x$(printf %02x $((npy_len % 256)))\\x$(printf %02x $((npy_len / 256)))";
  printf "%-$((npy_len - 1))s\n" "$npy_dict"; head -c 48 /dev/zero; } > "$S/npy/two.npy"
cp "$ROOT"/tests/data/onnx/*.onnx "$S/onnx/"
cp "$ROOT"/tests/data/onnx/*.cvdw "$S/cvdw/"
cat > "$S/tum/poses.txt" <<'P'
# timestamp tx ty tz qx qy qz qw
0.000000 -0.768578513 1.399014806 -2.397571400 0.106073309 -0.057480978 0.992683034 0.004978431
0.033333 -0.506872388 1.444226777 -2.317175687 0.067516497 -0.067672399 0.995414591 0.003429331
P
cat > "$S/kitti/poses.txt" <<'P'
1 0 0 0 0 1 0 0 0 0 1 0
0.99 -0.01 0.1 0.5 0.01 1 0 0 -0.1 0 0.99 1.5e-1
P
cat > "$S/intrinsics_json/intrinsics.json" <<'P'
{"cx": 63.5, "cy": 47.5, "fps": 30.0, "fx": 91.4, "fy": 91.4, "height": 96, "width": 128}
P
cat > "$S/colmap_text/model.txt" <<'P'
# Camera list with one line of data per camera:
1 SIMPLE_RADIAL 128 96 100.5 64 48 0.01
2 PINHOLE 128 96 90 91 63.5 47.5
@@images
# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
1 1 0 0 0 0 0 0 1 frame_000000.png
10.5 20.5 1
2 0.99 0 0.1 0 0.5 0 0 2 frame_000001.png
11.0 21.0 1 30 40 -1
@@points
1 0.1 0.2 3.0 255 128 0 0.5 1 0 2 0
P

# ---- run ----
status=0
for t in "${TARGETS[@]}"; do
  mkdir -p "$BUILD/corpus/$t" "$BUILD/crashes/$t"
  limit=(-max_total_time="$SECONDS_PER_TARGET")
  if [ -n "${RUNS:-}" ]; then
    limit=(-runs="$RUNS")
    echo "== fuzz_$t for $RUNS executions"
  else
    echo "== fuzz_$t for ${SECONDS_PER_TARGET}s"
  fi
  started=$(date +%s)
  if ! (cd "$BUILD/crashes/$t" && UBSAN_OPTIONS=print_stacktrace=1 \
        ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1 \
        "$BUILD/fuzz_$t" "${limit[@]}" -max_len=65536 -rss_limit_mb=4096 \
        -timeout=10 -print_final_stats=1 "$BUILD/corpus/$t" "$S/$t" > "$BUILD/fuzz_$t.log" 2>&1); then
    echo "!! fuzz_$t found a crash: see $BUILD/fuzz_$t.log and $BUILD/crashes/$t/"
    grep -m5 -E "ERROR|SUMMARY|threw" "$BUILD/fuzz_$t.log" || true
    status=1
  else
    grep -E "stat::number_of_executed_units|cov:" "$BUILD/fuzz_$t.log" | tail -2
    echo "   fuzz_$t: $(grep -oE 'stat::number_of_executed_units: *[0-9]+' "$BUILD/fuzz_$t.log" |
      grep -oE '[0-9]+$') executions in $(( $(date +%s) - started )) s, corpus $(ls "$BUILD/corpus/$t" | wc -l) inputs"
  fi
done
rm -rf /tmp/cvd-fuzz-*
exit $status
