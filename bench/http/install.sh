#!/usr/bin/env bash
# Installs the Debian packages named on the command line, only those missing (the bench
# scripts' tools: wrk, nginx-light, curl). Needs root (or sudo) only when one is missing.
set -euo pipefail
missing=()
for p in "$@"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
sudo=""
[ "$(id -u)" -ne 0 ] && sudo="sudo"
echo "bench: installing ${missing[*]}" >&2
# RUNLEVEL=1: a package's own service (nginx) is not started.
export DEBIAN_FRONTEND=noninteractive RUNLEVEL=1
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null ||
  { $sudo apt-get update -qq && $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null; }
