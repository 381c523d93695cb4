#!/usr/bin/env bash
# Builds the benchmarks (Release, MOTIONLOD_BUILD_BENCH=ON) into build-bench/ and runs the
# bake against one skinning pass, side by side in one run, for 1 and 2 threads, with
# 5 repetitions in random interleaved order; then prints the markdown tables of
# docs/PERFORMANCE.md (bench/summarize.py).
#
#   bash scripts/bench.sh                 full run (about 11 minutes on 2 cores)
#   bash scripts/bench.sh --quick         vp and vpno+pd, 2 subdivided characters, 3 repetitions
#   bash scripts/bench.sh --update-doc    also rewrite the results section of docs/PERFORMANCE.md
#   bash scripts/bench.sh --threads 1,2,4 -- --benchmark_filter=Orc   (extra flags after --)
#
# Outputs: build-bench/bench-results.json (Google Benchmark JSON) and
# build-bench/bench-results.md (bench-results-quick.* with --quick). Data: ../shared/data
# (override with --data DIR).
set -euo pipefail
cd "$(dirname "$0")/.."

threads=1,2
repetitions=5
min_time=0.2
quick=()
update_doc=0
data=()
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=(--quick); repetitions=3; min_time=0.05 ;;
    --update-doc) update_doc=1 ;;
    --threads) threads="$2"; shift ;;
    --repetitions) repetitions="$2"; shift ;;
    --data) data=("--data=$2"); shift ;;
    --) shift; extra=("$@"); break ;;
    *) echo "bench.sh: unknown argument '$1'" >&2; exit 2 ;;
  esac
  shift
done

bash scripts/setup.sh
build=build-bench
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOTIONLOD_BUILD_BENCH=ON \
  -DMOTIONLOD_BUILD_TESTS=OFF >/dev/null
cmake --build "$build" --target motionlod_bench_bake -j "$(nproc 2>/dev/null || echo 2)"

# The tree being measured (HEAD may move while a long run goes on).
commit="$(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
changed="$(git status --porcelain --untracked-files=no 2>/dev/null | awk '{print $2}')"
if [ -n "$changed" ]; then
  count=$(printf '%s\n' "$changed" | wc -l)
  if [ "$count" -le 5 ]; then
    commit="$commit+uncommitted($(printf '%s\n' "$changed" | tr '\n' ' ' | sed 's/ $//'))"
  else
    commit="$commit+uncommitted($count files)"
  fi
fi

name=bench-results
[ ${#quick[@]} -gt 0 ] && name=bench-results-quick
json="$build/$name.json"
args=(--threads="$threads" "${quick[@]}" "${data[@]}" --benchmark_context=git="$commit"
      --benchmark_repetitions="$repetitions" --benchmark_min_time="$min_time"
      --benchmark_enable_random_interleaving=true
      --benchmark_out="$json" --benchmark_out_format=json "${extra[@]}")
command="$build/bench/motionlod_bench_bake ${args[*]}"
echo "running: $command" >&2
start=$(date +%s)
"$build/bench/motionlod_bench_bake" "${args[@]}" >"$build/$name-console.txt"
echo "bench: $(( $(date +%s) - start )) s" >&2

python3 bench/summarize.py "$json" --command "$command" >"$build/$name.md"
if [ "$update_doc" -eq 1 ]; then
  python3 bench/summarize.py "$json" --command "$command" --doc docs/PERFORMANCE.md
fi
cat "$build/$name.md"
