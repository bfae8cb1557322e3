#!/usr/bin/env bash
# Installs the dependencies, builds cvd (Release) and runs `cvd demo`: a generated scene with
# known ground truth through the whole pipeline, printing the metrics table.
# Usage: bash scripts/demo.sh [extra cvd demo flags]   (outputs in ./demo-out)
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
$SUDO bash scripts/install-deps.sh
cmake -G Ninja -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build -j "$(nproc)" --target cvd
./build/cvd demo --out demo-out "$@"
