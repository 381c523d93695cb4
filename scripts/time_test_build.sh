#!/usr/bin/env bash
# Wall and CPU time of building every test program from scratch in an existing build
# directory, the libraries already built: what the test programs' own flags and
# precompiled headers cost (docs/RELIABILITY.md). Compare two trees by running it on each,
# one after the other, on an otherwise idle machine.
#   bash scripts/time_test_build.sh [BUILD_DIR]   (default: build, configured with
#                                                  MOTIONLOD_BUILD_TESTS=ON)
set -euo pipefail
build=${1:-build}
[ -f "$build/build.ninja" ] && [ -d "$build/tests" ] ||
  { echo "time_test_build: $build is not a Ninja build with the tests" >&2; exit 2; }
[ -x /usr/bin/time ] ||
  { echo "time_test_build: /usr/bin/time is not installed (apt-get install time)" >&2; exit 2; }
ninja -C "$build" >/dev/null
find "$build/tests" \( -name '*.o' -o -name '*.gch' \) -delete
/usr/bin/time -f "tests' build: %e s wall, %U s user CPU" ninja -C "$build" >/dev/null
