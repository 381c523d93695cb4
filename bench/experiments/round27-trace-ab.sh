#!/usr/bin/env bash
# Round 27's A/B of two or more builds of the trace tool (round26-pool-trace.patch, target
# motionlod_trace_bake): ROUNDS processes of each, the builds alternating, each printing
# the medians of 400 bakes; per stage (between the trace's marks), the median and the
# fastest over the processes. Steadier than the benchmark's own side by side on a machine
# whose speed drifts over minutes: each process is half a second, and the builds alternate.
#   bash bench/experiments/round27-trace-ab.sh FILE VARIANT THREADS ROUNDS TRACE_BINARY...
# FILE is relative to ../shared/data, e.g. characters/Fox.glb.
set -euo pipefail
[ $# -ge 5 ] || { echo "usage: round27-trace-ab.sh FILE VARIANT THREADS ROUNDS TRACE_BINARY..." >&2; exit 2; }
file=$1 variant=$2 threads=$3 rounds=$4
shift 4
data="$(cd "$(dirname "$0")/../.." && pwd)/../shared/data"
out=$(mktemp)
trap 'rm -f "$out"' EXIT
for _ in $(seq "$rounds"); do
  for binary in "$@"; do
    {
      printf '%s ' "$binary"
      "$binary" "$data/$file" "$variant" "$threads" | awk '/ MARK /{printf "%s=%s ", $5, $1}'
      echo
    } >>"$out"
  done
done
python3 - "$out" "$@" <<'PY'
import statistics, sys
rows = {}
for line in open(sys.argv[1]):
    fields = line.split()
    marks = {k: float(v) for k, v in (f.split('=') for f in fields[1:])}
    stage = {'inputs': marks['rank+create'] - marks['inputs'],
             'rank+create': marks['ladder'] - marks['rank+create'],
             'ladder': marks['search'] - marks['ladder'],
             'search': marks['final'] - marks['search'],
             'final': marks['encode'] - marks['final'],
             'encode': marks['end'] - marks['encode'],
             'total': marks['end']}
    rows.setdefault(fields[0], []).append(stage)
keys = ['inputs', 'rank+create', 'ladder', 'search', 'final', 'encode', 'total']
print('| build | statistic | ' + ' | '.join(keys) + ' |')
print('|---|---|' + '---:|' * len(keys))
for binary in sys.argv[2:]:
    for name, stat in (('median', statistics.median), ('fastest', min)):
        print(f'| `{binary}` | {name} | ' + ' | '.join(f'{stat([r[k] for r in rows[binary]]):.1f}' for k in keys) + ' |')
PY
