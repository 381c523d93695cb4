#!/usr/bin/env bash
# Installs the Debian 12 packages motionlod builds and tests with, only those missing,
# then builds the web viewer (web/setup.sh: npm ci and Vite into web/dist).
# Idempotent; needs root (or sudo) only when something is missing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev libassimp-dev nlohmann-json3-dev libspdlog-dev libcli11-dev libssl-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcpp-httplib-dev libsqlite3-dev libtomlplusplus-dev zlib1g-dev libxxhash-dev
  libmeshoptimizer-dev  # simplified meshes of far levels (core/simplify_mesh.cc)
  chromium  # the web viewer's end-to-end test drives it (never a downloaded browser)
  bubblewrap libseccomp-dev  # the import worker's sandbox and its seccomp filter (server/import_sandbox.h)
  clang libclang-rt-14-dev  # libFuzzer targets (scripts/fuzz.sh)
  nginx-light  # the reverse proxy of deploy/nginx/, run by the slow-client test
  libhiredis-dev redis-server  # the Redis backend (server/redis_*.h) and its tests
)
# The web viewer builds with Node.js (18 or later): Debian's, unless one is installed.
command -v node >/dev/null || packages+=(nodejs npm)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}" >&2
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  export DEBIAN_FRONTEND=noninteractive
  if ! $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null; then
    $sudo apt-get update -qq
    $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
fi

# The web viewer (web/dist), served by motionlodd at /.
bash "$(dirname "$0")/../web/setup.sh"

# The Khronos glTF validator the export tests run (tools/gltf-validate).
bash "$(dirname "$0")/npm_ci.sh" "$(dirname "$0")/../tools/gltf-validate"
