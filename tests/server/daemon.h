// A real motionlodd process for tests: fork/exec of the built binary on an ephemeral
// loopback port (--port 0) with its own data directory; the port is read from the
// "listening on http://HOST:PORT" line it prints. Its log goes to <dir>/daemon.log.
#pragma once

#include <httplib.h>
#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace motionlod::server::testing {

class Daemon {
 public:
  // `dir` holds data/ and daemon.log; kept across Start() calls so a restart finds
  // the same data, and removed with the Daemon unless the test failed.
  explicit Daemon(std::filesystem::path dir) : dir_(std::move(dir)) {}
  ~Daemon();

  // Starts motionlodd --port 0 --data-dir DIR/data plus `args`, with `env` added to the
  // environment ("NAME=value"). False (with the log in `error`) when it did not print
  // its address within 20 s.
  bool Start(const std::vector<std::string>& args = {}, const std::vector<std::string>& env = {});
  // Sends `signal` and waits for the exit; returns the exit code (128 + signal when
  // killed), -1 on timeout.
  int Stop(int signal, std::chrono::seconds timeout = std::chrono::seconds(30));
  bool running() const { return pid_ > 0; }

  // The next line the daemon prints on stdout (without its newline), or false at the
  // deadline or the end of its output.
  bool ReadStdoutLine(std::string& line, std::chrono::steady_clock::time_point deadline);

  int port() const { return port_; }
  pid_t pid() const { return pid_; }
  std::unique_ptr<httplib::Client> Client() const;
  std::string Log() const;
  const std::filesystem::path& dir() const { return dir_; }
  std::string error;

 private:
  std::filesystem::path dir_;
  pid_t pid_ = -1;
  int stdout_fd_ = -1;
  int port_ = 0;
};

// Test data: the sample character in the source tree; shared data when present.
std::string SourcePath(const std::string& relative);
std::string SharedDataPath(const std::string& relative);  // "" when absent
std::string ReadFile(const std::string& path);

// A fresh temporary directory named after the running test.
std::filesystem::path TestDirectory();

}  // namespace motionlod::server::testing
