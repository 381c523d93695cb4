#!/usr/bin/env bash
# Fails when a layer includes what STYLE.md keeps out of it (the arrows of the layers).
set -uo pipefail
cd "$(dirname "$0")/.."
status=0
forbid() {  # forbid DIR REGEX WHY
  local hits
  hits=$(grep -REn --include='*.h' --include='*.cc' "^#include [<\"]($2)" "$1" 2>/dev/null)
  if [ -n "$hits" ]; then
    echo "layering: $1 must not include $3:"
    echo "$hits"
    status=1
  fi
}
forbid core 'iostream|fstream|cstdio|stdio\.h|filesystem|thread|mutex|future|spdlog|nlohmann|httplib|assimp|io/|proto/|pipeline/|tools/|server/|client/' \
  "I/O, threads, logging, JSON, HTTP, Assimp or a higher layer"
forbid base 'Eigen|spdlog|nlohmann|httplib|assimp|core/|io/|proto/' "anything but the standard library"
forbid proto 'Eigen|core/|io/|pipeline/|spdlog|httplib|assimp' "Eigen, core, io, logging, HTTP or Assimp"
forbid io 'spdlog|httplib|pipeline/|tools/|server/|client/|proto/' "logging, HTTP or a higher layer"
forbid pipeline 'spdlog|httplib|tools/|server/|client/' "logging, HTTP or a higher layer"
# Assimp stays behind one file of io.
assimp_files=$(grep -RlE '^#include [<"]assimp/' io | sort | tr '\n' ' ')
if [ "$assimp_files" != "io/assimp_scene.cc " ]; then
  echo "layering: only io/assimp_scene.cc may include Assimp, found: $assimp_files"
  status=1
fi
# cpp-httplib stays behind one file of the server.
httplib_files=$(grep -RlE '^#include [<"]httplib\.h' server 2>/dev/null | sort | tr '\n' ' ')
if [ -n "$httplib_files" ] && [ "$httplib_files" != "server/http_server.cc " ]; then
  echo "layering: only server/http_server.cc may include httplib.h, found: $httplib_files"
  status=1
fi
forbid server 'tools/|client/' "the tools or the client"
# The thin client needs proto/ and base/ only, and keeps cpp-httplib behind one file.
forbid client 'Eigen|core/|io/|pipeline/|tools/|server/|spdlog|assimp' \
  "Eigen, the core, io, the pipeline, the tools, the server, logging or Assimp"
client_httplib_files=$(grep -RlE '^#include [<"]httplib\.h' client 2>/dev/null | sort | tr '\n' ' ')
if [ -n "$client_httplib_files" ] && [ "$client_httplib_files" != "client/http_connection.cc " ]; then
  echo "layering: only client/http_connection.cc may include httplib.h, found: $client_httplib_files"
  status=1
fi
[ $status -eq 0 ] && echo "layering: ok"
exit $status
