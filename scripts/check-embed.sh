#!/usr/bin/env bash
# Proves that cvd can be embedded from an installation: installs the build tree BUILD (default
# build) to a temporary prefix, builds examples/embed against it with find_package(cvd CONFIG),
# runs it, and builds and runs a one-file consumer with `pkg-config --cflags --libs cvd`.
# Usage: scripts/check-embed.sh [BUILD_DIR]   (the build must already have cvd, cvd_shared and
# cvd_static built, or this builds them)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$root/build}" && pwd)
jobs=${CVD_JOBS:-2}
tmp=$(mktemp -d "${TMPDIR:-/tmp}/cvd-check-embed.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}

echo "== the embedding guide's code is the example's code"
# The first ```LANG block after the "Embedding guide" heading of a Markdown file.
guide_code() {
  awk -v lang="$2" '/^#+ Embedding guide/ { in_guide = 1 } in_guide && $0 == "```" lang { on = 1; next }
                    on && $0 == "```" { exit } on' "$1"
}
for doc in "$root/docs/embedding.md" $(grep -l '^## Embedding guide' "$root/README.md" 2>/dev/null || true); do
  diff <(guide_code "$doc" cpp) "$root/examples/embed/main.cpp" > /dev/null ||
    { echo "check-embed: the C++ code of $doc differs from examples/embed/main.cpp" >&2; exit 1; }
  diff <(guide_code "$doc" cmake) <(grep -v '^#' "$root/examples/embed/CMakeLists.txt") > /dev/null ||
    { echo "check-embed: the CMake code of $doc differs from examples/embed/CMakeLists.txt" >&2; exit 1; }
done

echo "== building and installing to $tmp/prefix"
cmake --build "$build" --target cvd cvd_shared cvd_static -j"$jobs"
cmake --install "$build" --prefix "$tmp/prefix" > "$tmp/install.log"
test -f "$tmp/prefix/include/cvd/cvd.h"
test -f "$tmp/prefix/lib/cmake/cvd/cvdConfig.cmake"
test -f "$tmp/prefix/lib/cmake/cvd/cvdConfigVersion.cmake"
test -x "$tmp/prefix/bin/cvd"
ls "$tmp"/prefix/lib/libcvd.so* "$tmp"/prefix/lib/libcvd.a > /dev/null

echo "== the public headers include no internal or third-party header"
if grep -rhoE '#include *[<"][^>"]+[>"]' "$tmp/prefix/include/cvd" | grep -vE '[<"](cvd/[a-z_]+\.h|[a-z_]+)[>"]'; then
  echo "check-embed: a public header includes a non-standard header" >&2
  exit 1
fi

echo "== the shared library exports only cvd:: symbols"
bad=$(nm -D --defined-only -C "$tmp"/prefix/lib/libcvd.so | awk '{ $1 = ""; $2 = ""; print }' | grep -v '^ *cvd::\|for cvd::' || true)
if [ -n "$bad" ]; then
  echo "check-embed: libcvd.so exports non-cvd symbols:" >&2
  echo "$bad" | head -20 >&2
  exit 1
fi

echo "== examples/embed with find_package(cvd CONFIG)"
cmake -S "$root/examples/embed" -B "$tmp/example" -DCMAKE_PREFIX_PATH="$tmp/prefix" \
  -DCMAKE_BUILD_RPATH="$tmp/prefix/lib" > "$tmp/example-configure.log"
cmake --build "$tmp/example" -j"$jobs"
"$tmp/example/cvd_embed_example" "$tmp/example-run"

echo "== one-file consumer with pkg-config"
cat > "$tmp/consumer.cpp" <<'CPP'
#include <cvd/cvd.h>

#include <cstdio>

int main() {
  cvd::DepthModelOptions o;
  o.long_side = 32;
  cvd::DepthModel model = cvd::DepthModel::create_default(o);
  const cvd::DepthMap d = model.infer(cvd::Image(48, 32, 3));
  try {
    cvd::DepthModel::load("/nonexistent.cvdw");
    return 1;
  } catch (const cvd::Error& e) {
    if (e.category() != cvd::ErrorCategory::io) return 1;
  }
  std::printf("pkg-config consumer: cvd %s, depth %dx%d\n", cvd::version(), d.width, d.height);
  return d.width == 32 && d.depth.front() > 0 ? 0 : 1;
}
CPP
export PKG_CONFIG_PATH="$tmp/prefix/lib/pkgconfig${PKG_CONFIG_PATH:+:$PKG_CONFIG_PATH}"
# shellcheck disable=SC2046
c++ -std=c++17 -Wall -Wextra -Werror "$tmp/consumer.cpp" -o "$tmp/consumer" $(pkg-config --cflags --libs cvd)
"$tmp/consumer"
echo "== the same consumer against the static library (find_package(cvd CONFIG COMPONENTS static))"
mkdir -p "$tmp/static"
cp "$tmp/consumer.cpp" "$tmp/static/main.cpp"
cat > "$tmp/static/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(cvd_static_consumer LANGUAGES CXX)
find_package(cvd CONFIG REQUIRED COMPONENTS static)
add_executable(consumer main.cpp)
target_link_libraries(consumer PRIVATE cvd::cvd_static)
CMAKE
cmake -S "$tmp/static" -B "$tmp/static/build" -DCMAKE_PREFIX_PATH="$tmp/prefix" > "$tmp/static-configure.log"
cmake --build "$tmp/static/build" -j"$jobs" > /dev/null
if ldd "$tmp/static/build/consumer" | grep -q libcvd; then
  echo "check-embed: the static consumer links libcvd.so" >&2
  exit 1
fi
"$tmp/static/build/consumer"
echo "check-embed: OK"
