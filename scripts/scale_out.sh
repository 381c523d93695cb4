#!/usr/bin/env bash
# docker/compose.yaml's topology as plain processes on loopback: redis-server (append-only
# file, fsync always), N motionlodd on it (backend = "redis", one shared blob directory)
# and nginx with deploy/nginx/motionlod.conf in front of them. For trying it without
# Docker, for CI (check) and for bench/scale/run.sh.
#   scripts/scale_out.sh up DIR [N]   start them (N daemons, default 3); prints the proxy URL
#   scripts/scale_out.sh check DIR    upload, bake and fetch through the proxy, bytes checked
#   scripts/scale_out.sh down DIR     stop them (SIGTERM: the daemons drain)
#   scripts/scale_out.sh test DIR     up with 3 daemons, check, down (CI: ctest scale_out_script)
# Needs a build (BUILD, default build/) with the daemon and the client, redis-server and
# nginx. MOTIONLODD_ARGS: more flags for every daemon (e.g. "--threads 1").
set -euo pipefail
cd "$(dirname "$0")/.."
command=${1:?usage: $0 up|check|down DIR [N]}
dir=$(realpath -m "${2:?usage: $0 up|check|down DIR [N]}")
build=${BUILD:-build}

free_port() {
  local port
  while :; do
    port=$((20000 + RANDOM % 40000))
    (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null || { echo "$port"; return; }
  done
}
# Whether the process runs (a zombie whose parent, the shell of "up", is gone does not).
alive() { [ -e "/proc/$1" ] && ! grep -qE '^[0-9]+ \(.*\) Z' "/proc/$1/stat" 2>/dev/null; }
wait_for() {  # URL: until it answers 200 (20 s)
  for _ in $(seq 200); do curl -sf -o /dev/null "$1" && return 0; sleep 0.1; done
  echo "scale_out: $1 did not answer" >&2
  return 1
}

case "$command" in
up)
  daemons=${3:-3}
  mkdir -p "$dir/redis" "$dir/blobs" "$dir/nginx/cache" "$dir/nginx/logs"
  redis_port=$(free_port)
  redis-server --port "$redis_port" --bind 127.0.0.1 --dir "$dir/redis" --appendonly yes \
    --appendfsync always --save "" --logfile "$dir/redis/redis.log" --daemonize no &
  echo $! >"$dir/redis.pid"
  for _ in $(seq 100); do redis-cli -p "$redis_port" ping >/dev/null 2>&1 && break; sleep 0.1; done
  servers=""
  for d in $(seq "$daemons"); do
    port=$(free_port)
    "$build/server/motionlodd" --port "$port" --data-dir "$dir/daemon$d" --backend redis \
      --redis-url "redis://127.0.0.1:$redis_port" --blob-dir "$dir/blobs" \
      ${MOTIONLODD_ARGS:-} >"$dir/daemon$d.log" 2>&1 &
    echo $! >"$dir/daemon$d.pid"
    wait_for "http://127.0.0.1:$port/readyz"
    servers+="  server 127.0.0.1:$port max_fails=3 fail_timeout=10s;\n"
  done
  proxy_port=$(free_port)
  sed -e "s|listen 8080|listen 127.0.0.1:$proxy_port|" \
    -e "s|^  server 127.0.0.1:8081 .*|$servers|" \
    -e "s|/var/cache/nginx/motionlod|$dir/nginx/cache|" deploy/nginx/motionlod.conf >"$dir/nginx/site.conf"
  user=""
  [ "$(id -u)" = 0 ] && user="user root;"
  cat >"$dir/nginx/nginx.conf" <<CONF
$user
worker_processes 1;
pid $dir/nginx/nginx.pid;
error_log $dir/nginx/logs/error.log warn;
events { worker_connections 4096; }
http {
  access_log off;
  client_body_temp_path $dir/nginx/body;
  proxy_temp_path $dir/nginx/proxy;
  fastcgi_temp_path $dir/nginx/fastcgi;
  uwsgi_temp_path $dir/nginx/uwsgi;
  scgi_temp_path $dir/nginx/scgi;
  include $dir/nginx/site.conf;
}
CONF
  nginx -p "$dir/nginx" -c "$dir/nginx/nginx.conf" -g "daemon off;" &
  echo $! >"$dir/nginx.pid"
  echo "http://127.0.0.1:$proxy_port" >"$dir/url"
  wait_for "http://127.0.0.1:$proxy_port/readyz"
  echo "scale_out: $daemons daemons on redis://127.0.0.1:$redis_port behind $(cat "$dir/url")"
  ;;
check)
  url=$(cat "$dir/url")
  client=("$build/client/motionlod-client" --server "$url")
  character=$("${client[@]}" upload samples/Rig_Medium_MovementBasic.glb | grep -Eo '[0-9a-f]{64}' | head -1)
  bake=$("${client[@]}" bake "$character" --motion Walking_A --levels 16,8 | grep -Eo '[0-9a-f]{64}' | head -1)
  for level in 0 1; do
    "${client[@]}" fetch "$bake" --level "$level" -o "$dir/level$level.mlod" >/dev/null
    hash=$(sha256sum "$dir/level$level.mlod" | cut -c1-64)
    # Through the proxy's cache and from every daemon: the same bytes under that hash.
    for source in "$url" $(sed -n 's|^  server \(127.0.0.1:[0-9]*\) .*|http://\1|p' "$dir/nginx/site.conf"); do
      got=$(curl -sf "$source/v1/levels/$hash" | sha256sum | cut -c1-64)
      [ "$got" = "$hash" ] || { echo "scale_out: $source serves other bytes for level $level" >&2; exit 1; }
    done
  done
  echo "scale_out: check passed (bake $bake, levels served by the proxy and every daemon)"
  ;;
down)
  # The proxy and the daemons first (they drain, requeueing into Redis), then Redis.
  for group in "nginx daemon*" "redis"; do
    pids=()
    for name in $group; do
      for pidfile in "$dir"/$name.pid; do
        [ -f "$pidfile" ] && pids+=("$(cat "$pidfile")") && rm -f "$pidfile"
      done
    done
    [ ${#pids[@]} -gt 0 ] || continue
    kill "${pids[@]}" 2>/dev/null || true
    for pid in "${pids[@]}"; do
      for _ in $(seq 300); do alive "$pid" || break; sleep 0.1; done
    done
  done
  ;;
test)
  trap 'bash "$0" down "$dir"' EXIT
  bash "$0" up "$dir" 3
  bash "$0" check "$dir"
  ;;
*) echo "usage: $0 up|check|down|test DIR [N]" >&2; exit 2 ;;
esac
