// Raw HTTP for the daemon tests: a TCP connection that sends bytes exactly as given
// (where a client library would sanitise them) and reads one response at a time, and the
// bodies hostile clients send (gzip, chunked).
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

namespace motionlod::server::testing {

// One response read off a raw connection.
struct RawReply {
  int status = 0;    // 0: no status line arrived
  std::string head;  // status line and headers
  std::string body;
  bool closed = false;  // the daemon closed the connection after it
};

// A TCP connection to the daemon that sends bytes exactly as given.
class RawConnection {
 public:
  explicit RawConnection(int port) : fd_(::socket(AF_INET, SOCK_STREAM, 0)) {
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<uint16_t>(port));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ =
        fd_ >= 0 && ::connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
    SetReceiveTimeout(std::chrono::seconds(60));
  }
  ~RawConnection() {
    if (fd_ >= 0) ::close(fd_);
  }
  RawConnection(const RawConnection&) = delete;
  RawConnection& operator=(const RawConnection&) = delete;

  bool connected() const { return connected_; }

  // False when the daemon has closed or reset the connection.
  bool Send(std::string_view bytes) {
    while (!bytes.empty()) {
      const ssize_t n = ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL);
      if (n <= 0) return false;
      bytes.remove_prefix(static_cast<size_t>(n));
    }
    return true;
  }

  // The daemon has sent something (or closed): a reply is waiting to be read.
  bool Answered() {
    pollfd ready{fd_, POLLIN, 0};
    return ::poll(&ready, 1, 0) > 0;
  }

  void SetReceiveTimeout(std::chrono::seconds timeout) {
    timeval tv{};
    tv.tv_sec = static_cast<time_t>(timeout.count());
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }

  // Reads one response: the head, then Content-Length bytes of body (or up to the close).
  RawReply Read() {
    RawReply reply;
    size_t head_end = std::string::npos;
    while ((head_end = buffer_.find("\r\n\r\n")) == std::string::npos) {
      if (!Receive()) {
        reply.closed = true;
        return reply;
      }
    }
    reply.head = buffer_.substr(0, head_end + 2);
    buffer_.erase(0, head_end + 4);
    if (reply.head.rfind("HTTP/1.1 ", 0) == 0) reply.status = std::atoi(reply.head.c_str() + 9);
    const std::string length = Header(reply.head, "content-length");
    if (length.empty()) {
      while (Receive()) {
      }
      reply.body = std::move(buffer_);
      reply.closed = true;
      return reply;
    }
    const size_t size = std::stoul(length);
    while (buffer_.size() < size && Receive()) {
    }
    reply.body = buffer_.substr(0, std::min(size, buffer_.size()));
    buffer_.erase(0, reply.body.size());
    reply.closed = Header(reply.head, "connection") == "close";
    return reply;
  }

  // The status line and headers of a response whose body may never end (a stream): its
  // status, 0 when none came.
  int ReadStatus() {
    while (buffer_.find("\r\n\r\n") == std::string::npos) {
      if (!Receive()) return 0;
    }
    return buffer_.rfind("HTTP/1.1 ", 0) == 0 ? std::atoi(buffer_.c_str() + 9) : 0;
  }

  // Closes with a reset (SO_LINGER 0), as a client that crashed or lost its network.
  void Reset() {
    linger hard{1, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_LINGER, &hard, sizeof hard);
    ::close(fd_);
    fd_ = -1;
  }

  // Waits for the daemon to close the connection (reading and dropping what comes).
  bool ClosedByDaemon() {
    while (Receive()) {
    }
    return closed_;
  }

  // A header of a raw head, by lower-case name; "" when absent.
  static std::string Header(const std::string& head, const std::string& lower_name) {
    size_t start = head.find("\r\n");
    while (start != std::string::npos && start + 2 < head.size()) {
      const size_t end = head.find("\r\n", start + 2);
      const std::string line = head.substr(start + 2, end - start - 2);
      const size_t colon = line.find(':');
      std::string name = line.substr(0, colon);
      std::transform(name.begin(), name.end(), name.begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      if (colon != std::string::npos && name == lower_name) {
        size_t value = colon + 1;
        while (value < line.size() && line[value] == ' ') ++value;
        return line.substr(value);
      }
      start = end;
    }
    return "";
  }

 private:
  // False at the end of the stream, a reset or the receive timeout.
  bool Receive() {
    char chunk[65536];
    const ssize_t n = ::recv(fd_, chunk, sizeof chunk, 0);
    if (n <= 0) {
      closed_ = n == 0 || errno == ECONNRESET;
      return false;
    }
    buffer_.append(chunk, static_cast<size_t>(n));
    return true;
  }

  int fd_;
  bool connected_ = false;
  bool closed_ = false;
  std::string buffer_;
};

// `bytes` compressed with gzip.
inline std::string Gzip(const std::string& bytes) {
  z_stream stream{};
  deflateInit2(&stream, Z_BEST_COMPRESSION, Z_DEFLATED, 31, 8, Z_DEFAULT_STRATEGY);
  std::string out(deflateBound(&stream, bytes.size()) + 64, '\0');
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
  stream.avail_in = static_cast<uInt>(bytes.size());
  stream.next_out = reinterpret_cast<Bytef*>(out.data());
  stream.avail_out = static_cast<uInt>(out.size());
  deflate(&stream, Z_FINISH);
  out.resize(stream.total_out);
  deflateEnd(&stream);
  return out;
}

// `bytes` as chunks of `chunk` bytes in the chunked transfer coding, with the last chunk.
inline std::string Chunked(const std::string& bytes, size_t chunk) {
  std::string out;
  char size[32];
  for (size_t at = 0; at < bytes.size(); at += chunk) {
    const size_t n = std::min(chunk, bytes.size() - at);
    std::snprintf(size, sizeof size, "%zx\r\n", n);
    out += size;
    out.append(bytes, at, n);
    out += "\r\n";
  }
  return out + "0\r\n\r\n";
}

}  // namespace motionlod::server::testing
