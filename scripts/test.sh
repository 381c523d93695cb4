#!/usr/bin/env bash
# The README's test command (and CI's): install what is missing, build with warnings as
# errors, run every test.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh -DMOTIONLOD_BUILD_TESTS=ON -DMOTIONLOD_WERROR=ON
cd build
ctest --output-on-failure -j "$(nproc 2>/dev/null || echo 2)" --timeout 900
