#!/usr/bin/env bash
# Cached level fetches over loopback: motionlodd against nginx serving the same bytes as
# a static file, and against nginx in front of motionlodd with deploy/nginx/motionlod.conf
# (its level cache), in the same run, with the same load:
#   wrk -t2 -c64 -d10s --latency -s bench/http/report.lua URL
# Installs what is missing (wrk, nginx-light, curl), builds motionlodd, bakes the sample
# character, and writes bench/http/RESULTS.md. Options (environment):
#   DURATION=10s CONNECTIONS=64 WRK_THREADS=2 ROUNDS=3 BUILD_DIR=build ACCESS_LOG=true
# bench/http/RESULTS.md was written with ROUNDS=5.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
duration=${DURATION:-10s}
connections=${CONNECTIONS:-64}
wrk_threads=${WRK_THREADS:-2}
build_dir=${BUILD_DIR:-build}
access_log=${ACCESS_LOG:-true}
rounds=${ROUNDS:-3}
load=$(cut -d' ' -f1-3 /proc/loadavg)

bash bench/http/install.sh wrk nginx-light curl
bash scripts/setup.sh
# An existing build directory keeps its settings; a new one is configured without tests.
[ -f "$build_dir/CMakeCache.txt" ] ||
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOTIONLOD_BUILD_TESTS=OFF >/dev/null
cmake --build "$build_dir" --target motionlodd motionlod-import-worker -j "$(nproc)"

work=$(mktemp -d)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT

# motionlodd on a free port, the sample baked, a level URL picked.
"$build_dir/server/motionlodd" --port 0 --data-dir "$work/data" --access-log "$access_log" \
  >"$work/motionlodd.out" 2>"$work/motionlodd.log" &
pids+=($!)
for _ in $(seq 100); do grep -q '^listening on ' "$work/motionlodd.out" 2>/dev/null && break; sleep 0.1; done
base=$(sed -n 's/^listening on //p' "$work/motionlodd.out")
[ -n "$base" ] || { cat "$work/motionlodd.log"; exit 1; }
character=$(curl -sf -X POST -H 'Content-Type: application/octet-stream' \
  --data-binary @samples/Rig_Medium_MovementBasic.glb "$base/v1/characters?filename=Rig_Medium_MovementBasic.glb" |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
job=$(curl -sf -X POST -H 'Content-Type: application/json' \
  -d "{\"character\":\"$character\",\"motion\":\"Walking_A\"}" "$base/v1/bakes" |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
state=$(curl -sf "$base/v1/jobs/$job?wait=30" | python3 -c 'import json,sys; print(json.load(sys.stdin)["state"])')
for _ in $(seq 30); do
  [ "$state" = succeeded ] && break
  state=$(curl -sf "$base/v1/jobs/$job?wait=5" | python3 -c 'import json,sys; print(json.load(sys.stdin)["state"])')
done
[ "$state" = succeeded ] || { echo "bench: the bake did not succeed ($state)"; exit 1; }
level=$(curl -sf -H 'Accept: application/json' "$base/v1/bakes/$job/level?px=120" |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["url"])')
curl -sf -o "$work/level.mlod" "$base$level"
bytes=$(stat -c %s "$work/level.mlod")

# Starts nginx in DIR (its pid, logs and temporary files there) with these http-level
# lines after the common ones.
start_nginx() {  # DIR HTTP_LINES
  mkdir -p "$1"
  cat >"$1/nginx.conf" <<CONF
worker_processes auto;
daemon off;
pid $1/nginx.pid;
error_log $1/error.log warn;
events { worker_connections 1024; }
http {
  access_log off;
  client_body_temp_path $1/body;
  proxy_temp_path $1/proxy;
  fastcgi_temp_path $1/fastcgi;
  uwsgi_temp_path $1/uwsgi;
  scgi_temp_path $1/scgi;
$2
}
CONF
  nginx -c "$1/nginx.conf" -p "$1" &
  pids+=($!)
}
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

# nginx serving the same bytes on a free port.
port=$(free_port)
mkdir -p "$work/www/v1/levels"
cp "$work/level.mlod" "$work/www$level"
# nginx's workers drop root for nobody: let them read the file and write the cache.
chmod 755 "$work"
chmod -R a+rX "$work/www"
start_nginx "$work/nginx" "  sendfile on;
  tcp_nopush on;
  tcp_nodelay on;
  keepalive_requests 10000;
  types { application/octet-stream mlod; }
  default_type application/octet-stream;
  server {
    listen 127.0.0.1:$port;
    root $work/www;
    location /v1/levels/ { add_header Cache-Control \"public, max-age=31536000, immutable\"; etag on; }
  }"
for _ in $(seq 50); do curl -sf -o /dev/null "http://127.0.0.1:$port$level" && break; sleep 0.1; done
cmp -s <(curl -sf "http://127.0.0.1:$port$level") "$work/level.mlod" || { echo "bench: nginx serves other bytes"; exit 1; }

# nginx in front of motionlodd with the deployment's site file (its addresses and cache
# directory replaced), the level fetched once so that it is in nginx's cache.
proxy_port=$(free_port)
mkdir -p "$work/proxy/cache"
chmod 777 "$work/proxy/cache"
sed -e "s|listen 8080|listen 127.0.0.1:$proxy_port|" -e "s|server 127.0.0.1:8081|server ${base#http://}|" \
  -e "s|/var/cache/nginx/motionlod|$work/proxy/cache|" deploy/nginx/motionlod.conf >"$work/proxy/site.conf"
start_nginx "$work/proxy" "  include $work/proxy/site.conf;"
for _ in $(seq 50); do curl -sf -o /dev/null "http://127.0.0.1:$proxy_port$level" && break; sleep 0.1; done
[ "$(curl -sf -o /dev/null -w '%header{x-cache-status}' "http://127.0.0.1:$proxy_port$level")" = HIT ] ||
  { echo "bench: the proxy does not serve the level from its cache"; exit 1; }

run() {  # URL -> the RESULT line
  wrk -t"$wrk_threads" -c"$connections" -d"$duration" --latency -s bench/http/report.lua "$1" | grep "^RESULT"
}
field() { sed -n "s/.* $2=\([^ ]*\).*/\1/p" <<<"$1"; }
curl -sf -o /dev/null "$base$level"  # warm: the level is in motionlodd's cache

# Rounds alternate the two servers, so that load from elsewhere on the machine weighs on
# both alike; the table gives every round and the median of each.
ours=()
theirs=()
proxied=()
for round in $(seq "$rounds"); do
  ours+=("$(run "$base$level")")
  theirs+=("$(run "http://127.0.0.1:$port$level")")
  proxied+=("$(run "http://127.0.0.1:$proxy_port$level")")
  echo "round $round: motionlodd ${ours[-1]#RESULT }"
  echo "round $round: nginx      ${theirs[-1]#RESULT }"
  echo "round $round: proxy      ${proxied[-1]#RESULT }"
done
median() {  # FIELD LINE... -> the median of that field
  local name=$1
  shift
  for line in "$@"; do field "$line" "$name"; done | sort -g | awk '{v[NR]=$1} END {print (NR%2) ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2}'
}
row() {  # NAME ROUND LINE
  echo "| $1 | $2 | $(field "$3" rps) | $(field "$3" p50_ms) | $(field "$3" p90_ms) | $(field "$3" p99_ms) | $(field "$3" max_ms) | $(field "$3" errors) |"
}
ours_rps=$(median rps "${ours[@]}")
theirs_rps=$(median rps "${theirs[@]}")
ours_p99=$(median p99_ms "${ours[@]}")
theirs_p99=$(median p99_ms "${theirs[@]}")
ratio=$(python3 -c "print(f'{$ours_rps / $theirs_rps:.2f}')")
proxied_rps=$(median rps "${proxied[@]}")
proxied_p99=$(median p99_ms "${proxied[@]}")
proxy_ratio=$(python3 -c "print(f'{$proxied_rps / $theirs_rps:.2f}')")
proxy_gain=$(python3 -c "print(f'{$proxied_rps / $ours_rps:.2f}')")
{
  cat <<MD
# Cached level fetches: motionlodd and nginx

Written by \`bash bench/http/run.sh\` on $(date -u +%Y-%m-%d) ($(nproc) cores, $(uname -srm);
$(dpkg-query -W -f='${Package} ${Version}' libcpp-httplib0.11 2>/dev/null), $(nginx -v 2>&1 | sed 's/.*: //'),
wrk $(dpkg-query -W -f='${Version}' wrk)). Both servers, wrk and the kernel share the machine,
with whatever else runs on it (load average before the run: ${load}).

One level file of the sample character (px=120: ${bytes} bytes), fetched over loopback by
\`wrk -t${wrk_threads} -c${connections} -d${duration} --latency -s bench/http/report.lua URL\`,
${rounds} rounds alternating the servers: motionlodd serving \`/v1/levels/{sha256}\` from its
memory cache (access log: ${access_log}), nginx serving the same bytes as a static file
(\`worker_processes auto\`, sendfile, no access log), and "proxy": nginx with
\`deploy/nginx/motionlod.conf\` in front of motionlodd, the level in its cache.

| server | round | requests/s | p50 ms | p90 ms | p99 ms | max ms | errors |
|---|---:|---:|---:|---:|---:|---:|---:|
MD
  for r in $(seq "$rounds"); do row motionlodd "$r" "${ours[$((r - 1))]}"; done
  for r in $(seq "$rounds"); do row nginx "$r" "${theirs[$((r - 1))]}"; done
  for r in $(seq "$rounds"); do row proxy "$r" "${proxied[$((r - 1))]}"; done
  cat <<MD

Medians: motionlodd ${ours_rps} requests/s (p99 ${ours_p99} ms), nginx ${theirs_rps} requests/s
(p99 ${theirs_p99} ms): motionlodd reaches **${ratio}** of nginx's throughput (target: at
least 0.5, with p99 under 20 ms). Through the proxy ${proxied_rps} requests/s (p99
${proxied_p99} ms): **${proxy_ratio}** of static nginx (target: at least 0.9), ${proxy_gain}x
motionlodd alone.

The ratio depends on the machine's load: with more runnable threads than cores, the
kernel shares CPU time per thread, and motionlodd's 64 busy connection threads then get
more of it than nginx's 2 workers. On a quiet machine the same code may give a lower ratio
than on a loaded one; compare runs only at similar load averages (above).
MD
} >bench/http/RESULTS.md
cat bench/http/RESULTS.md
