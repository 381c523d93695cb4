#!/usr/bin/env bash
# Where a bake's time goes by the clock: `perf record -e cpu-clock` samples over the bake
# benchmark cases FILTER matches, then the functions' shares of the samples. By the clock
# because callgrind's instruction counts miss stalls (cache misses, failed store forwarding,
# long dependency chains), and the shared machines have no hardware counters.
#   bash bench/profile_clock.sh BUILD_DIR FILTER [TOP]
# e.g. bash bench/profile_clock.sh build-bench 'bake/stormtrooper.dae@16647v/vpno/all'
# BUILD_DIR holds bench/motionlod_bench_bake. The shares include the bench's own skinning
# passes where the filter runs them (the bake/ cases of the default ladder do).
set -euo pipefail
build=${1:?usage: profile_clock.sh BUILD_DIR FILTER [TOP]}
filter=${2:?usage: profile_clock.sh BUILD_DIR FILTER [TOP]}
top=${3:-15}
here=$(cd "$(dirname "$0")/.." && pwd)
command -v perf >/dev/null || { echo "profile_clock: perf is not installed (apt-get install linux-perf)" >&2; exit 2; }
[ -x "$build/bench/motionlod_bench_bake" ] || { echo "profile_clock: no $build/bench/motionlod_bench_bake" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
perf record -q -e cpu-clock -F 4000 -o "$work/perf.data" "$build/bench/motionlod_bench_bake" \
  --data="$here/../shared/data" --benchmark_filter="$filter" --benchmark_min_time=3 >/dev/null 2>&1
perf report -i "$work/perf.data" --no-children --sort symbol -g none --percent-limit 0.5 2>/dev/null |
  grep '%' | head -n "$top" | sed -E 's/ +-? +-? *$//; s/^ +//' | cut -c1-140
