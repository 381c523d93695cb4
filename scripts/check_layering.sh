#!/usr/bin/env bash
# Fails when a layer includes what STYLE.md keeps out of it (the arrows of the layers):
#   base      the standard library only: what every layer shares
#   core      base, Eigen and meshoptimizer (core/simplify_mesh.cc alone); reads no environment. Its public headers (core/*.h) and
#             references (core/reference/) never include the private core/internal/
#   proto     base, JSON and xxHash: no Eigen, no core
#   io        core and base, Assimp behind one file; starts no thread (takes a PieceRunner)
#   pipeline  core, io, proto and base, and the thread pool
#   tools     the pipeline and below; server: the same and HTTP
#   client    proto and base only
set -uo pipefail
cd "$(dirname "$0")/.."
status=0
forbid() {  # forbid DIR REGEX WHY
  local hits
  hits=$(grep -REn --include='*.h' --include='*.cc' --exclude-dir=node_modules \
    "^#include [<\"]($2)" "$1" 2>/dev/null)
  if [ -n "$hits" ]; then
    echo "layering: $1 must not include $3:"
    echo "$hits"
    status=1
  fi
}
# only_in FILE DIRS REGEX WHAT: REGEX may be included by FILE alone within DIRS.
only_in() {
  local found
  found=$(grep -RlE --include='*.h' --include='*.cc' --exclude-dir=node_modules \
    "^#include [<\"]($3)" $2 2>/dev/null | sort | tr '\n' ' ')
  if [ -n "$found" ] && [ "$found" != "$1 " ]; then
    echo "layering: only $1 may include $4, found: $found"
    status=1
  fi
}
higher='core/|io/|proto/|pipeline/|tools/|server/|client/'
forbid base "Eigen|spdlog|nlohmann|httplib|assimp|xxhash|$higher" \
  "anything but the standard library and base/"
forbid core 'iostream|fstream|cstdio|stdio\.h|filesystem|thread|mutex|future|spdlog|nlohmann|httplib|assimp|xxhash|io/|proto/|pipeline/|tools/|server/|client/' \
  "I/O, threads, logging, JSON, HTTP, Assimp or a higher layer"
forbid proto 'Eigen|core/|io/|pipeline/|tools/|server/|client/|spdlog|httplib|assimp' \
  "Eigen, the core, io, a higher layer, logging, HTTP or Assimp"
forbid io 'thread|future|condition_variable|spdlog|httplib|pipeline/|tools/|server/|client/|proto/|core/internal/' \
  "threads (it takes a PieceRunner), logging, HTTP, a higher layer or the core's internals"
forbid pipeline 'spdlog|httplib|tools/|server/|client/|core/internal/' \
  "logging, HTTP, a higher layer or the core's internals"
forbid tools 'httplib|server/|client/|core/internal/' "HTTP, the server, the client or the core's internals"
forbid server 'tools/|client/|core/internal/' "the tools, the client or the core's internals"
only_in core/simplify_mesh.cc 'base core io proto pipeline tools server client' 'meshoptimizer' 'meshoptimizer'
# The core's public surface: what the pipeline calls, not how the core does it.
for header in core/*.h core/reference/*.h; do
  if grep -qE '^#include [<"]core/internal/' "$header"; then
    echo "layering: the public header $header must not include core/internal/"
    status=1
  fi
done
if grep -RnE --include='*.h' --include='*.cc' 'getenv|environ\b' core; then
  echo "layering: the core reads no environment (the programs pass settings down)"
  status=1
fi
# The thin client needs proto/ and base/ only.
forbid client 'Eigen|core/|io/|pipeline/|tools/|server/|spdlog|assimp' \
  "Eigen, the core, io, the pipeline, the tools, the server, logging or Assimp"
# Third-party headers stay behind one file each.
assimp_files=$(grep -RlE '^#include [<"]assimp/' io | sort | tr '\n' ' ')
if [ "$assimp_files" != "io/assimp_scene.cc " ]; then
  echo "layering: only io/assimp_scene.cc may include Assimp, found: $assimp_files"
  status=1
fi
only_in server/http_server.cc server 'httplib\.h' "httplib.h in the server"
only_in client/http_connection.cc client 'httplib\.h' "httplib.h in the client"
only_in proto/checksum.cc "base core proto io pipeline tools server client" 'xxhash\.h' "xxhash.h"
[ $status -eq 0 ] && echo "layering: ok"
exit $status
