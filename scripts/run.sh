#!/usr/bin/env bash
# The README's run command: install what is missing, build, and bake the embedded sample
# character (CC0) with the default ladder, printing its level table.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh -DMOTIONLOD_BUILD_TESTS=OFF
./build/tools/motionlod bake samples/Rig_Medium_MovementBasic.glb --animation Walking_A \
  --out out/sample
