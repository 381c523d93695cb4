#include "tests/server/daemon.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <fstream>
#include <sstream>
#include <thread>

namespace motionlod::server::testing {

namespace fs = std::filesystem;

// A daemon may answer (401, 413) before it has read a whole upload and close the
// connection: the client's write then fails with EPIPE instead of killing the test.
const bool kIgnoreSigpipe = [] {
  ::signal(SIGPIPE, SIG_IGN);
  return true;
}();

Daemon::~Daemon() {
  if (pid_ > 0) Stop(SIGKILL);
  if (stdout_fd_ >= 0) ::close(stdout_fd_);
  // Kept when the test failed: its daemon.log says why.
  if (!::testing::Test::HasFailure()) {
    std::error_code ignored;
    fs::remove_all(dir_, ignored);
  }
}

bool Daemon::Start(const std::vector<std::string>& args, const std::vector<std::string>& env) {
  fs::create_directories(dir_ / "data");
  int out[2];
  if (::pipe2(out, O_CLOEXEC) != 0) return false;
  std::vector<std::string> argv_text = {
      MOTIONLODD, "--port", "0", "--data-dir", (dir_ / "data").string(), "--log-level", "debug"};
  argv_text.insert(argv_text.end(), args.begin(), args.end());
  const std::string log = (dir_ / "daemon.log").string();
  // Everything the child needs is built before fork (only async-signal-safe calls after).
  std::vector<char*> argv;
  for (std::string& a : argv_text) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::vector<std::string> env_text;
  for (char** e = environ; *e != nullptr; ++e) {
    if (std::strncmp(*e, "MOTIONLODD_", 11) != 0) env_text.emplace_back(*e);
  }
  env_text.insert(env_text.end(), env.begin(), env.end());
  std::vector<char*> envp;
  for (std::string& e : env_text) envp.push_back(e.data());
  envp.push_back(nullptr);
  const int log_fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // no daemon outlives a crashed test
    ::dup2(out[1], STDOUT_FILENO);
    if (log_fd >= 0) ::dup2(log_fd, STDERR_FILENO);
    ::execve(argv[0], argv.data(), envp.data());
    ::_exit(127);
  }
  if (log_fd >= 0) ::close(log_fd);
  ::close(out[1]);
  if (pid < 0) {
    ::close(out[0]);
    return false;
  }
  pid_ = pid;
  if (stdout_fd_ >= 0) ::close(stdout_fd_);
  stdout_fd_ = out[0];
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::string line;
  while (ReadStdoutLine(line, deadline)) {
    const std::string prefix = "listening on http://127.0.0.1:";
    if (line.rfind(prefix, 0) == 0) {
      port_ = std::stoi(line.substr(prefix.size()));
      return true;
    }
  }
  error = "motionlodd did not start; its log:\n" + Log();
  Stop(SIGKILL);
  return false;
}

bool Daemon::ReadStdoutLine(std::string& line, std::chrono::steady_clock::time_point deadline) {
  line.clear();
  while (stdout_fd_ >= 0 && std::chrono::steady_clock::now() < deadline) {
    pollfd p{stdout_fd_, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    char c = 0;
    if (::read(stdout_fd_, &c, 1) != 1) return false;
    if (c == '\n') return true;
    line += c;
  }
  return false;
}

int Daemon::Stop(int signal, std::chrono::seconds timeout) {
  if (pid_ <= 0) return -1;
  ::kill(pid_, signal);
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (std::chrono::steady_clock::now() < deadline) {
    const pid_t done = ::waitpid(pid_, &status, WNOHANG);
    if (done == pid_) {
      pid_ = -1;
      if (WIFEXITED(status)) return WEXITSTATUS(status);
      if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::kill(pid_, SIGKILL);
  ::waitpid(pid_, &status, 0);
  pid_ = -1;
  return -1;
}

std::unique_ptr<httplib::Client> Daemon::Client() const {
  auto client = std::make_unique<httplib::Client>("127.0.0.1", port_);
  client->set_connection_timeout(5, 0);
  client->set_read_timeout(60, 0);
  client->set_write_timeout(60, 0);
  client->set_tcp_nodelay(true);  // as the client library: no delayed-ACK wait per POST
  return client;
}

std::string Daemon::Log() const { return ReadFile((dir_ / "daemon.log").string()); }

std::string SourcePath(const std::string& relative) {
  return (fs::path(MOTIONLOD_SOURCE_DIR) / relative).string();
}

std::string SharedDataPath(const std::string& relative) {
  const std::string path = (fs::path(MOTIONLOD_SHARED_DATA) / relative).string();
  return fs::exists(path) ? path : "";
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

fs::path TestDirectory() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path dir =
      fs::temp_directory_path() / ("motionlodd_" + std::string(info->test_suite_name()) + "_" +
                                   info->name() + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

}  // namespace motionlod::server::testing
