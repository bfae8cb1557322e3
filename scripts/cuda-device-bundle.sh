#!/bin/bash
# Packs what a GPU machine without this project's Debian packages needs to run the CUDA checks:
# test_cuda_ops, bench_cuda_ops and bench_op_table (the op and kernel tables' perf mode) linked with
# --as-needed against the engine and kernel layers only (no OpenCV / ffmpeg / Ceres), the shared
# libraries they load (oneDNN xz-compressed), the PyTorch reference script and
# bench/cuda_device_check.sh. ~22 MiB.
#   scripts/cuda-device-bundle.sh BUILD_DIR OUT_DIR      (BUILD_DIR: a CUDA build, layers built)
# Then on the GPU machine: bash OUT_DIR/cuda_device_check.sh  (results under $OUT).
set -euo pipefail
build=$(realpath "$1")
out=$2
src=$(cd "$(dirname "$0")/.." && pwd)
[ -f "$build/kernels/libcvd_kernels_cuda.a" ] || { echo "$build: no CUDA layer built" >&2; exit 1; }
grep -q "CVD_WITH_CUDA" "$build/build.ninja" || { echo "$build: not a CUDA build" >&2; exit 1; }
rm -rf "$out" && mkdir -p "$out/obj"
flags="-O2 -DNDEBUG -std=gnu++17 -fopenmp -I$src -I$src/include -DCVD_WITH_CUDA=1 -I/usr/local/cuda/include"
for s in tests/gtest_main tests/op_case_table tests/op_case_run tests/kernel_case_run \
  tests/kernel_cases_elementwise tests/kernel_cases_spatial tests/test_cuda_ops \
  bench/bench_cuda_ops bench/bench_op_table; do
  g++ $flags -c "$src/$s.cpp" -o "$out/obj/$(basename $s).o"
done
libs=("$build"/kernels/libcvd_kernels.a "$build"/kernels/libcvd_kernels_reference.a
      "$build"/kernels/libcvd_kernels_cpu.a "$build"/kernels/libcvd_kernels_cuda.a
      "$build"/engine/libcvd_engine.a -ldnnl -fopenmp /usr/local/cuda/lib/libcudart.so -ldl -lz
      -lspdlog -lfmt -lpthread '-Wl,-rpath,$ORIGIN')
o=$out/obj
tables="$o/op_case_table.o $o/op_case_run.o $o/kernel_case_run.o $o/kernel_cases_elementwise.o
        $o/kernel_cases_spatial.o"
g++ -o "$out/test_cuda_ops" $o/gtest_main.o $tables $o/test_cuda_ops.o -Wl,--as-needed -lgtest \
  "${libs[@]}"
g++ -o "$out/bench_cuda_ops" $o/bench_cuda_ops.o -Wl,--as-needed "${libs[@]}"
g++ -o "$out/bench_op_table" $o/bench_op_table.o $tables -Wl,--as-needed "${libs[@]}"
rm -rf "$o"
for l in libdnnl.so.2 libfmt.so.9 libgomp.so.1 libOpenCL.so.1 libstdc++.so.6 libz.so.1; do
  cp -L "/lib/x86_64-linux-gnu/$l" "$out/"
done
cp -L /usr/local/cuda/lib/libcudart.so.13 "$out/"
xz -T2 -6 "$out/libdnnl.so.2"
cp "$src/tools/reference/bench_cuda_ops_torch.py" "$src/bench/cuda_device_check.sh" "$out/"
du -sh "$out"
