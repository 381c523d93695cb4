#!/usr/bin/env bash
# One stage of the bake, side by side in two builds: the minimum over all repetitions of a
# counter of the bake benchmark cases FILTER matches (inputs_s, rank_s, prepare_s,
# solve_s, encode_s: seconds per bake; see bench/bake_bench.cc), the two programs run
# alternately, ROUNDS rounds of 3 repetitions each. Printed in milliseconds, per case.
#   bash bench/compare_counter.sh BASE_BUILD NEW_BUILD FILTER COUNTER
# e.g. THREADS=2 bash bench/compare_counter.sh /tmp/base/build-bench build-bench \
#        'stormtrooper.dae@16647v/vpno\+pd/all' prepare_s
# ROUNDS (default 3), MIN_TIME (default 0.3 s) and THREADS (default 1) come from the
# environment.
set -euo pipefail
base=${1:?usage: compare_counter.sh BASE_BUILD NEW_BUILD FILTER COUNTER}
new=${2:?usage: compare_counter.sh BASE_BUILD NEW_BUILD FILTER COUNTER}
filter=${3:?usage: compare_counter.sh BASE_BUILD NEW_BUILD FILTER COUNTER}
counter=${4:?usage: compare_counter.sh BASE_BUILD NEW_BUILD FILTER COUNTER}
rounds=${ROUNDS:-3}
min_time=${MIN_TIME:-0.3}
threads=${THREADS:-1}
here=$(cd "$(dirname "$0")/.." && pwd)
data="$here/../shared/data"
[ -d "$data" ] || { echo "compare_counter: no $data" >&2; exit 2; }
for build in "$base" "$new"; do
  [ -x "$build/bench/motionlod_bench_bake" ] || {
    echo "compare_counter: no $build/bench/motionlod_bench_bake" >&2
    exit 2
  }
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for ((round = 0; round < rounds; ++round)); do
  for side in base new; do
    build=$base
    [ "$side" = new ] && build=$new
    "$build/bench/motionlod_bench_bake" --data="$data" --threads="$threads" \
      --benchmark_filter="bake/$filter/threads:$threads" --benchmark_min_time="$min_time" \
      --benchmark_repetitions=3 --benchmark_format=json 2>/dev/null >"$work/$side.$round.json"
  done
done
python3 - "$work" "$rounds" "$threads" "$counter" <<'PY'
import json, sys
work, rounds, threads, counter = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
values = {}
for side in ("base", "new"):
    for r in range(rounds):
        for b in json.load(open(f"{work}/{side}.{r}.json"))["benchmarks"]:
            if b.get("run_type") != "iteration" or counter not in b:
                continue
            name = b["run_name"].replace(f"/threads:{threads}", "").replace("/manual_time", "")
            values.setdefault(name, {}).setdefault(side, []).append(b[counter] * 1e3)
if not values:
    sys.exit(f"compare_counter: no case reports {counter}")
print(f"| case ({threads} thread{'s' if threads != '1' else ''}, min of {counter}) | base ms | new ms |")
print("|---|---|---|")
for name in sorted(values):
    sides = values[name]
    cell = lambda side: f"{min(sides[side]):.3g}" if side in sides else "–"
    print(f"| {name} | {cell('base')} | {cell('new')} |")
PY
