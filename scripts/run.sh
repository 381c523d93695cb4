#!/usr/bin/env bash
# The README's run command: install what is missing, build (the web viewer too, by
# setup.sh), and start motionlodd on http://127.0.0.1:${PORT:-8080} with the embedded CC0
# sample character uploaded and baked; it prints the viewer's URL ("web viewer: ..."),
# the other URLs and the level table, and serves until Ctrl-C (SIGINT drains).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh -DMOTIONLOD_BUILD_TESTS=OFF
exec ./build/server/motionlodd --config config/motionlodd.toml --data-dir out/motionlodd \
  --port "${PORT:-8080}" --seed samples/Rig_Medium_MovementBasic.glb --seed-animation Walking_A
