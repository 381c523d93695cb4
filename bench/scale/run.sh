#!/usr/bin/env bash
# Bakes per minute with 1, 2 and 3 daemons on one Redis behind nginx (scripts/scale_out.sh:
# the compose topology as plain processes), each daemon with its default workers (one per
# hardware thread). Each measurement starts a fresh Redis, uploads the sample character
# through the proxy, submits every bake at once (its 11 animations at 30 and 24 fps, the
# default ladder: 22 bakes) and times until the last has succeeded. The orders alternate
# across ROUNDS (default 3); the medians are printed. WORKERS=N gives each daemon N bake
# workers instead (WORKERS=1: one core per daemon, as on machines of their own). Needs a
# build (build/).
set -euo pipefail
cd "$(dirname "$0")/../.."
rounds=${ROUNDS:-3}
work=$(mktemp -d)
trap 'for t in "$work"/*/; do bash scripts/scale_out.sh down "$t" 2>/dev/null; done; rm -rf "$work"' EXIT
animations=(Jump_Full_Long Jump_Full_Short Jump_Idle Jump_Land Jump_Start Running_A Running_B
            T-Pose Walking_A Walking_B Walking_C)

measure() {  # DAEMONS -> bakes per minute
  local dir="$work/run$RANDOM" url character ids=() start end
  MOTIONLODD_ARGS=${WORKERS:+--threads $WORKERS} bash scripts/scale_out.sh up "$dir" "$1" >/dev/null
  url=$(cat "$dir/url")
  character=$(curl -sf -H 'Content-Type: application/octet-stream' \
    --data-binary @samples/Rig_Medium_MovementBasic.glb \
    "$url/v1/characters?filename=Rig_Medium_MovementBasic.glb" |
    grep -Eo '"character":"[0-9a-f]{64}"' | grep -Eo '[0-9a-f]{64}' | head -1)
  start=$(date +%s.%N)
  for fps in 30 24; do
    for animation in "${animations[@]}"; do
      ids+=("$(curl -sf -H 'Content-Type: application/json' "$url/v1/bakes" -d \
        "{\"character\":\"$character\",\"motion\":\"$animation\",\"fps\":$fps}" |
        grep -Eo '"id":"[0-9a-f]{64}"' | grep -Eo '[0-9a-f]{64}')")
      [ -n "${ids[-1]}" ] || { echo "bench: a bake was not accepted" >&2; exit 1; }
    done
  done
  for id in "${ids[@]}"; do
    until curl -sf "$url/v1/jobs/$id?wait=20" | grep -q '"state":"succeeded"'; do
      curl -sf "$url/v1/jobs/$id" | grep -q '"state":"failed"' && { echo "bench: bake $id failed" >&2; exit 1; }
    done
  done
  end=$(date +%s.%N)
  bash scripts/scale_out.sh down "$dir"
  echo "${#ids[@]} $start $end" | awk '{printf "%.1f\n", $1 * 60 / ($3 - $2)}'
}

declare -A results
for round in $(seq "$rounds"); do
  order=(1 2 3)
  [ $((round % 2)) = 0 ] && order=(3 2 1)
  for daemons in "${order[@]}"; do
    results[$daemons]+="$(measure "$daemons") "
    echo "round $round, $daemons daemons: bakes/min ${results[$daemons]}" >&2
  done
done
median() { tr ' ' '\n' | grep . | sort -n | awk '{v[NR]=$1} END {print v[int((NR+1)/2)]}'; }
echo "| daemons | bakes/min (median of $rounds) | runs |"
echo "|---|---|---|"
for daemons in 1 2 3; do
  echo "| $daemons | $(median <<<"${results[$daemons]}") | ${results[$daemons]}|"
done
echo "machine: $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg); workers per daemon: ${WORKERS:-one per hardware thread}"
