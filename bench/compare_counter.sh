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
ROUNDS=${ROUNDS:-3}
THREADS=${THREADS:-1}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# shellcheck source=bench/side_by_side.sh
source "$(dirname "$0")/side_by_side.sh"
run_side_by_side compare_counter "$base" "$new" "bake/$filter/threads:$THREADS" "$work"
python3 - "$work" "$ROUNDS" "$THREADS" "$counter" "$(dirname "$0")" <<'PY'
import sys
work, rounds, threads, counter = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
sys.path.insert(0, sys.argv[5])
from side_by_side import side_by_side_results
values = {}
for side, name, b in side_by_side_results(work, rounds, threads):
    if b.get("run_type") == "iteration" and counter in b:
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
