#!/usr/bin/env bash
# Wall-clock A/B of two builds of the bake benchmark, side by side on the same machine:
# the two programs run alternately, ROUNDS rounds of 3 repetitions each, and every bake is
# compared as a ratio to its own build's skinning pass, so that load on the shared machine
# falls on both builds alike (docs/PERFORMANCE.md, "How to run").
#   bash bench/compare_builds.sh BASE_BUILD NEW_BUILD [FILTER]
# BASE_BUILD and NEW_BUILD hold bench/motionlod_bench_bake (MOTIONLOD_BUILD_BENCH=ON; e.g.
# a `git worktree` of the base commit configured like build-bench/). FILTER is a Google
# Benchmark regex over bake/ cases; the matching skin/ cases are added. ROUNDS (default
# 2), MIN_TIME (default 0.3 s) and THREADS (default 1) come from the environment, and
# STAT: `median` (the default: the median of the rounds' medians) or `min` (the fastest
# repetition of all rounds, steadier where other tenants load the machine: noise only
# ever adds time).
set -euo pipefail
base=${1:?usage: compare_builds.sh BASE_BUILD NEW_BUILD [FILTER]}
new=${2:?usage: compare_builds.sh BASE_BUILD NEW_BUILD [FILTER]}
filter=${3:-'(09_11_cmu.fbx|stormtrooper.dae|Orc.gltf)/(vp|vpno\+pd)/default'}
ROUNDS=${ROUNDS:-2}
THREADS=${THREADS:-1}
stat=${STAT:-median}
case "$stat" in median | min) ;; *) echo "compare_builds: STAT must be median or min" >&2; exit 2 ;; esac
# The skinning passes of the files the filter names, e.g. skin/Orc.gltf/threads:1.
cases=$(sed -E 's/^\(([^)]*)\)\/.*$/\1/; t; s/\/.*$//' <<<"$filter")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# shellcheck source=bench/side_by_side.sh
source "$(dirname "$0")/side_by_side.sh"
run_side_by_side compare_builds "$base" "$new" \
  "bake/$filter/threads:$THREADS|skin/($cases)/threads:$THREADS" "$work"
python3 - "$work" "$ROUNDS" "$THREADS" "$stat" "$(dirname "$0")" <<'EOF'
import statistics, sys
work, rounds, threads, stat = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
sys.path.insert(0, sys.argv[5])
from side_by_side import side_by_side_results
# median: one entry per round (its median); min: every repetition.
times = {}
for side, name, b in side_by_side_results(work, rounds, threads):
    wanted = b.get("aggregate_name") == "median" if stat == "median" else b.get("run_type") == "iteration"
    if wanted:
        scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b["time_unit"]]
        times.setdefault((name, side), []).append(b["real_time"] * scale)
print(f"| case ({threads} thread{'s' if threads != '1' else ''}, {stat}) | base ms (ratio) | new ms (ratio) | change |")
print("|---|---|---|---|")
for name in sorted({n for n, _ in times if n.startswith("bake/")}):
    case = name.split("/")[1]
    row = []
    for side in ("base", "new"):
        pick = statistics.median if stat == "median" else min
        bake = pick(times[(name, side)])
        skin = pick(times[("skin/" + case, side)])
        row.append((bake, bake / skin))
    change = 100 * (row[1][0] / row[0][0] - 1)
    print(f"| {name[5:]} | {row[0][0]:.3g} ({row[0][1]:.2f}x) | {row[1][0]:.3g} ({row[1][1]:.2f}x) | {change:+.0f}% |")
EOF
