# shellcheck shell=bash
# Sourced by compare_builds.sh and compare_counter.sh: runs two builds of the bake
# benchmark alternately on the same machine, so that the machine's load falls on both.
#   run_side_by_side NAME BASE_BUILD NEW_BUILD BENCHMARK_FILTER WORK_DIR
# NAME prefixes the errors. Round r of side base|new leaves Google Benchmark JSON in
# WORK_DIR/SIDE.r.json. ROUNDS (the caller's default), MIN_TIME (default 0.3 s) and
# THREADS (default 1) come from the environment; each round runs 3 repetitions.
run_side_by_side() {
  local name=$1 base=$2 new=$3 filter=$4 work=$5
  local here data build round side
  here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
  data="$here/../shared/data"
  [ -d "$data" ] || { echo "$name: no $data" >&2; exit 2; }
  for build in "$base" "$new"; do
    [ -x "$build/bench/motionlod_bench_bake" ] || {
      echo "$name: no $build/bench/motionlod_bench_bake" >&2
      exit 2
    }
  done
  for ((round = 0; round < ROUNDS; ++round)); do
    for side in base new; do
      build=$base
      [ "$side" = new ] && build=$new
      "$build/bench/motionlod_bench_bake" --data="$data" --threads="$THREADS" \
        --benchmark_filter="$filter" --benchmark_min_time="${MIN_TIME:-0.3}" \
        --benchmark_repetitions=3 --benchmark_format=json 2>/dev/null >"$work/$side.$round.json"
    done
  done
}
