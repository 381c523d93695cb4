#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ with clang (build-fuzz) and runs each for a bounded
# time, seeded from ../shared/data, samples/ and the committed regression inputs
# (fuzz/regressions/<target>/, each replayed first: a regression that crashes again fails;
# the hand-written seeds of api_fuzz and of the DirectX and SMD importers live there too).
#
#   bash scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     (default 60 s, every target)
#
# Environment: FUZZ_BUILD_DIR (default build-fuzz), FUZZ_WORK_DIR (default
# $FUZZ_BUILD_DIR/work: corpora, crash inputs, logs; corpora grow across runs),
# FUZZ_RSS_MB (default 2048), FUZZ_TIMEOUT_S (one input, default 20).
# Prints one line per target: executions, corpus size, and whether it crashed. Exit status
# 0 when no target crashed, 1 when one did (the input is in $FUZZ_WORK_DIR/<target>/).
# The import targets keep the inputs that crash, hang or exhaust Assimp as artifacts for
# triage instead (counted in their line): the daemon's worker turns those into 422s.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
seconds=${1:-60}
shift || true
build=${FUZZ_BUILD_DIR:-$root/build-fuzz}
work=${FUZZ_WORK_DIR:-$build/work}
data=$root/../shared/data
formats=(glb gltf fbx dae bvh x smd)
all_targets=(level_format_fuzz api_fuzz asset_wire_fuzz)
for f in "${formats[@]}"; do all_targets+=("import_${f}_fuzz"); done
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=("${all_targets[@]}")

launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
# A unity build, as scripts/test.sh's (a few sources a batch: a third of the time).
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_COMPILER=clang++ -DMOTIONLOD_BUILD_FUZZERS=ON -DMOTIONLOD_BUILD_TESTS=OFF \
  -DCMAKE_UNITY_BUILD=ON "${launcher[@]}" >/dev/null
# Quiet unless the build fails: then its errors, not a bare exit status.
if ! ninja -C "$build" "${targets[@]}" make_seeds >"$build/build.log" 2>&1; then
  grep -E 'error|FAILED' "$build/build.log" | head -n 40 >&2
  echo "fuzz: building the fuzz targets with clang failed (the whole log: $build/build.log)" >&2
  exit 1
fi

# Seeds: copied at run time, never committed (the data set is 19 MiB).
seed_files=("$root"/samples/*.glb)
[ -d "$data" ] && seed_files+=("$data"/characters/*.* "$data"/motions/*.*)
mkdir -p "$work/seeds"
if [ ! -e "$work/seeds/.done" ]; then
  for f in "${seed_files[@]}"; do
    ext=${f##*.}
    ext=${ext,,}
    mkdir -p "$work/seeds/import_${ext}_fuzz"
    cp "$f" "$work/seeds/import_${ext}_fuzz/"
  done
  "$build/fuzz/make_seeds" "$work/seeds" "$root"/samples/*.glb \
    $([ -d "$data" ] && echo "$data/characters/Fox.glb $data/motions/cmu_131_03.bvh") >/dev/null
  touch "$work/seeds/.done"
fi

crashed=0
for target in "${targets[@]}"; do
  binary=$build/fuzz/$target
  corpus=$work/$target/corpus
  mkdir -p "$corpus" "$work/$target/artifacts"
  regressions=$root/fuzz/regressions/$target
  if [ -d "$regressions" ] && [ -n "$(ls -A "$regressions")" ]; then
    replay=()
    [[ $target == import_* ]] && replay=(-detect_leaks=0)
    if ! "$binary" "${replay[@]}" -runs=0 -rss_limit_mb="${FUZZ_RSS_MB:-2048}" "$regressions"/* \
        >"$work/$target/regressions.log" 2>&1; then
      echo "fuzz: $target: a committed regression input crashes again (see $work/$target/regressions.log)"
      crashed=1
      continue
    fi
  fi
  seeds=()
  [ -d "$work/seeds/$target" ] && seeds=("$work/seeds/$target")
  [ -d "$regressions" ] && seeds+=("$regressions")
  # The importers run Assimp (Debian's, not ours to fix), which allocates what a file
  # declares, loops on some inputs and corrupts its heap on others: in the daemon the
  # sandboxed worker turns each into a 422 (tests/server/import_isolation_test.cc holds
  # the findings). So here out-of-memory, timeout and crash inputs are kept as artifacts,
  # counted in the summary for triage, and fuzzing goes on (fork mode). Assimp's error
  # paths also leak: harmless in a worker that exits after one import, so leaks are not
  # checked here, as in the worker.
  mode=()
  [[ $target == import_* ]] &&
    mode=(-fork=1 -ignore_ooms=1 -ignore_timeouts=1 -ignore_crashes=1 -detect_leaks=0)
  leaks=1
  [[ $target == import_* ]] && leaks=0
  status=0
  ASAN_OPTIONS=detect_leaks=$leaks "$binary" "$corpus" "${seeds[@]}" "${mode[@]}" -max_total_time="$seconds" \
    -rss_limit_mb="${FUZZ_RSS_MB:-2048}" -timeout="${FUZZ_TIMEOUT_S:-20}" -max_len=1048576 \
    -print_final_stats=1 -artifact_prefix="$work/$target/artifacts/" \
    >"$work/$target/fuzz.log" 2>&1 || status=$?
  # Executions: the final stats line, or (fork mode) the last progress line "#N: ...".
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$work/$target/fuzz.log" |
    grep -o '[0-9]*$' | tail -1 || true)
  [ -z "$runs" ] && runs=$(grep -oE '^#[0-9]+' "$work/$target/fuzz.log" | tail -1 | tr -d '#')
  kept=$(ls "$work/$target/artifacts" | grep -cE '^(oom|timeout|crash)-' || true)
  # Fork mode exits non-zero when it kept an input; those are reported, not failures.
  [ ${#mode[@]} -gt 0 ] && status=0
  if [ $status -ne 0 ]; then
    crashed=1
    echo "fuzz: $target: CRASH after ${runs:-?} executions: $(ls -t "$work/$target/artifacts" | head -1) (log $work/$target/fuzz.log)"
  else
    echo "fuzz: $target: ${runs:-0} executions in ${seconds} s, corpus $(ls "$corpus" | wc -l) inputs, no crash${mode:+; Assimp inputs kept for triage (out of memory, timeout, crash): $kept}"
  fi
done
exit $crashed
