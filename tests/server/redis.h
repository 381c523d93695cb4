// A real redis-server for tests, on a free loopback port, with its data (an append-only
// file fsynced at every write, as docker/compose.yaml runs it) in the test's directory,
// so that a kill and a restart on the same port find every acknowledged write. The
// binary is Debian's (redis-server, installed by scripts/setup.sh).
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <string>

namespace motionlod::server::testing {

class Redis {
 public:
  // With a `password`, Redis requires it (requirepass) and url() carries it.
  explicit Redis(std::filesystem::path dir, std::string password = "")
      : dir_(std::move(dir)), password_(std::move(password)) {}
  ~Redis();
  Redis(const Redis&) = delete;
  Redis& operator=(const Redis&) = delete;

  static bool Installed();
  // Starts redis-server (the first time on a free port, then on the same one); false
  // (with its log in `error`) when it did not accept connections within 10 s.
  bool Start();
  // SIGKILL, and waits for the exit.
  void Kill();
  int port() const { return port_; }
  std::string url() const {
    return "redis://" + (password_.empty() ? "" : ":" + password_ + "@") +
           "127.0.0.1:" + std::to_string(port_);
  }
  std::string error;

 private:
  std::filesystem::path dir_;
  std::string password_;
  pid_t pid_ = -1;
  int port_ = 0;
};

}  // namespace motionlod::server::testing
