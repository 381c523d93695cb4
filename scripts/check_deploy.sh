#!/usr/bin/env bash
# Checks docker/Dockerfile and docker/compose.yaml where no Docker engine runs (CI, these
# machines): every compose build target is a Dockerfile stage, every MOTIONLODD_*
# variable they set is an option of the daemon, every package they install is a Debian
# 12 package, and the proxy stage's edit of deploy/nginx/motionlod.conf finds its line.
# Usage: scripts/check_deploy.sh path/to/motionlodd
set -euo pipefail
cd "$(dirname "$0")/.."
daemon=${1:?usage: $0 path/to/motionlodd}
dockerfile=docker/Dockerfile compose=docker/compose.yaml
failed=0
fail() { echo "check_deploy: $*" >&2; failed=1; }

stages=$(sed -n 's/^FROM .* AS \([a-z-]*\)$/\1/p' "$dockerfile")
for target in $(sed -n 's/.*target: \([a-z-]*\)}.*/\1/p' "$compose"); do
  grep -qx "$target" <<<"$stages" || fail "$compose builds target '$target', not a stage of $dockerfile"
done
[ "$(grep -c 'target:' "$compose")" -ge 3 ] || fail "$compose should build the redis, runtime and proxy targets"

help=$("$daemon" --help)
for variable in $(grep -ho 'MOTIONLODD_[A-Z_]*' "$dockerfile" "$compose" | sort -u); do
  [ "$variable" = MOTIONLODD_CONFIG ] && continue
  flag=--$(tr 'A-Z_' 'a-z-' <<<"${variable#MOTIONLODD_}")
  grep -qE -- "$flag([^a-z-]|$)" <<<"$help" || fail "$variable is set in docker/ but motionlodd has no $flag"
done

# The packages of every apt-get install (continued lines joined, up to its "&&"), checked
# when this machine has Debian's package lists.
packages=$(sed -e ':a' -e '/\\$/N; s/\\\n//; ta' "$dockerfile" |
  grep -o 'apt-get install [^&]*' | tr ' ' '\n' | grep -E '^[a-z0-9][a-z0-9.+-]+$' |
  grep -vxE 'apt-get|install' | sort -u)
known=$(apt-cache pkgnames 2>/dev/null || true)
if [ -n "$known" ]; then
  for package in $packages; do
    grep -qx -- "$package" <<<"$known" || fail "$dockerfile installs '$package', which Debian does not have"
  done
else
  echo "check_deploy: no apt package lists here; package names not checked" >&2
fi

grep -q '^  server 127.0.0.1:8081 ' deploy/nginx/motionlod.conf ||
  fail "the proxy stage's sed no longer finds the upstream line of deploy/nginx/motionlod.conf"
grep -q "sed -i 's/server 127.0.0.1:8081 /server motionlodd:8080 /'" "$dockerfile" ||
  fail "the proxy stage no longer points the upstream at the compose service"
[ "$failed" = 0 ] && echo "check_deploy: docker/ is consistent with the daemon and Debian 12"
exit "$failed"
