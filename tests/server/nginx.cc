#include "tests/server/nginx.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>

#include "tests/server/daemon.h"
#include "tests/server/loopback.h"

namespace motionlod::server::testing {
namespace {

constexpr const char* kNginxBinary = "/usr/sbin/nginx";

void Replace(std::string& text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  if (at != std::string::npos) text.replace(at, from.size(), to);
}

}  // namespace

bool Nginx::Installed() { return ::access(kNginxBinary, X_OK) == 0; }

Nginx::~Nginx() {
  if (pid_ <= 0) return;
  ::kill(pid_, SIGTERM);
  int status = 0;
  ::waitpid(pid_, &status, 0);
}

bool Nginx::Start(const std::vector<int>& daemon_ports) {
  std::filesystem::create_directories(dir_ / "logs");
  port_ = FreePort();
  std::string site = ReadFile(SourcePath("deploy/nginx/motionlod.conf"));
  Replace(site, "listen 8080", "listen 127.0.0.1:" + std::to_string(port_));
  const std::string server_line = "  server 127.0.0.1:8081 max_fails=3 fail_timeout=10s;\n";
  std::string servers;
  for (int daemon_port : daemon_ports) {
    std::string line = server_line;
    Replace(line, "8081", std::to_string(daemon_port));
    servers += line;
  }
  Replace(site, server_line, servers);
  Replace(site, "/var/cache/nginx/motionlod", (dir_ / "cache").string());
  std::ofstream(dir_ / "motionlod.conf") << site;
  const std::string prefix = dir_.string() + "/";
  std::ofstream(dir_ / "nginx.conf")
      << (::geteuid() == 0 ? "user root;\n" : "")  // workers write the temporary files here
      << "worker_processes 1;\nworker_rlimit_nofile 16384;\npid " << prefix
      << "nginx.pid;\nerror_log " << prefix << "logs/error.log warn;\n"
      << "events { worker_connections 8192; }\n"
      << "http {\n  access_log off;\n  client_body_temp_path " << prefix << "body;\n"
      << "  proxy_temp_path " << prefix << "proxy;\n  fastcgi_temp_path " << prefix
      << "fastcgi;\n  uwsgi_temp_path " << prefix << "uwsgi;\n  scgi_temp_path " << prefix
      << "scgi;\n  include " << prefix << "motionlod.conf;\n}\n";
  const std::string config = (dir_ / "nginx.conf").string();
  // What nginx says before its error log is open (a configuration error) goes here.
  const std::string stderr_path = (dir_ / "logs" / "stderr.log").string();
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int log = ::open(stderr_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (log >= 0) ::dup2(log, STDERR_FILENO);
    ::execl(kNginxBinary, kNginxBinary, "-p", prefix.c_str(), "-c", config.c_str(), "-g",
            "daemon off;", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  if (pid < 0) return false;
  pid_ = pid;
  if (WaitUntilAccepting(pid_, port_)) return true;
  error = "nginx did not start: " + ReadFile(stderr_path) +
          ReadFile((dir_ / "logs" / "error.log").string());
  return false;
}

}  // namespace motionlod::server::testing
