#!/usr/bin/env bash
# Instruction counts of bakes against one skinning pass (valgrind's callgrind, 1 thread):
# exact and independent of the machine's load, so two trees compare where wall-clock
# times on a shared machine cannot (docs/PERFORMANCE.md, "Where the time goes").
#   bash bench/count_instructions.sh BUILD_DIR [FILE:VARIANT[:all] ...]
# BUILD_DIR holds bench/motionlod_bench_bake_once (any MOTIONLOD_BUILD_BENCH=ON build).
# FILE is relative to ../shared/data; ":all" bakes every level instead of the default
# ladder. Without cases, a fixed set of short and long clips, rigid and not.
# "bake" = one pipeline::Bake (the import comes before it and is not counted);
# "skin" = one pipeline::SkinningPassSeconds of the same inputs on 1 thread.
# SIMD (default baseline) picks the hot loops' version (base/simd.h): baseline counts the
# same on any x86-64; auto counts the version this CPU runs (AVX2 and FMA where present).
set -euo pipefail
build=${1:?usage: count_instructions.sh BUILD_DIR [FILE:VARIANT[:all] ...]}
shift
here=$(cd "$(dirname "$0")/.." && pwd)
data="$here/../shared/data"
driver="$build/bench/motionlod_bench_bake_once"
command -v valgrind >/dev/null || { echo "count_instructions: valgrind is not installed (apt-get install valgrind)" >&2; exit 2; }
[ -x "$driver" ] || { echo "count_instructions: no $driver (build the target motionlod_bench_bake_once)" >&2; exit 2; }
[ -d "$data" ] || { echo "count_instructions: no $data" >&2; exit 2; }
simd=${SIMD:-baseline}
case "$simd" in baseline | auto) ;; *) echo "count_instructions: SIMD must be baseline or auto" >&2; exit 2 ;; esac
cases=("$@")
if [ ${#cases[@]} -eq 0 ]; then
  cases=(motions/55_01_cmu.fbx:vpno+pd motions/cmu_131_01.bvh:vpno+pd motions/09_11_cmu.fbx:vp+pd
         characters/stormtrooper.dae:vp+pd characters/CesiumMan.glb:vp+pd characters/Orc.gltf:vpno+pd
         characters/Fox.glb:vp characters/stormtrooper.dae:vpno:all)
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# Instructions of one run of the driver: it turns callgrind's counting on around the bake
# (WHAT=bake) or the skinning pass (WHAT=skin) alone, threads included.
count() {
  local what=$1
  shift
  MOTIONLOD_SIMD=$simd valgrind --tool=callgrind --instr-atstart=no --callgrind-out-file="$work/cg.out" \
    "$driver" "$@" >/dev/null 2>&1 || { echo "count_instructions: $what $* failed under valgrind" >&2; exit 2; }
  local total
  total=$(sed -n 's/^totals: *//p' "$work/cg.out" | head -n 1)
  [ -n "$total" ] && [ "$total" -gt 0 ] || { echo "count_instructions: nothing counted for $what $*" >&2; exit 2; }
  echo "$total"
}
printf '| case | bake (M instructions) | skin (M instructions) | bake / skin |\n|---|---:|---:|---:|\n'
for c in "${cases[@]}"; do
  IFS=: read -r file variant mode <<<"$c"
  path=$(find "$data" -path "*$file" | head -n 1)
  [ -n "$path" ] || { echo "count_instructions: no $file under $data" >&2; exit 2; }
  bake=$(count bake "$path" "$variant" ${mode:+"$mode"})
  skin=$(count skin "$path" "$variant" skin)
  python3 -c "import sys; b, s = int(sys.argv[1]), int(sys.argv[2]); print(f'| \`{sys.argv[3]}\` | {b/1e6:.1f} | {s/1e6:.1f} | {b/s:.2f}x |')" "$bake" "$skin" "$c"
done
