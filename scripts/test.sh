#!/usr/bin/env bash
# The README's test command (and CI's): install what is missing, build with warnings as
# errors, run every test; then build with sanitizers and run every test again.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh -DMOTIONLOD_BUILD_TESTS=ON -DMOTIONLOD_WERROR=ON
jobs=$(nproc 2>/dev/null || echo 2)
ctest --test-dir build --output-on-failure -j "$jobs" --timeout 900

# The whole suite again under AddressSanitizer and UndefinedBehaviorSanitizer
# (build-asan; warnings are not errors there: GCC warns differently with -fsanitize). A
# finding, a leak at exit included, aborts the process that has it, and so fails its
# test: the daemon tests see motionlodd exit non-zero at SIGTERM. MOTIONLOD_SANITIZE_TESTS=0
# skips it.
if [ "${MOTIONLOD_SANITIZE_TESTS:-1}" != 0 ]; then
  # -O1: the usual level for sanitizer builds (compiles faster than -O3, runs fast enough).
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O1 -DNDEBUG" \
    -DMOTIONLOD_BUILD_TESTS=ON -DMOTIONLOD_CHECK_HEADERS=OFF -DMOTIONLOD_SANITIZE=address,undefined \
    >/dev/null
  cmake --build build-asan -j "$jobs"
  ASAN_OPTIONS=halt_on_error=1:detect_leaks=1:abort_on_error=0 \
    LSAN_OPTIONS="suppressions=$PWD/scripts/lsan-suppressions.txt:print_suppressions=0" \
    UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
    ctest --test-dir build-asan --output-on-failure -j "$jobs" --timeout 1800
fi

# A short fuzzing pass (docs/RELIABILITY.md): build-fuzz with clang, every committed
# regression input replayed, then each libFuzzer target for MOTIONLOD_FUZZ_SECONDS
# (default 10; 0 skips it).
if [ "${MOTIONLOD_FUZZ_SECONDS:-10}" != 0 ]; then
  bash scripts/fuzz.sh "${MOTIONLOD_FUZZ_SECONDS:-10}"
fi
