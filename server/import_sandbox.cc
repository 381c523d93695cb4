#include "server/import_sandbox.h"

#include <fcntl.h>
#include <poll.h>
#include <sched.h>
#include <seccomp.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "io/asset_wire.h"
#include "server/http.h"

namespace motionlod::server {
namespace {

constexpr size_t kMaxStderrBytes = 16 << 10;  // kept for the log and for diagnosis
constexpr const char* kWorkerName = "motionlod-import-worker";
constexpr const char* kWorkerInSandbox = "/motionlod-import-worker";

// Every namespace new (so no network at all), no capability, a new session, no
// environment, and of the host's files only /usr, read-only (the worker's libraries);
// a /proc and /dev of the sandbox's own. The worker binary is bound in after these.
// clang-format off
constexpr const char* kBubblewrapOptions[] = {
    "--unshare-all", "--die-with-parent", "--new-session", "--clearenv",
    "--cap-drop", "ALL", "--ro-bind", "/usr", "/usr",
    "--symlink", "usr/lib", "/lib", "--symlink", "usr/lib64", "/lib64",
    "--symlink", "usr/bin", "/bin", "--proc", "/proc", "--dev", "/dev", "--chdir", "/"};
// clang-format on

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
constexpr bool kAddressSanitizer = __has_feature(address_sanitizer);
#else
constexpr bool kAddressSanitizer = false;
#endif
// AddressSanitizer reserves terabytes of shadow address space: RLIMIT_AS cannot apply.
constexpr bool kAddressSpaceLimitWorks = !kAddressSanitizer;

// The descriptor on which bubblewrap reads the worker's seccomp filter (--seccomp).
constexpr int kSeccompFilterFd = 3;
constexpr const char* kSeccompFilterFdText = "3";

// System calls the worker never makes (it reads stdin, runs Assimp in memory and writes
// stdout), each a way out of or around the sandbox for a compromised importer: the
// kernel's larger attack surfaces (bpf, perf, io_uring, userfaultfd, keyrings, modules),
// other processes (ptrace, process_vm_*), namespaces, mounts and file handles, the
// network, and the machine's state (reboot, clock, swap, I/O ports). They fail with EPERM;
// everything else is allowed, so Assimp, zlib and the C++ runtime run unchanged.
// clang-format off
constexpr int kDeniedSyscalls[] = {
    SCMP_SYS(ptrace), SCMP_SYS(process_vm_readv), SCMP_SYS(process_vm_writev),
    SCMP_SYS(mount), SCMP_SYS(umount2), SCMP_SYS(pivot_root), SCMP_SYS(chroot),
    SCMP_SYS(unshare), SCMP_SYS(setns),
    SCMP_SYS(keyctl), SCMP_SYS(add_key), SCMP_SYS(request_key),
    SCMP_SYS(bpf), SCMP_SYS(perf_event_open), SCMP_SYS(userfaultfd),
    SCMP_SYS(kexec_load), SCMP_SYS(kexec_file_load),
    SCMP_SYS(init_module), SCMP_SYS(finit_module), SCMP_SYS(delete_module),
    SCMP_SYS(open_by_handle_at), SCMP_SYS(name_to_handle_at),
    SCMP_SYS(io_uring_setup), SCMP_SYS(io_uring_enter), SCMP_SYS(io_uring_register),
    SCMP_SYS(socket), SCMP_SYS(socketpair),
    SCMP_SYS(reboot), SCMP_SYS(swapon), SCMP_SYS(swapoff), SCMP_SYS(acct),
    SCMP_SYS(quotactl), SCMP_SYS(settimeofday), SCMP_SYS(clock_settime),
    SCMP_SYS(clock_adjtime), SCMP_SYS(adjtimex), SCMP_SYS(syslog), SCMP_SYS(vhangup),
    SCMP_SYS(lookup_dcookie), SCMP_SYS(iopl), SCMP_SYS(ioperm)};
// clang-format on
// clone() flags that make a new namespace (the low byte of clone's flags is the exit
// signal, so CLONE_NEWTIME, which exists only for clone3 and unshare, is not among them).
constexpr scmp_datum_t kNamespaceCloneFlags[] = {CLONE_NEWNS,  CLONE_NEWCGROUP, CLONE_NEWUTS,
                                                 CLONE_NEWIPC, CLONE_NEWUSER,   CLONE_NEWPID,
                                                 CLONE_NEWNET};
// personality(2)'s query, which the C runtime's sanitizers make at start-up.
constexpr scmp_datum_t kPersonalityQuery = 0xffffffff;

// Builds the worker's seccomp filter (default: allow; kDeniedSyscalls, clone() into a new
// namespace and personality() changes fail with EPERM; clone3, whose flags a filter cannot
// read, fails with ENOSYS so that the C library falls back to clone) and writes it, as BPF,
// to a new memory file read from its start. Returns the descriptor (close-on-exec).
StatusOr<int> ExportSeccompFilter() {
  const auto fail = [](const std::string& step, int error) -> Status {
    return InvalidArgument("the importer's seccomp filter could not be built (" + step +
                           "): " + std::strerror(error));
  };
  scmp_filter_ctx filter = seccomp_init(SCMP_ACT_ALLOW);
  if (filter == nullptr) return fail("seccomp_init", ENOMEM);
  const uint32_t eperm = SCMP_ACT_ERRNO(EPERM);
  int result = 0;
  for (int syscall : kDeniedSyscalls) {
    // LeakSanitizer stops the worker's threads with ptrace to scan them at exit: a
    // sanitizer build (the test suite's) leaves ptrace allowed.
    if (kAddressSanitizer && syscall == SCMP_SYS(ptrace)) continue;
    if (result == 0) result = seccomp_rule_add_array(filter, eperm, syscall, 0, nullptr);
  }
  for (scmp_datum_t flag : kNamespaceCloneFlags) {
    const scmp_arg_cmp makes_namespace = {0, SCMP_CMP_MASKED_EQ, flag, flag};
    if (result == 0)
      result = seccomp_rule_add_array(filter, eperm, SCMP_SYS(clone), 1, &makes_namespace);
  }
  const scmp_arg_cmp changes_personality = {0, SCMP_CMP_NE, kPersonalityQuery, 0};
  if (result == 0)
    result = seccomp_rule_add_array(filter, eperm, SCMP_SYS(personality), 1, &changes_personality);
  if (result == 0)
    result = seccomp_rule_add_array(filter, SCMP_ACT_ERRNO(ENOSYS), SCMP_SYS(clone3), 0, nullptr);
  if (result != 0) {
    seccomp_release(filter);
    return fail("seccomp_rule_add", -result);
  }
  const int fd = memfd_create("motionlod-import-seccomp", MFD_CLOEXEC);
  if (fd < 0) {
    const int saved = errno;
    seccomp_release(filter);
    return fail("memfd_create", saved);
  }
  result = seccomp_export_bpf(filter, fd);
  seccomp_release(filter);
  if (result != 0 || lseek(fd, 0, SEEK_SET) != 0) {
    const int saved = result != 0 ? -result : errno;
    close(fd);
    return fail("seccomp_export_bpf", saved);
  }
  return fd;
}


// The guardian's bubblewrap, for its signal handler (one per guardian process, which
// runs nothing else: the variable is never shared between threads).
volatile pid_t guarded_sandbox = 0;

void KillSandboxAndExit(int) {
  if (guarded_sandbox > 0) kill(guarded_sandbox, SIGKILL);
  _exit(128 + SIGKILL);
}

// Runs in the forked child: execs `argv` through a guardian process. bubblewrap clears the
// parent-death signal while it sets the sandbox up (it changes its credentials), so a
// daemon killed in those milliseconds would leave bubblewrap and the worker running. The
// guardian keeps a catchable parent-death signal, kills bubblewrap when the daemon dies,
// and otherwise ends as bubblewrap ended (same exit code or signal), so the daemon reads
// the worker's fate as before and wait4 sums every process's CPU time.
[[noreturn]] void ExecGuarded(char* const argv[], char* const environment[], pid_t daemon_pid) {
  struct sigaction on_death = {};
  on_death.sa_handler = KillSandboxAndExit;
  sigaction(SIGTERM, &on_death, nullptr);
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  if (getppid() != daemon_pid) _exit(127);
  const pid_t guardian = getpid();
  const pid_t sandbox = fork();
  if (sandbox == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != guardian) _exit(127);
    execve(argv[0], argv, environment);
    _exit(127);
  }
  if (sandbox < 0) _exit(127);
  guarded_sandbox = sandbox;
  int status = 0;
  while (waitpid(sandbox, &status, 0) < 0) {
    if (errno != EINTR) _exit(127);
  }
  if (WIFEXITED(status)) _exit(WEXITSTATUS(status));
  const int signal_number = WTERMSIG(status);
  signal(signal_number, SIG_DFL);
  kill(getpid(), signal_number);
  _exit(128 + signal_number);
}

std::string FindOnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path != nullptr && *path != '\0' ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const std::filesystem::path candidate = std::filesystem::path(dir) / name;
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return "";
}

std::string DefaultWorkerPath() {
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  if (error) return kWorkerName;
  return (self.parent_path() / kWorkerName).string();
}

std::string SignalName(int signal) {
  const char* abbreviation = sigabbrev_np(signal);
  return abbreviation != nullptr ? std::string("SIG") + abbreviation
                                 : "signal " + std::to_string(signal);
}

void CloseFd(int& fd) {
  if (fd >= 0) close(fd);
  fd = -1;
}

struct Pipe {
  int read = -1, write = -1;
  bool Open() {
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) return false;
    read = fds[0];
    write = fds[1];
    return true;
  }
  void Close() {
    CloseFd(read);
    CloseFd(write);
  }
};

// What became of one worker run.
struct WorkerRun {
  std::string reply;
  std::string stderr_text;
  int wait_status = 0;
  double cpu_seconds = 0;
  bool timed_out = false;
  bool output_too_large = false;
};

std::string Seconds(double seconds) {
  std::ostringstream text;
  text << seconds;
  return text.str();
}

double CpuSeconds(const rusage& usage) {
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

}  // namespace

const char* IsolationName(Isolation isolation) {
  return isolation == Isolation::kBubblewrap ? "bwrap" : "process";
}

ImportSandbox::ImportSandbox(Isolation isolation, std::string worker_path,
                             const ImportLimits& limits)
    : isolation_(isolation), worker_path_(std::move(worker_path)), limits_(limits) {}

StatusOr<std::unique_ptr<ImportSandbox>> ImportSandbox::Create(const std::string& mode,
                                                               const std::string& worker_path,
                                                               const ImportLimits& limits) {
  if (mode != "auto" && mode != "bwrap" && mode != "process") {
    return InvalidArgument("import_isolation must be auto, bwrap or process, got '" + mode + "'");
  }
  std::string worker = worker_path.empty() ? DefaultWorkerPath() : worker_path;
  std::error_code error;
  worker = std::filesystem::absolute(worker, error).string();
  if (access(worker.c_str(), X_OK) != 0) {
    return Unsupported("the import worker '" + worker + "' is not an executable file (build " +
                       kWorkerName + " next to motionlodd, or set import_worker)");
  }
  std::string fallback_reason;
  if (mode != "process") {
    std::unique_ptr<ImportSandbox> sandbox(
        new ImportSandbox(Isolation::kBubblewrap, worker, limits));
    Status probe = FindOnPath("bwrap").empty()
                       ? Unsupported("bwrap (Debian package bubblewrap) is not installed")
                       : sandbox->Probe();
    if (probe.ok()) return sandbox;
    if (mode == "bwrap") {
      return Unsupported("import_isolation = \"bwrap\" but bubblewrap does not work here: " +
                         probe.message());
    }
    fallback_reason = probe.message();
  }
  std::unique_ptr<ImportSandbox> sandbox(new ImportSandbox(Isolation::kProcess, worker, limits));
  sandbox->fallback_reason_ = fallback_reason;
  if (Status probe = sandbox->Probe(); !probe.ok()) {
    return Unsupported("the import worker '" + worker + "' does not run: " + probe.message());
  }
  return sandbox;
}

Status ImportSandbox::Probe() const {
  io::LoadOptions options;
  StatusOr<std::shared_ptr<const io::Asset>> result = Run({}, options, ImportLimits{});
  // The worker answers an empty request with the importer's own refusal.
  if (!result.ok() && result.status().code() == StatusCode::kInvalidArgument &&
      result.status().message() == "no file was given") {
    return Status::Ok();
  }
  return InvalidArgument(result.ok() ? "the probe import returned an asset"
                                     : result.status().message());
}

StatusOr<std::shared_ptr<const io::Asset>> ImportSandbox::Import(
    const std::vector<io::SourceFile>& files, const io::LoadOptions& options) const {
  return Run(files, options, limits_);
}

StatusOr<std::shared_ptr<const io::Asset>> ImportSandbox::Run(
    const std::vector<io::SourceFile>& files, const io::LoadOptions& options,
    const ImportLimits& limits) const {
  const std::string request = io::EncodeImportRequest(files, options);

  // Everything the child needs is built before fork(): after it, only async-signal-safe
  // calls (no allocation: another thread may hold the allocator's lock).
  std::vector<std::string> args;
  StatusOr<int> exported = ExportSeccompFilter();
  if (!exported.ok()) {
    spdlog::error("import worker not started: {}", exported.status().message());
    return exported.status();
  }
  // Under bubblewrap, which applies it last, just before it runs the worker, the filter is
  // read from a descriptor; a plain process installs it itself right before exec.
  int seccomp_filter = *exported;
  std::vector<sock_filter> filter_program;
  if (isolation_ == Isolation::kProcess) {
    const off_t bytes = lseek(seccomp_filter, 0, SEEK_END);
    filter_program.resize(bytes > 0 ? static_cast<size_t>(bytes) / sizeof(sock_filter) : 0);
    const size_t wanted = filter_program.size() * sizeof(sock_filter);
    const bool read_whole = bytes > 0 && pread(seccomp_filter, filter_program.data(), wanted, 0) ==
                                             static_cast<ssize_t>(wanted);
    CloseFd(seccomp_filter);
    seccomp_filter = -1;
    if (!read_whole) {
      const Status status = InvalidArgument(
          "the importer's seccomp filter could not be built (reading the exported program)");
      spdlog::error("import worker not started: {}", status.message());
      return status;
    }
  }
  const sock_fprog filter{static_cast<unsigned short>(filter_program.size()), filter_program.data()};
  if (isolation_ == Isolation::kBubblewrap) {
    args = {FindOnPath("bwrap")};
    args.insert(args.end(), std::begin(kBubblewrapOptions), std::end(kBubblewrapOptions));
    args.insert(args.end(), {"--seccomp", kSeccompFilterFdText, "--ro-bind", worker_path_,
                             kWorkerInSandbox, kWorkerInSandbox});
  } else {
    args = {worker_path_};
  }
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  char* const empty_environment[] = {nullptr};
  const rlim_t cpu_limit = static_cast<rlim_t>(std::ceil(std::max(limits.cpu_seconds, 1.0)));
  const rlimit cpu = {cpu_limit, cpu_limit + 1};  // SIGXCPU first, SIGKILL a second later
  const rlimit memory = {static_cast<rlim_t>(limits.memory_bytes),
                         static_cast<rlim_t>(limits.memory_bytes)};
  const bool limit_memory = kAddressSpaceLimitWorks && limits.memory_bytes > 0;
  const rlimit no_core = {0, 0};
  const pid_t daemon_pid = getpid();

  Pipe in, out, err;
  if (!in.Open() || !out.Open() || !err.Open()) {
    const int saved = errno;
    in.Close();
    out.Close();
    err.Close();
    CloseFd(seccomp_filter);
    return Status(StatusCode::kInternal,
                  std::string("cannot create the import worker's pipes: ") + std::strerror(saved));
  }
  const pid_t pid = fork();
  if (pid == 0) {
    if (dup2(in.read, STDIN_FILENO) < 0 || dup2(out.write, STDOUT_FILENO) < 0 ||
        dup2(err.write, STDERR_FILENO) < 0) {
      _exit(127);
    }
    // bubblewrap reads the filter on a known descriptor, inherited across exec.
    if (seccomp_filter >= 0 &&
        (dup2(seccomp_filter, kSeccompFilterFd) < 0 || fcntl(kSeccompFilterFd, F_SETFD, 0) != 0)) {
      _exit(127);
    }
    // No listening socket, database or blob descriptor leaks in.
    close_range(seccomp_filter >= 0 ? kSeccompFilterFd + 1 : 3, ~0U, 0);
    setpgid(0, 0);
    prctl(PR_SET_PDEATHSIG, SIGKILL);  // a daemon killed mid-import takes its worker along
    if (getppid() != daemon_pid) _exit(127);
    prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0);
    setrlimit(RLIMIT_CPU, &cpu);
    setrlimit(RLIMIT_CORE, &no_core);
    if (limit_memory) setrlimit(RLIMIT_AS, &memory);
    if (isolation_ == Isolation::kBubblewrap) ExecGuarded(argv.data(), empty_environment, daemon_pid);
    if (prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, &filter) != 0) _exit(127);
    execve(argv[0], argv.data(), empty_environment);
    _exit(127);
  }
  const int fork_errno = errno;
  CloseFd(seccomp_filter);
  CloseFd(in.read);
  CloseFd(out.write);
  CloseFd(err.write);
  if (pid < 0) {
    in.Close();
    out.Close();
    err.Close();
    return Status(StatusCode::kInternal,
                  std::string("cannot start the import worker: ") + std::strerror(fork_errno));
  }

  WorkerRun run;
  const auto start = std::chrono::steady_clock::now();
  const auto deadline =
      start + std::chrono::milliseconds(static_cast<int64_t>(limits.wall_seconds * 1000));
  for (int fd : {in.write, out.read, err.read}) fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK);
  size_t written = 0;
  char buffer[1 << 16];
  while (in.write >= 0 || out.read >= 0 || err.read >= 0) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      run.timed_out = true;
      break;
    }
    pollfd fds[3];
    int count = 0;
    if (in.write >= 0) fds[count++] = {in.write, POLLOUT, 0};
    if (out.read >= 0) fds[count++] = {out.read, POLLIN, 0};
    if (err.read >= 0) fds[count++] = {err.read, POLLIN, 0};
    const int ready = poll(fds, static_cast<nfds_t>(count),
                           static_cast<int>(std::min<int64_t>(left.count(), 1000)));
    if (ready < 0 && errno != EINTR) break;
    for (int k = 0; k < count && ready > 0; ++k) {
      if (fds[k].revents == 0) continue;
      if (fds[k].fd == in.write) {
        const ssize_t n = write(in.write, request.data() + written, request.size() - written);
        if (n > 0) written += static_cast<size_t>(n);
        // EPIPE: the worker stopped reading (it failed); its exit status tells why.
        if ((n < 0 && errno != EAGAIN && errno != EINTR) || written == request.size())
          CloseFd(in.write);
        continue;
      }
      const bool is_out = fds[k].fd == out.read;
      const ssize_t n = read(fds[k].fd, buffer, sizeof buffer);
      if (n > 0) {
        std::string& target = is_out ? run.reply : run.stderr_text;
        if (is_out || target.size() < kMaxStderrBytes)
          target.append(buffer, static_cast<size_t>(n));
      } else if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
        CloseFd(is_out ? out.read : err.read);
      }
      if (is_out && run.reply.size() > static_cast<size_t>(limits.output_bytes)) {
        run.output_too_large = true;
        break;
      }
    }
    if (run.output_too_large) break;
  }
  in.Close();
  out.Close();
  err.Close();
  // The worker closed its output: it exits now, unless it hangs on; the deadline holds.
  rusage usage{};
  pid_t waited = 0;
  while (!run.timed_out && !run.output_too_large &&
         (waited = wait4(pid, &run.wait_status, WNOHANG, &usage)) == 0) {
    if (std::chrono::steady_clock::now() >= deadline) {
      run.timed_out = true;
      break;
    }
    usleep(2000);
  }
  if (run.timed_out || run.output_too_large || waited <= 0) {
    kill(-pid, SIGKILL);
    kill(pid, SIGKILL);
    while (wait4(pid, &run.wait_status, 0, &usage) < 0 && errno == EINTR) {
    }
  }
  run.cpu_seconds = CpuSeconds(usage);

  const auto failed = [&](const std::string& why) {
    spdlog::warn(
        "import worker {}: {}{}", pid, why,
        run.stderr_text.empty() ? "" : "; its stderr: " + http::Printable(run.stderr_text, 2000));
    return InvalidArgument("the importer " + why);
  };
  const std::string out_of_memory = "ran out of memory (the address space limit is " +
                                    std::to_string(limits.memory_bytes) + " bytes)";
  if (run.timed_out) {
    return failed("took longer than " + Seconds(limits.wall_seconds) +
                  " s (the wall-clock limit) and was stopped");
  }
  if (run.output_too_large) {
    return failed("produced a result larger than " + std::to_string(limits.output_bytes) +
                  " bytes (the output limit) and was stopped");
  }
  // An allocation failure outside Assimp's own handlers ends the worker (status 3, or an
  // abort when it struck where no exception may pass).
  const bool said_out_of_memory = run.stderr_text.find("bad_alloc") != std::string::npos ||
                                  run.stderr_text.find("out of memory") != std::string::npos;
  const int code = WIFEXITED(run.wait_status) ? WEXITSTATUS(run.wait_status) : -1;
  // bubblewrap exits with 128 + N when the worker it runs dies of signal N.
  const int signal = WIFSIGNALED(run.wait_status) ? WTERMSIG(run.wait_status)
                     : isolation_ == Isolation::kBubblewrap && code > 128 && code < 128 + 65
                         ? code - 128
                         : 0;
  if (signal != 0) {
    if (signal == SIGXCPU || (signal == SIGKILL && run.cpu_seconds >= cpu_limit)) {
      return failed("used more than " + std::to_string(cpu_limit) +
                    " s of CPU time (the CPU limit) and was stopped");
    }
    if (said_out_of_memory) return failed(out_of_memory);
    return failed("crashed (" + SignalName(signal) + ") on this upload");
  }
  if (code == io::kWorkerExitOutOfMemory || (code != 0 && said_out_of_memory)) {
    return failed(out_of_memory);
  }
  if (code != 0) return failed("failed with exit status " + std::to_string(code));
  StatusOr<std::shared_ptr<const io::Asset>> asset = io::DecodeImportReply(run.reply);
  if (asset.ok()) return asset;
  if (asset.status().message().rfind("malformed import reply", 0) == 0) {
    return failed("sent back a malformed result: " + asset.status().message());
  }
  // Assimp catches std::bad_alloc itself and reports it as a read error.
  if (asset.status().message().find("bad_alloc") != std::string::npos) return failed(out_of_memory);
  return asset;
}

}  // namespace motionlod::server
