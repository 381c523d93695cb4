#!/usr/bin/env bash
# The README's test command (and CI's): install what is missing, build with warnings as
# errors, run every test; then build with sanitizers and run the tests again.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# A unity build (each target's sources compiled a few at a time, the headers parsed once
# per batch) takes about a third of the time of one source at a time on 2 cores; each
# header still compiles on its own (the header checks), and builds by hand stay per source.
bash scripts/build.sh -DMOTIONLOD_BUILD_TESTS=ON -DMOTIONLOD_WERROR=ON -DCMAKE_UNITY_BUILD=ON
jobs=$(nproc 2>/dev/null || echo 2)
ctest --test-dir build --output-on-failure -j "$jobs" --timeout 900

# The suite again under AddressSanitizer and UndefinedBehaviorSanitizer
# (build-asan; warnings are not errors there: GCC warns differently with -fsanitize). A
# finding, a leak at exit included, aborts the process that has it, and so fails its
# test: the daemon tests see motionlodd exit non-zero at SIGTERM. MOTIONLOD_SANITIZE_TESTS=0
# skips it.
if [ "${MOTIONLOD_SANITIZE_TESTS:-1}" != 0 ]; then
  # -O1: the usual level for sanitizer builds (compiles faster than -O3, runs fast enough);
  # a unity build as above.
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O1 -DNDEBUG" \
    -DMOTIONLOD_BUILD_TESTS=ON -DMOTIONLOD_CHECK_HEADERS=OFF -DMOTIONLOD_SANITIZE=address,undefined \
    -DCMAKE_UNITY_BUILD=ON >/dev/null
  cmake --build build-asan -j "$jobs"
  # Left to the Release pass: the baseline-SIMD copies of the real-data tests, and the
  # tests that bake default ladders (by cost), 20 to 30 times slower here (0.5 to 3
  # minutes each). Under the sanitizers the same code runs in the daemon's other bakes,
  # the explicit-level CLI tests and the core's tests on built fixtures.
  sanitizer_skip='^simd_baseline\.RealData\.|^RealData\.TheDefaultLadder|^Cli\.BakesTheSampleWithTheDefaultLadder$'
  sanitizer_skip+='|^CostLevels\.RealCharacters|^LevelChoiceOnRealData\.|^GltfExportHttp\.ExportsEachLevelByCost'
  sanitizer_skip+='|^CostLevels\.TheSamplesLadder|^DaemonFlow\.UploadBakeWatchAndFetchLevelsMatchTheEngineInProcess$'
  sanitizer_skip+='|^DaemonFlow\.TheSeedPrintsAReadableHeightRangeForEveryLevel$|^Cli\.ExportsEachLevelByCost'
  sanitizer_skip+='|^Cli\.BakesTheLevelsForTheHeightsAsked$'
  # Their paths run here in lighter tests: every clip's levels (the clip tests), the glTF
  # validator (the daemon's export test), a drain at SIGTERM (the crash test's last stop).
  sanitizer_skip+='|^RealData\.CharacterWideLevelsServeEveryClip$|^Cli\.ExportsLevelsThatTheGltfValidatorAccepts$'
  sanitizer_skip+='|^DaemonRestart\.SigtermLeavesUnfinishedJobsQueuedForTheNextStart$'
  # Processes killed and restarted, a minute or more here: the recovery code they drive
  # runs here in the one-kill restart test, the poison-job test and the Redis backend's
  # tests (the store, the queue's takeover, sixty bakes on three daemons).
  sanitizer_skip+='|^CrashRestart\.|^DaemonRestart\.JobsQueuedOrRunningAtASigkill'
  sanitizer_skip+='|^ScaleOut\.AKilledDaemons|^ScaleOut\.ARedisRestart'
  sanitizer_skip+='|^web_viewer_e2e$'  # minutes here; the server tests cover the daemon's routes
  ASAN_OPTIONS=halt_on_error=1:detect_leaks=1:abort_on_error=0 \
    LSAN_OPTIONS="suppressions=$PWD/scripts/lsan-suppressions.txt:print_suppressions=0" \
    UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
    ctest --test-dir build-asan --output-on-failure -j "$jobs" --timeout 1800 -E "$sanitizer_skip"
fi

# The committed fuzz regression inputs ran above, in both builds (ctest
# fuzz_regressions.*). MOTIONLOD_FUZZ_SECONDS=N adds a fuzzing pass (docs/RELIABILITY.md):
# build-fuzz with clang, then each libFuzzer target for N seconds.
if [ "${MOTIONLOD_FUZZ_SECONDS:-0}" != 0 ]; then
  bash scripts/fuzz.sh "$MOTIONLOD_FUZZ_SECONDS"
fi
