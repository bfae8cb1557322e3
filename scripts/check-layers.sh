#!/usr/bin/env bash
# Fails when a layer reaches upward (docs/design.md section 2). Two checks:
#  1. includes: every `#include "dir/..."` in a layer's sources names a folder that layer may use;
#  2. symbols (when the layer libraries are given): no symbol a layer library leaves undefined is
#     defined by a library it may not use, so an upward call without an include fails too.
#
#   scripts/check-layers.sh SOURCE_DIR [libcvd_engine.a libcvd_kernels_reference.a
#       libcvd_kernels_cpu.a libcvd_kernels_cuda.a libcvd_kernels.a libcvd_models.a
#       libcvd_pipeline.a libcvd_scene.a libcvd_convert.a libcvd_mpi.a libcvd_viewer.a]
# (ctest runs it as check_layers with the libraries of the build.)
set -euo pipefail
root=$1
shift

# layer folder -> the folders its includes may name (its own included). Every layer may also
# include the public headers (include/cvd: the standard library only, and the one cvd::Error).
declare -A allowed=(
  [engine]="engine"
  [kernels/reference]="engine kernels/reference"
  [kernels/cpu]="engine kernels/cpu"
  [kernels/cuda]="engine kernels/cuda"
  [kernels]="engine kernels kernels/reference kernels/cpu kernels/cuda"
  [models]="engine models"
  [pipeline]="engine kernels models pipeline"
  [scene]="engine pipeline scene"
  [tools/convert]="engine models tools/convert"
  [tools/distributed]="engine tools/distributed"
  [tools/viewer]="engine pipeline tools/viewer"
  [api]="api engine kernels models pipeline"
  [tools/cli]="engine kernels models pipeline scene tools/convert tools/distributed tools/viewer tools/cli"
)

status=0
# The folder an include names: "kernels/cpu/x.h" -> kernels/cpu, "kernels/x.h" -> kernels,
# "pipeline/flow/x.h" -> pipeline, "tools/convert/x.h" -> tools/convert.
include_layer() {
  case $1 in
    kernels/reference/* | kernels/cpu/* | kernels/cuda/*) echo "${1%/*}" ;;
    tools/*/*) echo "$(echo "$1" | cut -d/ -f1-2)" ;;
    */*) echo "${1%%/*}" ;;
    *) echo "" ;;
  esac
}
for layer in "${!allowed[@]}"; do
  dir=$root/$layer
  [ -d "$dir" ] || continue
  # Files of this layer: its folder, without the folders of other layers below it.
  if [ "$layer" = kernels ]; then
    files=$(find "$dir" -maxdepth 1 -type f \( -name '*.h' -o -name '*.cpp' -o -name '*.cu' -o -name '*.cuh' \))
  else
    files=$(find "$dir" -type f \( -name '*.h' -o -name '*.cpp' -o -name '*.cu' -o -name '*.cuh' \))
  fi
  for f in $files; do
    while IFS= read -r inc; do
      target=$(include_layer "$inc")
      [ -z "$target" ] && continue
      ok=0
      for a in cvd ${allowed[$layer]}; do [ "$a" = "$target" ] && ok=1; done
      if [ $ok = 0 ]; then
        echo "check-layers: ${f#$root/} includes \"$inc\": layer $layer may not use $target" >&2
        status=1
      fi
    done < <(sed -n 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"\([^"]*\)".*/\1/p' "$f")
  done
done

if [ $# -gt 0 ]; then
  if [ $# -ne 11 ]; then
    echo "check-layers: expected 11 libraries, got $#" >&2
    exit 2
  fi
  names=(engine kernels/reference kernels/cpu kernels/cuda kernels models pipeline scene tools/convert
    tools/distributed tools/viewer)
  libs=("$@")
  declare -A lib
  for i in "${!names[@]}"; do lib[${names[$i]}]=${libs[$i]}; done
  # library -> the libraries it may use (besides itself).
  declare -A below=(
    [engine]=""
    [kernels/reference]="engine"
    [kernels/cpu]="engine"
    [kernels/cuda]="engine"
    [kernels]="engine kernels/reference kernels/cpu kernels/cuda"
    [models]="engine"
    [pipeline]="engine kernels/reference kernels/cpu kernels/cuda kernels models"
    [scene]="engine kernels/reference kernels/cpu kernels/cuda kernels models pipeline"
    [tools/convert]="engine models"
    [tools/distributed]="engine"
    [tools/viewer]="engine kernels/reference kernels/cpu kernels/cuda kernels models pipeline"
  )
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  for n in "${names[@]}"; do
    key=${n//\//_}
    # Only the project's own symbols (namespace cvd): the standard library's inline code is
    # instantiated in every library that uses it.
    nm -g --defined-only "${lib[$n]}" 2>/dev/null | awk 'NF == 3 && $2 != "w" && $2 != "V" {print $3}' |
      grep -E '^_ZN[KVRO]*3cvd' | sort -u > "$tmp/$key.def" || true
    nm -g --undefined-only "${lib[$n]}" 2>/dev/null | awk '{print $NF}' | grep -E '^_ZN[KVRO]*3cvd' |
      sort -u > "$tmp/$key.undef" || true
  done
  for n in "${names[@]}"; do
    key=${n//\//_}
    for m in "${names[@]}"; do
      [ "$m" = "$n" ] && continue
      case " ${below[$n]} " in *" $m "*) continue ;; esac
      # Symbols both defined here and there (inline functions, templates) are not calls upward.
      hits=$(comm -12 "$tmp/$key.undef" "$tmp/${m//\//_}.def" | comm -23 - "$tmp/$key.def" | head -5)
      if [ -n "$hits" ]; then
        echo "check-layers: $n ($(basename "${lib[$n]}")) uses symbols of $m, which it may not use:" >&2
        echo "$hits" | c++filt | sed 's/^/  /' >&2
        status=1
      fi
    done
  done
fi

if [ $status = 0 ]; then
  echo "check-layers: every include and symbol reference points down (${#allowed[@]} layers)"
fi
exit $status
