#!/usr/bin/env bash
# ctest viewer_browser: a short `cvd run --viewer` on the built-in scene (8 frames, ground-truth
# poses, 1 epoch at 96 px), then viewer_browser_test.mjs opens OUT/viewer.html in headless
# Chromium. Exit 77 (skipped, saying why) without node, Chromium, the npm packages, or a cvd built
# without the viewer's script.
#   tests/viewer/viewer_browser_test.sh CVD [SCREENSHOT.png]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cvd=$1
screenshot=${2:-${CVD_VIEWER_SCREENSHOT:-}}
command -v node >/dev/null || { echo "skipped: node is not installed (apt install nodejs npm)"; exit 77; }
work=$(mktemp -d /tmp/cvd-viewer-test.XXXXXX)
trap 'rm -rf "$work"' EXIT
"$cvd" --quiet scene --out "$work/scene" --frames 8 --width 192 --height 112
intr=$(sed -e 's/[{}" ]//g' "$work/scene/intrinsics.json" |
  tr ',' '\n' | awk -F: '{v[$1]=$2} END {print v["fx"] "," v["fy"] "," v["cx"] "," v["cy"]}')
set +e
"$cvd" --quiet run "$work/scene/rgb" -o "$work/run" --poses "$work/scene/poses.txt" --poses-format tum \
  --intrinsics "$intr" --epochs 1 --depth-size 96 --width 0.125 --warmup 10 --no-videos --viewer \
  >"$work/run.log" 2>&1
rc=$?
set -e
if [ $rc = 7 ] && grep -q "without the viewer's script" "$work/run.log"; then
  echo "skipped: this cvd was built without the viewer's script (npm ci --prefix tools/viewer/web, then reconfigure)"
  exit 77
fi
[ $rc = 0 ] || { echo "cvd run --viewer failed (exit $rc):"; cat "$work/run.log"; exit 1; }
[ -s "$work/run/viewer.html" ] || { echo "cvd run --viewer wrote no viewer.html"; exit 1; }
node "$here/viewer_browser_test.mjs" "$work/run/viewer.html" ${screenshot:+"$screenshot"}
