#!/usr/bin/env bash
# npm_ci.sh DIR: `npm ci` in DIR when its package-lock.json changed since the last install
# there (a stamp in DIR/node_modules), without running install scripts. Idempotent.
set -euo pipefail
cd "$1"
lock_hash=$(sha256sum package-lock.json | cut -d' ' -f1)
stamp=node_modules/.motionlod-lock-sha256
if [ "$(cat "$stamp" 2>/dev/null)" != "$lock_hash" ]; then
  echo "setup: npm ci in $1" >&2
  npm ci --ignore-scripts --no-audit --no-fund --loglevel=error >/dev/null
  echo "$lock_hash" >"$stamp"
fi
