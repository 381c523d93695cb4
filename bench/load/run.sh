#!/usr/bin/env bash
# Bounded mixed load on loopback: level fetches, level choices, bake submissions and
# uploads together, with 64 connections for a fixed duration, against a motionlodd with
# a small level cache. Checks: no 5xx but the intended 503s (a full bake queue, too many
# uploads or imports at once), no socket errors, and the daemon's resident memory
# (sampled every 0.2 s) within the cache budget plus a stated margin. Writes
# bench/load/RESULTS.md; exits 1 when a check fails.
# Options (environment):
#   DURATION=30s CONNECTIONS=64 WRK_THREADS=2 BUILD_DIR=build
#   CACHE_BYTES=262144 (256 KiB: smaller than the level files fetched, so that the cache
#   evicts and reloads under the load) RSS_MARGIN_BYTES=268435456 (256 MiB)
set -euo pipefail
cd "$(dirname "$0")/../.."
duration=${DURATION:-30s}
connections=${CONNECTIONS:-64}
wrk_threads=${WRK_THREADS:-2}
build_dir=${BUILD_DIR:-build}
cache_bytes=${CACHE_BYTES:-262144}
margin_bytes=${RSS_MARGIN_BYTES:-268435456}
load=$(cut -d' ' -f1-3 /proc/loadavg)

bash bench/http/install.sh wrk curl
bash scripts/setup.sh
[ -f "$build_dir/CMakeCache.txt" ] ||
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOTIONLOD_BUILD_TESTS=OFF >/dev/null
cmake --build "$build_dir" --target motionlodd motionlod-import-worker -j "$(nproc)"

work=$(mktemp -d)
pid=""
sampler=""
cleanup() {
  [ -n "$sampler" ] && kill "$sampler" 2>/dev/null
  [ -n "$pid" ] && kill "$pid" 2>/dev/null
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT

# Enough connection threads for the load's connections and the set-up's; the bake queue
# and the import limits at their defaults, so that the load meets them.
"$build_dir/server/motionlodd" --port 0 --data-dir "$work/data" --http-threads 128 \
  --cache-bytes "$cache_bytes" >"$work/out" 2>"$work/log" &
pid=$!
for _ in $(seq 100); do grep -q '^listening on ' "$work/out" 2>/dev/null && break; sleep 0.1; done
base=$(sed -n 's/^listening on //p' "$work/out")
[ -n "$base" ] || { cat "$work/log"; exit 1; }
json() { python3 -c "import json,sys; print(json.load(sys.stdin)$1)"; }

sample=samples/Rig_Medium_MovementBasic.glb
character=$(curl -sf -X POST -H 'Content-Type: application/octet-stream' --data-binary @$sample \
  "$base/v1/characters?filename=load.glb" | json '["id"]')
# Three bakes to fetch levels of: every level of each.
bakes=()
levels=()
for motion in Walking_A Walking_B Running_A; do
  job=$(curl -sf -X POST -H 'Content-Type: application/json' \
    -d "{\"character\":\"$character\",\"motion\":\"$motion\"}" "$base/v1/bakes" | json '["id"]')
  state=queued
  for _ in $(seq 60); do
    state=$(curl -sf "$base/v1/jobs/$job?wait=5" | json '["state"]')
    [ "$state" = succeeded ] || [ "$state" = failed ] && break
  done
  [ "$state" = succeeded ] || { echo "load: the bake of $motion did not succeed ($state)"; exit 1; }
  bakes+=("$job")
  for hash in $(curl -sf "$base/v1/bakes/$job" |
    python3 -c 'import json,sys; print(" ".join(l["hash"] for l in json.load(sys.stdin)["levels"]))'); do
    levels+=("/v1/levels/$hash")
  done
done
rss_kib() { sed -n 's/^VmRSS:[[:space:]]*\([0-9]*\) kB/\1/p' "/proc/$pid/status"; }
rss_before=$(rss_kib)

( while kill -0 "$pid" 2>/dev/null; do rss_kib; sleep 0.2; done >"$work/rss" ) &
sampler=$!
LOAD_LEVELS="${levels[*]}" LOAD_BAKES="${bakes[*]}" LOAD_CHARACTER="$character" \
  LOAD_SAMPLE="$sample" wrk -t"$wrk_threads" -c"$connections" -d"$duration" --latency \
  --timeout 30s -s bench/load/mix.lua "$base" >"$work/wrk" || { cat "$work/wrk"; exit 1; }
kill "$sampler" 2>/dev/null || true
wait "$sampler" 2>/dev/null || true
sampler=""
rss_max=$(sort -n "$work/rss" | tail -1)
metrics=$(curl -sf "$base/metrics")
kill -0 "$pid" || { echo "load: motionlodd died"; cat "$work/log"; exit 1; }

result=$(grep '^RESULT' "$work/wrk")
field() { sed -n "s/.* $1=\([^ ]*\).*/\1/p" <<<"$result"; }
sent=$(grep '^SENT' "$work/wrk" | sort -k3,3nr)
statuses=$(grep '^STATUS' "$work/wrk" | sort -k2,2n)
unexpected=$(awk '$2 >= 500 && $2 != 503 {n += $3} END {print n + 0}' <<<"$statuses")
refused=$(awk '$2 == 503 {n += $3} END {print n + 0}' <<<"$statuses")
socket_errors=$(field socket_errors)
limit_kib=$(((cache_bytes + margin_bytes) / 1024))
verdict=pass
[ "$unexpected" -eq 0 ] && [ "$socket_errors" -eq 0 ] && [ "$rss_max" -le "$limit_kib" ] || verdict=FAIL

{
  cat <<MD
# Mixed load: uploads, bakes and level fetches

Written by \`bash bench/load/run.sh\` on $(date -u +%Y-%m-%d) ($(nproc) cores, $(uname -srm);
load average before the run: ${load}). motionlodd (\`--http-threads 128 --cache-bytes
${cache_bytes}\`, every other option at its default: 2 imports and 8 uploads at once, a
bake queue of 64) seeded with the sample character and three bakes of it (${#levels[@]}
level files), then \`wrk -t${wrk_threads} -c${connections} -d${duration} --latency -s bench/load/mix.lua\`
on loopback: of every 1000 requests 900 level fetches (\`GET /v1/levels/{hash}\`), 60
level choices (\`GET /v1/bakes/{id}/level?px=\`, JSON), 30 bake submissions (levels and
fps drawn from 33 combinations: new ones are queued, repeats answered at once) and 10
uploads of the 674 KiB sample (content-addressed: the same id each time).

| requests | seconds | requests/s | p50 ms | p90 ms | p99 ms | max ms | socket errors |
|---:|---:|---:|---:|---:|---:|---:|---:|
| $(field requests) | $(field seconds) | $(field rps) | $(field p50_ms) | $(field p90_ms) | $(field p99_ms) | $(field max_ms) | ${socket_errors} |

| requests sent | count |
|---|---:|
$(awk '{print "| " $2 " | " $3 " |"}' <<<"$sent")

| responses: status | count |
|---|---:|
$(awk '{print "| " $2 " | " $3 " |"}' <<<"$statuses")

- 5xx other than 503: **${unexpected}**; 503 (intended: full bake queue, too many
  uploads or imports at once, each with Retry-After): ${refused}.
- Resident memory: $((rss_before / 1024)) MiB after seeding, **$((rss_max / 1024)) MiB** at most during
  the run (sampled every 0.2 s), against a limit of the cache budget
  ($((cache_bytes / 1024)) KiB) plus a margin of $((margin_bytes / 1048576)) MiB for uploads in flight,
  imports, bakes and thread stacks: $((limit_kib / 1024)) MiB.
- Level cache at the end: $(grep -E '^motionlodd_level_cache_(bytes|evictions_total|requests_total)' <<<"$metrics" | sed 's/^/`/; s/$/`/' | paste -sd ' ' -).

Verdict: **${verdict}**.
MD
} >bench/load/RESULTS.md
cat bench/load/RESULTS.md
[ "$verdict" = pass ]
