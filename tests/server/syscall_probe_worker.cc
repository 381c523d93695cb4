// A stand-in for motionlod-import-worker that tells which system calls it may make, for the
// seccomp filter's test (import_sandbox_test.cc). It speaks the worker's protocol
// (io/asset_wire.h): an empty request gets the importer's own answer, so that the sandbox's
// probe accepts it; otherwise each file's name is a system call to attempt, and the reply
// is an error whose message lists the outcomes in order, "name=ok" or "name=ERRNO"
// ("ptrace=EPERM socket=ok").
#include <linux/io_uring.h>
#include <linux/perf_event.h>
#include <sched.h>
#include <signal.h>
#include <sys/personality.h>
#include <sys/ptrace.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <iostream>
#include <iterator>
#include <string>

#include "io/asset.h"
#include "io/asset_wire.h"

namespace {

// Ends a child that a successful clone or fork made.
long ReapChild(long pid) {
  if (pid == 0) _exit(0);
  if (pid > 0) waitpid(static_cast<pid_t>(pid), nullptr, 0);
  return pid;
}

// The raw result of the named system call (negative with errno set on failure).
long Attempt(const std::string& name) {
  if (name == "ptrace") return ptrace(PTRACE_TRACEME, 0, nullptr, nullptr);
  if (name == "socket") {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd >= 0) close(fd);
    return fd;
  }
  if (name == "perf_event_open") {
    perf_event_attr attributes = {};
    attributes.type = PERF_TYPE_SOFTWARE;
    attributes.size = sizeof attributes;
    attributes.config = PERF_COUNT_SW_CPU_CLOCK;
    attributes.exclude_kernel = 1;
    const long fd = syscall(SYS_perf_event_open, &attributes, 0, -1, -1, 0);
    if (fd >= 0) close(static_cast<int>(fd));
    return fd;
  }
  if (name == "io_uring_setup") {
    io_uring_params parameters = {};
    const long fd = syscall(SYS_io_uring_setup, 1, &parameters);
    if (fd >= 0) close(static_cast<int>(fd));
    return fd;
  }
  if (name == "unshare") return unshare(CLONE_NEWUSER);
  if (name == "clone_newuser")
    return ReapChild(syscall(SYS_clone, CLONE_NEWUSER | SIGCHLD, 0, 0, 0, 0));
  if (name == "clone3") return syscall(SYS_clone3, nullptr, 0);
  if (name == "fork") return ReapChild(fork());
  if (name == "personality") return personality(ADDR_NO_RANDOMIZE);
  if (name == "personality_query") return personality(0xffffffff);
  errno = EINVAL;
  return -1;
}

}  // namespace

int main() {
  const std::string request_bytes(std::istreambuf_iterator<char>(std::cin), {});
  auto request = motionlod::io::DecodeImportRequest(request_bytes);
  if (!request.ok()) return motionlod::io::kWorkerExitBadRequest;
  if (request->files.empty()) {
    std::cout << motionlod::io::EncodeImportReply(motionlod::io::LoadAsset({}, request->options));
    return 0;
  }
  std::string outcomes;
  for (const motionlod::io::SourceFile& file : request->files) {
    const long result = Attempt(file.name);
    const char* error = result < 0 ? strerrorname_np(errno) : nullptr;
    outcomes += (outcomes.empty() ? "" : " ") + file.name + "=" + (error != nullptr ? error : "ok");
  }
  std::cout << motionlod::io::EncodeImportReply(motionlod::InvalidArgument(outcomes));
  return std::cout.flush() ? 0 : motionlod::io::kWorkerExitWriteFailed;
}
