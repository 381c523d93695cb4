#!/usr/bin/env bash
# Slow clients against motionlodd: 1000 connections (half trickle a header byte every
# 5 s, half never send) for 12 s while ordinary clients fetch levels, choose levels and
# submit bakes, on new and on kept connections. Runs the test
# SlowClients.AThousandSlowConnectionsLeaveOrdinaryClientsServed (tests/server/
# slow_clients_test.cc) REPEAT times with the target p99 of 100 ms and prints each run's
# figures; exits 1 when a run misses it.
# Options (environment): REPEAT=3 SLOW_CLIENTS=1000 P99_MS=100 BUILD_DIR=build
set -euo pipefail
cd "$(dirname "$0")/../.."
build_dir=${BUILD_DIR:-build}
[ -f "$build_dir/CMakeCache.txt" ] ||
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build_dir" --target server_daemon_test motionlodd motionlod-import-worker \
  -j "$(nproc)"
status=0
for run in $(seq "${REPEAT:-3}"); do
  echo "run $run:"
  MOTIONLOD_SLOW_CLIENTS=${SLOW_CLIENTS:-1000} MOTIONLOD_SLOW_CLIENTS_P99_MS=${P99_MS:-100} \
    "$build_dir/tests/server/server_daemon_test" \
    --gtest_filter='SlowClients.AThousandSlowConnectionsLeaveOrdinaryClientsServed:SlowClients.BehindTheProxyOfDeployNginxToo' |
    grep -E 'slow connections|OK|FAILED|Failure' || status=1
done
exit "$status"
