// motionlod-import-worker: imports one upload in a process of its own, so that whatever
// Assimp does with hostile bytes (crash, hang, runaway allocation) happens outside the
// daemon. Reads one import request (io/asset_wire.h) on stdin, runs io::LoadAsset on
// the files it holds and writes one reply (the asset or the importer's error) on stdout.
// The daemon starts it inside its sandbox with resource limits (server/import_sandbox.h);
// it opens no file and needs nothing but stdin and stdout.
//
// Exit status: 0 a reply was written, else one of io::kWorkerExit*.
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <new>
#include <string>

#include "io/asset.h"
#include "io/asset_wire.h"

namespace {

bool ReadAll(int fd, std::string& out) {
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = read(fd, buffer, sizeof buffer);
    if (n == 0) return true;
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    out.append(buffer, static_cast<size_t>(n));
  }
}

bool WriteAll(int fd, const std::string& bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    done += static_cast<size_t>(n);
  }
  return true;
}

int Run() {
  std::string request_bytes;
  if (!ReadAll(STDIN_FILENO, request_bytes)) {
    std::fputs("motionlod-import-worker: cannot read the request\n", stderr);
    return motionlod::io::kWorkerExitBadRequest;
  }
  auto request = motionlod::io::DecodeImportRequest(request_bytes);
  if (!request.ok()) {
    std::fprintf(stderr, "motionlod-import-worker: %s\n", request.status().ToString().c_str());
    return motionlod::io::kWorkerExitBadRequest;
  }
  request_bytes = std::string();  // the files live on in `request` only
  const auto asset = motionlod::io::LoadAsset(std::move(request->files), request->options);
  return WriteAll(STDOUT_FILENO, motionlod::io::EncodeImportReply(asset))
             ? 0
             : motionlod::io::kWorkerExitWriteFailed;
}

}  // namespace

// In sanitizer builds: no leak check at exit. A worker is one import and an exit, which
// frees everything, and Assimp's error paths leak (a truncated BVH: 1144 bytes), which
// would turn the importer's clear message into an exit status. Leaks in our own import
// code are caught in-process by the io tests.
extern "C" const char* __lsan_default_options() { return "detect_leaks=0"; }

int main() {
  try {
    return Run();
  } catch (const std::bad_alloc&) {
    std::fputs("motionlod-import-worker: out of memory\n", stderr);
    return motionlod::io::kWorkerExitOutOfMemory;
  }
}
