#!/usr/bin/env bash
# Two motionlodd binaries side by side on cached level fetches (a change to the HTTP
# layer against its base): each seeded with the sample character and one bake, then
# `wrk -t2 -c64 -d8s` on the same level file, ROUNDS rounds alternating the two. Prints
# requests/s and p99 per round.
#   bash bench/http/compare_daemons.sh BASE_MOTIONLODD NEW_MOTIONLODD [ROUNDS]
# (build the base with: git worktree add /tmp/base REV && cmake -S /tmp/base -B
# /tmp/base/build -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOTIONLOD_BUILD_TESTS=OFF &&
# ninja -C /tmp/base/build motionlodd motionlod-import-worker)
set -euo pipefail
cd "$(dirname "$0")/../.."
base_binary=$1
new_binary=$2
rounds=${3:-3}
bash bench/http/install.sh wrk curl
work=$(mktemp -d)
pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true; rm -rf "$work"' EXIT

start() {  # BINARY NAME -> its base URL
  "$1" --port 0 --data-dir "$work/$2" --web-root "" >"$work/$2.out" 2>"$work/$2.log" &
  pids+=($!)
  for _ in $(seq 100); do grep -q '^listening on ' "$work/$2.out" 2>/dev/null && break; sleep 0.1; done
  sed -n 's/^listening on //p' "$work/$2.out"
}
seed() {  # BASE_URL -> a level URL of a finished bake
  local id
  curl -sf -o /dev/null -X POST -H 'Content-Type: application/octet-stream' \
    --data-binary @samples/Rig_Medium_MovementBasic.glb "$1/v1/characters?filename=rig.glb"
  id=$(curl -sf -X POST -H 'Content-Type: application/json' \
    -d '{"character":"11422afd50abf7e8c92ea107e2e0bc94abd38023d6d15f55ad580347efbfa29e","motion":"Walking_A","levels":[17,6]}' \
    "$1/v1/bakes" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
  curl -sf -o /dev/null "$1/v1/jobs/$id?wait=30"
  curl -sf -H 'Accept: application/json' "$1/v1/bakes/$id/level?px=120" |
    python3 -c 'import json,sys; print(json.load(sys.stdin)["url"])'
}
base_url=$(start "$base_binary" base)
new_url=$(start "$new_binary" new)
base_level=$(seed "$base_url")
new_level=$(seed "$new_url")
for round in $(seq "$rounds"); do
  for which in base new; do
    if [ "$which" = base ]; then url=$base_url$base_level; else url=$new_url$new_level; fi
    wrk -t2 -c64 -d8s --latency "$url" |
      awk -v w="$which" -v r="$round" '/Requests\/sec/ {rps=$2} / 99%/ {p99=$2} END {print w, "round", r ":", rps, "requests/s, p99", p99}'
  done
done
