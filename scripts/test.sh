#!/usr/bin/env bash
# Installs the dependencies, builds cvd (Release, warnings as errors) and runs the whole test
# suite with ctest, then checks the installed package with the example consumer.
# Usage: bash scripts/test.sh [build-dir]   (default: build)
# CVD_SANITIZE_TESTS=1 additionally builds the suite under ASan + UBSan in <build-dir>-asan and
# runs every test not labelled "slow" (the slow ones run in the Release build above).
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
$SUDO bash scripts/install-deps.sh
jobs=$(nproc)
export CTEST_OUTPUT_ON_FAILURE=1
start=$(date +%s)
cmake -G Ninja -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DCVD_WERROR=ON
cmake --build "$build" -j "$jobs"
echo "test.sh: Release build done after $(( $(date +%s) - start )) s"
ctest --test-dir "$build" -j "$jobs" --timeout 1500
echo "test.sh: Release tests done after $(( $(date +%s) - start )) s"
bash scripts/check-embed.sh "$build"
if [ "${CVD_SANITIZE_TESTS:-0}" = "1" ]; then
  cmake -G Ninja -S . -B "$build-asan" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCVD_WERROR=ON \
    -DCVD_SANITIZE="address;undefined" -DCVD_BUILD_BENCH=OFF -DCVD_CUDA=OFF
  cmake --build "$build-asan" -j "$jobs"
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir "$build-asan" -j "$jobs" --timeout 3000 -LE slow
  echo "test.sh: sanitizer tests done after $(( $(date +%s) - start )) s"
fi
