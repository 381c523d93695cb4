#include "tests/server/redis.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>
#include <vector>

#include "server/redis_client.h"
#include "tests/server/daemon.h"
#include "tests/server/loopback.h"

namespace motionlod::server::testing {
namespace {

constexpr const char* kRedisBinary = "/usr/bin/redis-server";

}  // namespace

bool Redis::Installed() { return ::access(kRedisBinary, X_OK) == 0; }

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
  // Built before the fork: the child of a threaded process must not allocate.
  std::vector<const char*> argv = {
      kRedisBinary, "--port",       port.c_str(), "--bind",        "127.0.0.1", "--dir",
      dir.c_str(),  "--appendonly", "yes",        "--appendfsync", "always",    "--save",
      "",           "--logfile",    log.c_str(),  "--daemonize",   "no"};
  if (!password_.empty()) argv.insert(argv.end(), {"--requirepass", password_.c_str()});
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execv(kRedisBinary, const_cast<char* const*>(argv.data()));
    ::_exit(127);
  }
  if (pid < 0) return false;
  pid_ = pid;
  if (WaitUntilAccepting(pid_, port_)) {
    // Accepting is not answering: a restart loads the append-only file first (LOADING).
    RedisConnection connection(*ParseRedisUrl(url()), 1.0);
    for (int attempt = 0; attempt < 500; ++attempt) {
      if (connection.Command({"PING"}).ok()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  error = "redis-server did not start: " + ReadFile(log);
  return false;
}

}  // namespace motionlod::server::testing
