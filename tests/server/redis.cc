#include "tests/server/redis.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include "tests/server/daemon.h"
#include "tests/server/loopback.h"

namespace motionlod::server::testing {
namespace {

constexpr const char* kBinary = "/usr/bin/redis-server";

}  // namespace

bool Redis::Installed() { return ::access(kBinary, X_OK) == 0; }

Redis::~Redis() { Kill(); }

void Redis::Kill() {
  if (pid_ <= 0) return;
  ::kill(pid_, SIGKILL);
  int status = 0;
  ::waitpid(pid_, &status, 0);
  pid_ = -1;
}

bool Redis::Start() {
  std::filesystem::create_directories(dir_);
  if (port_ == 0) port_ = FreePort();
  const std::string port = std::to_string(port_);
  const std::string dir = dir_.string();
  const std::string log = (dir_ / "redis.log").string();
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl(kBinary, kBinary, "--port", port.c_str(), "--bind", "127.0.0.1", "--dir", dir.c_str(),
            "--appendonly", "yes", "--appendfsync", "always", "--save", "", "--logfile",
            log.c_str(), "--daemonize", "no", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  if (pid < 0) return false;
  pid_ = pid;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < deadline) {
    if (Accepts(port_)) return true;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  error = "redis-server did not start: " + ReadFile(log);
  return false;
}

}  // namespace motionlod::server::testing
