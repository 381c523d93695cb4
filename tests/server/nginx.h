// A real nginx in front of a test daemon: deploy/nginx/motionlod.conf, its listen address
// and upstream replaced by loopback ports and its cache directory by one of the test's,
// under a main config of the test's own (pid, logs and temporary files in the test's
// directory). The binary is Debian's
// (nginx-light, installed by scripts/setup.sh).
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <string>
#include <vector>

namespace motionlod::server::testing {

class Nginx {
 public:
  explicit Nginx(std::filesystem::path dir) : dir_(std::move(dir)) {}
  ~Nginx();
  Nginx(const Nginx&) = delete;
  Nginx& operator=(const Nginx&) = delete;

  // True when an nginx binary is installed.
  static bool Installed();
  // Starts nginx proxying to 127.0.0.1 at `daemon_ports` (round-robin) on a free loopback
  // port; false (with nginx's error log in `error`) when it did not accept connections
  // within 10 s.
  bool Start(const std::vector<int>& daemon_ports);
  bool Start(int daemon_port) { return Start(std::vector<int>{daemon_port}); }
  int port() const { return port_; }
  std::string error;

 private:
  std::filesystem::path dir_;
  pid_t pid_ = -1;
  int port_ = 0;
};

}  // namespace motionlod::server::testing
