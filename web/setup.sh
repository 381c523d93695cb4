#!/usr/bin/env bash
# Builds the web viewer into web/dist (served by motionlodd at /): `npm ci` when the lock
# file changed since the last install (scripts/npm_ci.sh), then the Vite build when a
# source is newer than the last build. Called by scripts/setup.sh; idempotent. Esbuild
# and Rollup take their native binaries from their platform packages: no install script
# needs to run.
set -euo pipefail
cd "$(dirname "$0")"
bash ../scripts/npm_ci.sh .
if [ ! -f dist/index.html ] ||
   [ -n "$(find index.html vite.config.js package-lock.json src -newer dist/index.html | head -1)" ]; then
  echo "setup: building web/dist" >&2
  npm run --silent build >/dev/null
fi
