// Runs the importer on uploaded files in a separate process (motionlod-import-worker),
// never in the daemon: Assimp parses hostile bytes, and a crash, a hang or a runaway
// allocation there must cost one request a 422, not the daemon.
//
// Each import forks a fresh worker with resource limits (setrlimit: address space, CPU
// time, no core file; the daemon kills it past the wall-clock limit or when its reply
// outgrows the output limit) and, with Isolation::kBubblewrap, inside bubblewrap: new
// user, network, PID, IPC, UTS and mount namespaces (no network at all), all
// capabilities dropped, and a file system of /usr read-only, a private /proc and /dev and
// the worker binary: no host file (/etc, the data directory, the upload's neighbours) is
// visible. Bubblewrap also installs a seccomp filter (libseccomp) under which the system
// calls the worker never needs fail with EPERM (ptrace, mount, unshare, bpf, io_uring,
// socket and more: the list is in import_sandbox.cc and docs/RELIABILITY.md); a filter
// that cannot be built fails the import (and so, at start-up, the bubblewrap probe): no
// worker runs in bubblewrap without it. The files
// travel on the worker's stdin and the result on its stdout, in the checked format of
// io/asset_wire.h; the reply is decoded and validated as hostile.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/status.h"
#include "io/asset.h"

namespace motionlod::server {

enum class Isolation {
  kBubblewrap,  // namespaces via bwrap, plus the limits
  kProcess,     // a plain child process with the limits only
};
const char* IsolationName(Isolation isolation);

struct ImportLimits {
  int64_t memory_bytes = int64_t{4} << 30;    // RLIMIT_AS of the worker; 0: none
  double cpu_seconds = 120;                   // RLIMIT_CPU (rounded up to whole seconds)
  double wall_seconds = 180;                  // killed after this long
  int64_t output_bytes = int64_t{512} << 20;  // largest reply read back
};

class ImportSandbox {
 public:
  // `mode` is "auto" (bubblewrap when a probe import through it works, else a plain
  // process, with a warning), "bwrap" (bubblewrap or fail) or "process". `worker_path`
  // "" means motionlod-import-worker next to the running executable. Probes the worker
  // once: errors (Unsupported, InvalidArgument) say why it cannot run.
  static StatusOr<std::unique_ptr<ImportSandbox>> Create(const std::string& mode,
                                                         const std::string& worker_path,
                                                         const ImportLimits& limits);

  Isolation isolation() const { return isolation_; }
  const ImportLimits& limits() const { return limits_; }
  // Why a weaker isolation was chosen in "auto" mode; "" otherwise.
  const std::string& fallback_reason() const { return fallback_reason_; }

  // Imports `files` (files[0] the main file) in a fresh worker. Errors: the importer's own
  // (InvalidArgument, NotFound, Unsupported, DataLoss); InvalidArgument naming the reason
  // when the worker crashed, ran past a limit or sent a malformed reply; Internal when
  // no worker could be started.
  StatusOr<std::shared_ptr<const io::Asset>> Import(const std::vector<io::SourceFile>& files,
                                                    const io::LoadOptions& options) const;

 private:
  ImportSandbox(Isolation isolation, std::string worker_path, const ImportLimits& limits);
  // One worker run under `limits`.
  StatusOr<std::shared_ptr<const io::Asset>> Run(const std::vector<io::SourceFile>& files,
                                                 const io::LoadOptions& options,
                                                 const ImportLimits& limits) const;
  // The probe: an import of no file, under the default limits (the configured ones may
  // be set too low for any real work), must come back as the importer's "no file" error.
  Status Probe() const;

  Isolation isolation_;
  std::string worker_path_;
  ImportLimits limits_;
  std::string fallback_reason_;
};

}  // namespace motionlod::server
