#!/usr/bin/env bash
# Installs every Debian package cvd needs to build, test and run (docs/design.md 2.2).
# Idempotent; run as root on Debian 12. Set CVD_WITH_PYTHON=1 to also install the offline
# reference tools' packages (python3-torch etc.), which the build and tests never need.
set -euo pipefail
if [ "$(id -u)" -ne 0 ]; then
  echo "install-deps.sh: must run as root (apt-get install)" >&2
  exit 1
fi
pkgs=(
  build-essential cmake ninja-build pkg-config ccache git
  libeigen3-dev libopencv-dev libopencv-contrib-dev libceres-dev colmap
  libdnnl-dev ocl-icd-opencl-dev libgtest-dev libgmock-dev libbenchmark-dev
  ffmpeg libavformat-dev libavutil-dev libcli11-dev nlohmann-json3-dev libspdlog-dev libfmt-dev
  libonnx-dev libprotobuf-dev protobuf-compiler zlib1g-dev doxygen clang chromium jq
  # libFuzzer and clang's sanitizer runtimes (only recommended by clang, so not pulled in by
  # --no-install-recommends): tests/fuzz/run_fuzzers.sh links -fsanitize=fuzzer against them.
  libclang-rt-14-dev
  # MPI (issue 21): data-parallel training and sharded flow over mpirun; optional at build time.
  libopenmpi-dev openmpi-bin
)
# The viewer's script is bundled with three.js at build time (tools/viewer/web, npm packages pinned
# in its package-lock.json); a machine that already has node and npm keeps its own.
if ! command -v npm >/dev/null || ! command -v node >/dev/null; then
  pkgs+=(nodejs npm)
fi
if [ "${CVD_WITH_PYTHON:-0}" = "1" ]; then
  pkgs+=(python3-torch python3-torchvision python3-onnx python3-numpy)
fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -eq 0 ]; then
  echo "install-deps.sh: all ${#pkgs[@]} packages already installed"
else
  echo "install-deps.sh: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
# The viewer's npm packages, exactly as locked (again only when the lock file changed).
web="$(cd "$(dirname "$0")/.." && pwd)/tools/viewer/web"
if ! cmp -s "$web/package-lock.json" "$web/node_modules/.cvd-installed-lock.json" 2>/dev/null; then
  echo "install-deps.sh: npm ci in tools/viewer/web (three.js, esbuild, playwright-core)"
  npm ci --prefix "$web" --no-audit --no-fund --loglevel=error
  cp "$web/package-lock.json" "$web/node_modules/.cvd-installed-lock.json"
fi
echo "install-deps.sh: done"
