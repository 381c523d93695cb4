// Connections wait for their request headers here, on one epoll thread, and take a
// connection thread only once a whole header block has arrived. cpp-httplib gives each
// accepted socket a thread that blocks on it: 64 clients trickling a header byte every few
// seconds (or idle keep-alive connections) held every thread and the daemon stopped
// answering. Here a waiting connection costs a file descriptor and its bytes so far,
// bounded by a header deadline, a header size and a connection count; the threads serve
// only requests that are ready. After a response the thread waits for the same client's
// next request while no other connection needs a thread (the requests per second of a
// thread per connection); otherwise the connection goes back to the gate. The gate
// knows sockets and HTTP framing, not the HTTP library: the server
// reads requests through Connection::Read, which hands out the bytes read ahead first.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <vector>

#include "server/metrics.h"

namespace motionlod::server {

struct GateLimits {
  int max_connections = 4096;             // open at once, waiting or served; refused beyond
  size_t max_header_bytes = 32 << 10;     // a request line and its headers (431 beyond)
  double header_timeout_seconds = 10;     // from a request's first byte to its blank line
  double keep_alive_timeout_seconds = 5;  // an idle connection between requests
  int threads = 64;                       // connection threads: requests served at once
};

// One accepted socket (non-blocking) and the bytes read ahead of the HTTP layer.
class Connection {
 public:
  explicit Connection(int fd);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  // Up to `size` bytes: those read ahead first, else from the socket, waiting up to
  // `timeout_ms` for some. 0 at end of stream, -1 on error or timeout.
  ssize_t Read(char* data, size_t size, int timeout_ms);
  // Writes all `size` bytes, waiting up to `timeout_ms` each time the socket is full.
  // `size` on success, -1 on error or timeout.
  ssize_t Write(const char* data, size_t size, int timeout_ms);
  bool HasBufferedBytes() const { return begin_ < buffer_.size(); }
  // True when the socket can take bytes within `timeout_ms` and has no error.
  bool WaitWritable(int timeout_ms) const;
  bool WaitReadable(int timeout_ms) const;

  int fd() const { return fd_; }
  const std::string& remote_ip() const { return remote_ip_; }
  int remote_port() const { return remote_port_; }
  const std::string& local_ip() const { return local_ip_; }
  int local_port() const { return local_port_; }
  int requests_served = 0;

 private:
  friend class ConnectionGate;
  // Reads what the socket has (non-blocking) into the buffer, up to `limit` bytes held.
  // False at end of stream or on an error.
  bool ReadAvailable(size_t limit);
  // The length of the buffered header block (through its blank line), 0 if incomplete.
  size_t HeaderLength();
  // Removes header lines the HTTP library would refuse though HTTP says to ignore them:
  // a Range in a unit other than bytes (RFC 9110 14.2).
  void DropIgnorableHeaders(size_t header_length);

  int fd_;
  std::vector<char> buffer_;
  size_t begin_ = 0;    // first byte not yet handed out
  size_t scanned_ = 0;  // header search resumes here (offset from begin_)
  size_t dropped_ = 0;  // bytes read and dropped after a refusal
  std::string remote_ip_, local_ip_;
  int remote_port_ = 0, local_port_ = 0;
};

class ConnectionGate {
 public:
  using Clock = std::chrono::steady_clock;
  // Serves one request whose header block is buffered; returns true to keep the
  // connection for another request.
  using Serve = std::function<bool(Connection&)>;
  // The whole HTTP response (status line to body) sent before closing for a refusal.
  using RefusalResponse = std::function<std::string(ConnectionRefusal)>;

  // `counters` outlives the gate.
  ConnectionGate(const GateLimits& limits, ConnectionCounters& counters, Serve serve,
                 RefusalResponse refusal);
  ~ConnectionGate();
  ConnectionGate(const ConnectionGate&) = delete;
  ConnectionGate& operator=(const ConnectionGate&) = delete;

  // Takes an accepted socket. Thread-safe; never blocks on the client.
  void Admit(int fd);
  // Closes waiting connections, lets requests being served finish, joins the threads.
  void Stop();

  // True once Stop() has begun: a request being served should be the connection's last.
  bool stopping() const { return stopping_flag_.load(std::memory_order_relaxed); }

 private:
  struct Waiting {
    std::unique_ptr<Connection> connection;
    Clock::time_point deadline;
    bool idle;      // between requests, no byte of the next yet
    bool draining;  // refused: its answer is sent, what it still sends is read and dropped
  };
  enum class Arrival { kReady, kWaiting, kClosed, kTooLarge };
  // Reads what has arrived on a connection the caller holds alone (or under mutex_):
  // kReady when a whole header block is buffered (its ignorable headers then dropped).
  Arrival Receive(Connection& connection) const;
  void Park(std::unique_ptr<Connection> connection, bool idle);
  // With mutex_ held: a ready connection to a thread, a closed one closed, one past
  // max_header_bytes refused.
  void Settle(std::unique_ptr<Connection> connection, Arrival arrival);
  void PollLoop();
  void ServeLoop();
  // The next connection whose request is ready; null once stopping.
  std::unique_ptr<Connection> NextReady();
  // Serves one request, then waits for the next on the same connection while no other
  // needs a thread; returns the connection when its next request is ready, else null.
  std::unique_ptr<Connection> ServeAndLinger(std::unique_ptr<Connection> connection);
  // With mutex_ held.
  void OnReadable(int fd);
  void Dispatch(std::unique_ptr<Connection> connection);
  void Close(std::unique_ptr<Connection> connection);
  // Sends the refusal's answer; a client still sending is read for a moment more (as
  // nginx's lingering close), so that closing with its bytes unread does not reset the
  // connection before the answer is read.
  void Refuse(std::unique_ptr<Connection> connection, ConnectionRefusal why);
  // With mutex_ held: waits `seconds` at most for the connection to be readable.
  void Watch(std::unique_ptr<Connection> connection, double seconds, bool idle, bool draining);
  // With mutex_ held: takes a connection off the wait list and epoll.
  std::unique_ptr<Connection> Unwatch(std::unordered_map<int, Waiting>::iterator waiting);

  const GateLimits limits_;
  ConnectionCounters& counters_;
  const Serve serve_;
  const RefusalResponse refusal_;
  int epoll_fd_ = -1;
  int wake_fd_ = -1;  // eventfd: Stop() wakes the poll thread
  int work_fd_ = -1;  // eventfd: a ready connection waits for a thread (lingerers yield)

  std::mutex mutex_;
  std::condition_variable ready_cv_;
  std::unordered_map<int, Waiting> waiting_;
  std::deque<std::unique_ptr<Connection>> ready_;
  int idle_threads_ = 0;  // serve threads waiting on ready_cv_
  bool stopping_ = false;

  std::atomic<bool> stopping_flag_{false};
  std::thread poll_thread_;
  std::vector<std::thread> serve_threads_;
};

}  // namespace motionlod::server
