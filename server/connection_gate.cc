#include "server/connection_gate.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>

namespace motionlod::server {
namespace {

// Bytes read from a socket at once while serving (the library reads a byte at a time).
constexpr size_t kReadChunk = 16 << 10;
// After a refusal, what a client still sends is dropped for this long, up to this much.
constexpr double kLingerSeconds = 2;
constexpr size_t kLingerBytes = 1 << 20;

void Address(const sockaddr_storage& address, std::string& ip, int& port) {
  char text[INET6_ADDRSTRLEN] = {};
  if (address.ss_family == AF_INET) {
    const auto& v4 = reinterpret_cast<const sockaddr_in&>(address);
    ::inet_ntop(AF_INET, &v4.sin_addr, text, sizeof text);
    port = ntohs(v4.sin_port);
  } else if (address.ss_family == AF_INET6) {
    const auto& v6 = reinterpret_cast<const sockaddr_in6&>(address);
    ::inet_ntop(AF_INET6, &v6.sin6_addr, text, sizeof text);
    port = ntohs(v6.sin6_port);
  }
  ip = text;
}

bool StartsWithNoCase(std::string_view text, std::string_view prefix) {
  if (text.size() < prefix.size()) return false;
  for (size_t i = 0; i < prefix.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(text[i])) != prefix[i]) return false;
  }
  return true;
}

// `seconds` from now.
std::chrono::steady_clock::time_point After(double seconds) {
  return std::chrono::steady_clock::now() +
         std::chrono::duration_cast<std::chrono::steady_clock::duration>(
             std::chrono::duration<double>(seconds));
}

int PollOne(int fd, short events, int timeout_ms, short& revents) {
  pollfd entry{fd, events, 0};
  int ready;
  do {
    ready = ::poll(&entry, 1, timeout_ms);
  } while (ready < 0 && errno == EINTR);
  revents = entry.revents;
  return ready;
}

}  // namespace

Connection::Connection(int fd) : fd_(fd) {
  ::fcntl(fd_, F_SETFL, ::fcntl(fd_, F_GETFL, 0) | O_NONBLOCK);
  sockaddr_storage address{};
  socklen_t length = sizeof address;
  if (::getpeername(fd_, reinterpret_cast<sockaddr*>(&address), &length) == 0) {
    Address(address, remote_ip_, remote_port_);
  }
  length = sizeof address;
  if (::getsockname(fd_, reinterpret_cast<sockaddr*>(&address), &length) == 0) {
    Address(address, local_ip_, local_port_);
  }
}

Connection::~Connection() {
  ::shutdown(fd_, SHUT_RDWR);
  ::close(fd_);
}

bool Connection::WaitReadable(int timeout_ms) const {
  short revents = 0;
  return PollOne(fd_, POLLIN, timeout_ms, revents) > 0;
}

bool Connection::WaitWritable(int timeout_ms) const {
  short revents = 0;
  return PollOne(fd_, POLLOUT, timeout_ms, revents) > 0 && (revents & POLLOUT) != 0 &&
         (revents & (POLLERR | POLLHUP)) == 0;
}

ssize_t Connection::Read(char* data, size_t size, int timeout_ms) {
  if (size == 0) return 0;
  if (!HasBufferedBytes()) {
    buffer_.clear();
    begin_ = 0;
    scanned_ = 0;
    for (;;) {
      if (!WaitReadable(timeout_ms)) return -1;
      char* target = data;
      size_t capacity = size;
      if (size < kReadChunk) {
        buffer_.resize(kReadChunk);
        target = buffer_.data();
        capacity = kReadChunk;
      }
      const ssize_t got = ::recv(fd_, target, capacity, 0);
      if (got < 0 && (errno == EAGAIN || errno == EINTR)) continue;
      if (target != data) buffer_.resize(got > 0 ? static_cast<size_t>(got) : 0);
      if (got <= 0 || target == data) return got;
      break;
    }
  }
  const size_t count = std::min(size, buffer_.size() - begin_);
  std::memcpy(data, buffer_.data() + begin_, count);
  begin_ += count;
  scanned_ = 0;  // the next header search starts at the new first byte
  return static_cast<ssize_t>(count);
}

ssize_t Connection::Write(const char* data, size_t size, int timeout_ms) {
  size_t done = 0;
  while (done < size) {
    const ssize_t sent = ::send(fd_, data + done, size - done, MSG_NOSIGNAL);
    if (sent > 0) {
      done += static_cast<size_t>(sent);
    } else if (sent < 0 && errno == EINTR) {
      continue;
    } else if (sent < 0 && errno == EAGAIN) {
      if (!WaitWritable(timeout_ms)) return -1;
    } else {
      return -1;
    }
  }
  return static_cast<ssize_t>(size);
}

bool Connection::ReadAvailable(size_t limit) {
  if (begin_ > 0) {
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(begin_));
    begin_ = 0;
  }
  while (buffer_.size() < limit) {
    const size_t held = buffer_.size();
    buffer_.resize(std::min(limit, held + kReadChunk));
    const ssize_t got = ::recv(fd_, buffer_.data() + held, buffer_.size() - held, 0);
    buffer_.resize(held + (got > 0 ? static_cast<size_t>(got) : 0));
    if (got == 0) return false;
    if (got < 0) {
      if (errno == EINTR) continue;
      return errno == EAGAIN;
    }
  }
  return true;
}

size_t Connection::HeaderLength() {
  const std::string_view held(buffer_.data() + begin_, buffer_.size() - begin_);
  const size_t from = scanned_ > 3 ? scanned_ - 3 : 0;
  const size_t end = held.find("\r\n\r\n", from);
  if (end == std::string_view::npos) {
    scanned_ = held.size();
    return 0;
  }
  return end + 4;
}

void Connection::DropIgnorableHeaders(size_t header_length) {
  size_t line = begin_;
  const size_t header_end = begin_ + header_length;
  while (line < header_end) {
    const std::string_view rest(buffer_.data() + line, header_end - line);
    const size_t next = rest.find("\r\n") + 2;
    std::string_view field = rest.substr(0, next - 2);
    if (line != begin_ && StartsWithNoCase(field, "range:")) {
      field.remove_prefix(6);
      while (!field.empty() && (field.front() == ' ' || field.front() == '\t')) {
        field.remove_prefix(1);
      }
      if (!StartsWithNoCase(field, "bytes=")) {
        const auto at = buffer_.begin() + static_cast<std::ptrdiff_t>(line);
        buffer_.erase(at, at + static_cast<std::ptrdiff_t>(next));
        return;
      }
    }
    line += next;
  }
}

ConnectionGate::ConnectionGate(const GateLimits& limits, ConnectionCounters& counters, Serve serve,
                               RefusalResponse refusal)
    : limits_(limits), counters_(counters), serve_(std::move(serve)), refusal_(std::move(refusal)) {
  epoll_fd_ = ::epoll_create1(EPOLL_CLOEXEC);
  wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  work_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  epoll_event wake{};
  wake.events = EPOLLIN;
  wake.data.fd = wake_fd_;
  ::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, wake_fd_, &wake);
  poll_thread_ = std::thread([this] { PollLoop(); });
  for (int i = 0; i < std::max(1, limits_.threads); ++i) {
    serve_threads_.emplace_back([this] { ServeLoop(); });
  }
}

ConnectionGate::~ConnectionGate() {
  Stop();
  ::close(epoll_fd_);
  ::close(wake_fd_);
  ::close(work_fd_);
}

void ConnectionGate::Admit(int fd) {
  auto connection = std::make_unique<Connection>(fd);
  if (counters_.open.fetch_add(1, std::memory_order_relaxed) >= limits_.max_connections) {
    Refuse(std::move(connection), ConnectionRefusal::kTooManyConnections);
    return;
  }
  Park(std::move(connection), false);
}

ConnectionGate::Arrival ConnectionGate::Receive(Connection& connection) const {
  const bool open = connection.ReadAvailable(limits_.max_header_bytes);
  if (const size_t header = connection.HeaderLength(); header > 0) {
    connection.DropIgnorableHeaders(header);
    return Arrival::kReady;
  }
  if (!open) return Arrival::kClosed;
  if (connection.buffer_.size() >= limits_.max_header_bytes) return Arrival::kTooLarge;
  return Arrival::kWaiting;
}

void ConnectionGate::Park(std::unique_ptr<Connection> connection, bool idle) {
  std::lock_guard lock(mutex_);
  if (stopping_) return Close(std::move(connection));
  // The request often came with the connection, or was pipelined behind the last one.
  const Arrival arrival = Receive(*connection);
  if (arrival != Arrival::kWaiting) return Settle(std::move(connection), arrival);
  idle = idle && !connection->HasBufferedBytes();
  Watch(std::move(connection),
        idle ? limits_.keep_alive_timeout_seconds : limits_.header_timeout_seconds, idle, false);
}

void ConnectionGate::Settle(std::unique_ptr<Connection> connection, Arrival arrival) {
  switch (arrival) {
    case Arrival::kReady:
      return Dispatch(std::move(connection));
    case Arrival::kTooLarge:
      return Refuse(std::move(connection), ConnectionRefusal::kHeaderTooLarge);
    case Arrival::kClosed:
    case Arrival::kWaiting:
      return Close(std::move(connection));
  }
}

void ConnectionGate::Watch(std::unique_ptr<Connection> connection, double seconds, bool idle,
                           bool draining) {
  const int fd = connection->fd();
  epoll_event event{};
  event.events = EPOLLIN | EPOLLRDHUP;
  event.data.fd = fd;
  ::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, fd, &event);
  waiting_[fd] = Waiting{std::move(connection), After(seconds), idle, draining};
}

std::unique_ptr<Connection> ConnectionGate::Unwatch(
    std::unordered_map<int, Waiting>::iterator waiting) {
  ::epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, waiting->first, nullptr);
  std::unique_ptr<Connection> connection = std::move(waiting->second.connection);
  waiting_.erase(waiting);
  return connection;
}

void ConnectionGate::OnReadable(int fd) {
  const auto found = waiting_.find(fd);
  if (found == waiting_.end()) return;
  Waiting& waiting = found->second;
  Connection& connection = *waiting.connection;
  if (waiting.draining) {
    char dropped[kReadChunk];
    ssize_t got = 0;
    while (connection.dropped_ <= kLingerBytes &&
           (got = ::recv(fd, dropped, sizeof dropped, 0)) > 0) {
      connection.dropped_ += static_cast<size_t>(got);
    }
    const bool open = got > 0 || (got < 0 && (errno == EAGAIN || errno == EINTR));
    if (!open || connection.dropped_ > kLingerBytes) Close(Unwatch(found));
    return;
  }
  const Arrival arrival = Receive(connection);
  if (arrival != Arrival::kWaiting) return Settle(Unwatch(found), arrival);
  if (waiting.idle && connection.HasBufferedBytes()) {
    // The next request has begun: it now has the header deadline.
    waiting.idle = false;
    waiting.deadline = After(limits_.header_timeout_seconds);
  }
}

void ConnectionGate::Dispatch(std::unique_ptr<Connection> connection) {
  ready_.push_back(std::move(connection));
  if (idle_threads_ > 0) {
    ready_cv_.notify_one();
  } else {
    // Every thread is serving or lingering on an idle connection: the lingerers give
    // theirs back.
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = ::write(work_fd_, &one, sizeof one);
  }
}

void ConnectionGate::Close(std::unique_ptr<Connection> connection) {
  connection.reset();
  counters_.open.fetch_sub(1, std::memory_order_relaxed);
}

void ConnectionGate::Refuse(std::unique_ptr<Connection> connection, ConnectionRefusal why) {
  counters_.refused[static_cast<int>(why)].fetch_add(1, std::memory_order_relaxed);
  const std::string response = refusal_(why);
  // One attempt, never a wait: a client that does not read loses the explanation.
  [[maybe_unused]] const ssize_t sent =
      ::send(connection->fd(), response.data(), response.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
  // Past max_connections nothing more is held for it.
  if (why == ConnectionRefusal::kTooManyConnections) return Close(std::move(connection));
  ::shutdown(connection->fd(), SHUT_WR);
  Watch(std::move(connection), kLingerSeconds, false, true);
}

void ConnectionGate::PollLoop() {
  constexpr int kMaxEvents = 256;
  epoll_event events[kMaxEvents];
  for (;;) {
    // Deadlines are checked at least every 100 ms.
    const int count = ::epoll_wait(epoll_fd_, events, kMaxEvents, 100);
    std::lock_guard lock(mutex_);
    if (stopping_) return;
    for (int i = 0; i < count; ++i) {
      if (events[i].data.fd != wake_fd_) OnReadable(events[i].data.fd);
    }
    const Clock::time_point now = Clock::now();
    std::vector<int> expired;
    for (const auto& [fd, waiting] : waiting_) {
      if (waiting.deadline <= now) expired.push_back(fd);
    }
    for (const int fd : expired) {
      const auto found = waiting_.find(fd);
      // A request begun and not finished gets its 408; an idle or refused one just closes.
      const bool quiet = found->second.idle || found->second.draining;
      std::unique_ptr<Connection> taken = Unwatch(found);
      if (quiet) {
        Close(std::move(taken));
      } else {
        Refuse(std::move(taken), ConnectionRefusal::kHeaderTimeout);
      }
    }
  }
}

void ConnectionGate::ServeLoop() {
  while (std::unique_ptr<Connection> connection = NextReady()) {
    while (connection) connection = ServeAndLinger(std::move(connection));
  }
}

std::unique_ptr<Connection> ConnectionGate::NextReady() {
  std::unique_lock lock(mutex_);
  ++idle_threads_;
  ready_cv_.wait(lock, [this] { return stopping_ || !ready_.empty(); });
  --idle_threads_;
  if (stopping_) return nullptr;
  std::unique_ptr<Connection> connection = std::move(ready_.front());
  ready_.pop_front();
  if (ready_.empty()) {
    uint64_t signals = 0;
    [[maybe_unused]] const ssize_t got = ::read(work_fd_, &signals, sizeof signals);
  }
  return connection;
}

std::unique_ptr<Connection> ConnectionGate::ServeAndLinger(std::unique_ptr<Connection> connection) {
  if (!serve_(*connection)) {
    Close(std::move(connection));
    return nullptr;
  }
  // While no other connection waits for a thread, this one waits here for the client's
  // next request (as a thread per connection would): a client streaming requests skips
  // the poll thread and a handoff, which cost 15% to 25% of the requests per second of
  // 64 kept connections. Work queued for a thread (work_fd_) sends it to the gate.
  const Clock::time_point deadline = After(limits_.keep_alive_timeout_seconds);
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    if (left.count() <= 0 || stopping()) {
      Close(std::move(connection));
      return nullptr;
    }
    pollfd waits[2] = {{connection->fd(), POLLIN, 0}, {work_fd_, POLLIN, 0}};
    if (::poll(waits, 2, static_cast<int>(left.count())) < 0 && errno != EINTR) {
      Close(std::move(connection));
      return nullptr;
    }
    if (stopping()) continue;
    if (waits[0].revents != 0) {
      const Arrival arrival = Receive(*connection);
      if (arrival == Arrival::kReady) return connection;
      if (arrival == Arrival::kClosed) {
        Close(std::move(connection));
        return nullptr;
      }
      Park(std::move(connection), true);  // a partial header: the gate times it
      return nullptr;
    }
    if (waits[1].revents != 0) {
      Park(std::move(connection), true);
      return nullptr;
    }
  }
}

void ConnectionGate::Stop() {
  {
    std::lock_guard lock(mutex_);
    if (stopping_) return;
    stopping_ = true;
    stopping_flag_.store(true, std::memory_order_relaxed);
    for (auto& [fd, waiting] : waiting_) Close(std::move(waiting.connection));
    waiting_.clear();
    while (!ready_.empty()) {
      Close(std::move(ready_.front()));
      ready_.pop_front();
    }
  }
  ready_cv_.notify_all();
  const uint64_t one = 1;
  [[maybe_unused]] const ssize_t woke = ::write(wake_fd_, &one, sizeof one);
  [[maybe_unused]] const ssize_t worked = ::write(work_fd_, &one, sizeof one);
  if (poll_thread_.joinable()) poll_thread_.join();
  for (std::thread& thread : serve_threads_) {
    if (thread.joinable()) thread.join();
  }
}

}  // namespace motionlod::server
