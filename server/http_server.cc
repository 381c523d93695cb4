// The only file of the daemon that includes httplib.h (see http_server.h).
#include "server/http_server.h"

#include <httplib.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <iterator>
#include <mutex>
#include <thread>

#include "server/connection_gate.h"

namespace motionlod::server {
namespace {

using Clock = std::chrono::steady_clock;

// Per connection thread: the request being served (httplib calls the pre-routing
// handler, the route handler and the logger of one request on the same thread). Kept
// from request to request so that its strings keep their capacity: serving a request
// allocates little beyond what the library does.
struct RequestContext {
  bool active = false;
  std::string id;
  Clock::time_point start;
  int route = -1;
  http::Request request;
  // The bytes of a zero-copy response, alive until the library has written them.
  std::shared_ptr<const std::string> response_bytes;
  // The response closes its connection: it said so, or the library refused the request
  // before any route saw it (a malformed request line or header).
  bool close_connection = false;
};
thread_local RequestContext t_request;

// The library, with its thread per socket replaced by the connection gate: an accepted
// socket goes to the gate, which calls the library back per ready request.
class GatedServer final : public httplib::Server {
 public:
  using httplib::Server::process_request;
  std::function<void(int)> admit;

 private:
  bool process_and_close_socket(socket_t sock) override {
    admit(sock);
    return true;
  }
};

// The library's only task is handing an accepted socket over, which never blocks: it
// runs on the accepting thread.
class InlineTaskQueue final : public httplib::TaskQueue {
 public:
  void enqueue(std::function<void()> task) override { task(); }
  void shutdown() override {}
};

// A gate connection as the library's stream, with the configured read and write timeouts.
class GateStream final : public httplib::Stream {
 public:
  GateStream(Connection& connection, int read_timeout_ms, int write_timeout_ms)
      : connection_(connection),
        read_timeout_ms_(read_timeout_ms),
        write_timeout_ms_(write_timeout_ms) {}
  bool is_readable() const override {
    return connection_.HasBufferedBytes() || connection_.WaitReadable(read_timeout_ms_);
  }
  bool is_writable() const override { return connection_.WaitWritable(write_timeout_ms_); }
  ssize_t read(char* data, size_t size) override {
    return connection_.Read(data, size, read_timeout_ms_);
  }
  ssize_t write(const char* data, size_t size) override {
    return connection_.Write(data, size, write_timeout_ms_);
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    ip = connection_.remote_ip();
    port = connection_.remote_port();
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    ip = connection_.local_ip();
    port = connection_.local_port();
  }
  // The library answers 500 to a socket number at or above FD_SETSIZE, which it would
  // select() on; nothing selects on this one, and a thousand connections pass 1024.
  socket_t socket() const override { return 0; }

 private:
  Connection& connection_;
  const int read_timeout_ms_;
  const int write_timeout_ms_;
};

// The answer to a connection the gate closes unserved.
std::string RefusalResponse(ConnectionRefusal why) {
  int status = 503;
  std::string detail;
  std::string extra;
  switch (why) {
    case ConnectionRefusal::kHeaderTimeout:
      status = 408;
      detail = "the request headers did not arrive in time (header_timeout_seconds)";
      break;
    case ConnectionRefusal::kHeaderTooLarge:
      status = 431;
      detail = "the request line and headers are larger than max_header_bytes";
      break;
    case ConnectionRefusal::kTooManyConnections:
      detail = "too many open connections (max_connections); retry shortly";
      extra = "Retry-After: 1\r\n";
      break;
  }
  const std::string id = http::NewRequestId();
  const std::string body = http::ProblemJson(status, detail, "", id);
  return fmt::format(
      "HTTP/1.1 {} {}\r\nContent-Type: application/problem+json\r\nContent-Length: {}\r\n"
      "Connection: close\r\n{}: {}\r\nX-Request-Id: {}\r\n{}\r\n{}",
      status, http::StatusTitle(status), body.size(), http::kNoSniffHeader.name,
      http::kNoSniffHeader.value, id, extra, body);
}

constexpr const char* kAnyPath = "[\\s\\S]*";
// Bytes of an unread request body read and dropped to keep the connection usable.
constexpr size_t kDrainBytes = size_t{1} << 20;

// Header values we write are our own text; strip line breaks all the same, so that no
// code path can ever split a response.
std::string HeaderSafe(std::string value) {
  value.erase(std::remove_if(value.begin(), value.end(),
                             [](char c) { return c == '\r' || c == '\n' || c == '\0'; }),
              value.end());
  return value;
}

// What every response carries: its request id and kNoSniffHeader.
void SetCommonHeaders(httplib::Response& res, const std::string& request_id) {
  res.set_header("X-Request-Id", request_id);
  res.set_header(http::kNoSniffHeader.name, http::kNoSniffHeader.value);
}

// A header of the library's request (its map compares names case-insensitively and
// looks up std::string keys only: one per thread is reused).
std::optional<std::string_view> Find(const httplib::Request& req, std::string_view name) {
  thread_local std::string key;
  key.assign(name);
  const auto found = req.headers.find(key);
  if (found == req.headers.end()) return std::nullopt;
  return std::string_view(found->second);
}

class SinkAdapter : public http::StreamSink {
 public:
  explicit SinkAdapter(httplib::DataSink& sink) : sink_(sink) {}
  bool Write(std::string_view data) override {
    if (sink_.is_writable && !sink_.is_writable()) return false;
    return sink_.write(data.data(), data.size());
  }

 private:
  httplib::DataSink& sink_;
};

// The access log: one line per request, in the format of the daemon's other log lines.
// Each connection thread formats its lines into a buffer of its own, under a lock that
// only the flusher ever contends: no shared lock and no write(2) per request (spdlog's
// sink serialises every line of every thread on one mutex). A buffer goes to stderr in
// one fwrite of whole lines (stdio locks the stream per call, so lines never mix) when
// it passes kBatchBytes, and every buffer once a second and when the server stops: a
// line can appear up to a second after the other lines logged at the same time.
class AccessLog {
 public:
  AccessLog() : flusher_([this] { FlushEverySecond(); }) {}
  ~AccessLog() {
    {
      std::lock_guard lock(stop_mutex_);
      stopping_ = true;
    }
    stop_.notify_all();
    flusher_.join();
    Flush();
  }
  AccessLog(const AccessLog&) = delete;
  AccessLog& operator=(const AccessLog&) = delete;

  void Write(std::string_view id, std::string_view method, std::string_view path, int status,
             double seconds, std::string_view client) {
    Buffer& buffer = ThreadBuffer();
    std::lock_guard lock(buffer.mutex);
    std::string& out = buffer.lines;
    AppendTimestamp(out);
    out += " info [";
    out += id;
    out += "] ";
    http::AppendPrintable(out, method, 16);
    out += ' ';
    http::AppendPrintable(out, path);
    fmt::format_to(std::back_inserter(out), " {} {:.2f} ms ", status, seconds * 1e3);
    http::AppendPrintable(out, client, 64);
    out += '\n';
    if (out.size() >= kBatchBytes) WriteOut(out);
  }

  void Flush() {
    std::lock_guard registry(buffers_mutex_);
    for (const auto& buffer : buffers_) {
      std::lock_guard lock(buffer->mutex);
      WriteOut(buffer->lines);
    }
    std::fflush(stderr);
  }

 private:
  static constexpr size_t kBatchBytes = 16384;
  struct Buffer {
    std::mutex mutex;
    std::string lines;
  };

  Buffer& ThreadBuffer() {
    // An id, not `this`: a later log at the same address must not find a stale buffer.
    thread_local uint64_t owner = 0;
    thread_local Buffer* buffer = nullptr;
    if (owner != id_) {
      std::lock_guard registry(buffers_mutex_);
      buffers_.push_back(std::make_unique<Buffer>());
      buffer = buffers_.back().get();
      buffer->lines.reserve(kBatchBytes + 1024);
      owner = id_;
    }
    return *buffer;
  }

  // "2026-11-22T14:04:10.123" in local time, as spdlog's "%Y-%m-%dT%H:%M:%S.%e"; the
  // seconds are formatted once per second per thread.
  static void AppendTimestamp(std::string& out) {
    thread_local std::time_t formatted_second = -1;
    thread_local char second_text[32] = "";
    const auto now = std::chrono::system_clock::now();
    const std::time_t second = std::chrono::system_clock::to_time_t(now);
    if (second != formatted_second) {
      std::tm local{};
      localtime_r(&second, &local);
      std::strftime(second_text, sizeof second_text, "%Y-%m-%dT%H:%M:%S", &local);
      formatted_second = second;
    }
    const auto millis =
        std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() %
        1000;
    fmt::format_to(std::back_inserter(out), "{}.{:03d}", second_text, millis);
  }

  static void WriteOut(std::string& lines) {
    if (lines.empty()) return;
    std::fwrite(lines.data(), 1, lines.size(), stderr);
    lines.clear();
  }

  void FlushEverySecond() {
    std::unique_lock lock(stop_mutex_);
    while (!stop_.wait_for(lock, std::chrono::seconds(1), [this] { return stopping_; })) {
      lock.unlock();
      Flush();
      lock.lock();
    }
  }

  static inline std::atomic<uint64_t> next_id_{1};
  const uint64_t id_ = next_id_.fetch_add(1);
  std::mutex buffers_mutex_;
  std::vector<std::unique_ptr<Buffer>> buffers_;
  std::mutex stop_mutex_;
  std::condition_variable stop_;
  bool stopping_ = false;
  std::thread flusher_;
};

}  // namespace

std::vector<HttpMetrics::RouteLabel> RouteLabels(const http::Router& router) {
  std::vector<HttpMetrics::RouteLabel> labels;
  for (const http::Route& route : router.routes()) labels.push_back({route.method, route.pattern});
  return labels;
}

struct HttpServer::Impl {
  Impl(const Config& c, const http::Router& r, HttpMetrics& m) : config(c), router(r), metrics(m) {
    dispatch.write_keys = config.write_keys;
    dispatch.read_keys = config.read_keys;
    framing.max_upload_bytes = config.max_upload_bytes;
    framing.max_json_bytes = config.max_json_bytes;
    framing.drain_bytes = static_cast<int64_t>(kDrainBytes);
    if (config.access_log) access_log = std::make_unique<AccessLog>();
  }

  void Configure();
  // Starts the thread's request: a new id, the clock, method, path and header lookup.
  void Begin(const httplib::Request& req);
  void Handle(const httplib::Request& req, httplib::Response& res,
              const httplib::ContentReader* reader);
  http::BodyResult ReadBody(const httplib::Request& req, const httplib::ContentReader* reader,
                            int64_t limit, int max_parts, bool& consumed);
  void Write(const httplib::Request& req, http::Response& out, httplib::Response& res);
  void Log(const httplib::Request& req, const httplib::Response& res);

  const Config& config;
  const http::Router& router;
  HttpMetrics& metrics;
  http::DispatchOptions dispatch;
  http::FramingLimits framing;
  // Null when access_log is off.
  std::unique_ptr<AccessLog> access_log;
  GatedServer server;
  // Serves one ready request of a gate connection; true to keep the connection.
  bool Serve(Connection& connection);
  // Made by Run(), stopped when the listener's loop has ended.
  std::unique_ptr<ConnectionGate> gate;
  std::atomic<int> listen_fd{-1};
  // The library's stop() does nothing until its listen loop has started: a SIGTERM
  // right after "listening on" was lost, and the daemon served on. Run() and Stop()
  // agree on who goes first.
  std::mutex run_mutex;
  bool stop_requested = false;  // Run() returns at once
  bool run_started = false;     // Run() has entered the library: Stop() waits for its loop
  std::atomic<bool> run_ended{false};
};

void HttpServer::Impl::Configure() {
  server.new_task_queue = [] { return new InlineTaskQueue(); };
  server.admit = [this](int fd) { gate->Admit(fd); };
  server.set_socket_options([this](int fd) {
    const int yes = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    // Accepted sockets inherit TCP_NODELAY on Linux: without it every response waits
    // for the client's delayed ACK (Nagle), about 300 requests per second in all.
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
    listen_fd = fd;
  });
  server.set_tcp_nodelay(true);
  server.set_read_timeout(config.read_timeout_seconds, 0);
  server.set_write_timeout(config.write_timeout_seconds, 0);
  server.set_keep_alive_timeout(config.keep_alive_timeout_seconds);
  server.set_keep_alive_max_count(static_cast<size_t>(config.keep_alive_max_requests));
  // Bodies a little over the limits are read and dropped (see ReadBody) so the client
  // sees the 413; the library's own check only refuses beyond that.
  server.set_payload_max_length(
      kDrainBytes + static_cast<size_t>(std::max(config.max_upload_bytes, config.max_json_bytes)));

  // Every request but POST is served right here: the library has read its (small,
  // bounded) body already, and its regex route table would only cost time. POST goes
  // on to the content-reader handler below, which reads the body under our limits.
  server.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    Begin(req);
    http::Response out;
    if (!http::CheckFraming(t_request.request, framing, out)) {
      // The body is left unread: the connection cannot be reused.
      out.SetHeader("Connection", "close");
      Write(req, out, res);
      return httplib::Server::HandlerResponse::Handled;
    }
    if (req.method == "POST") return httplib::Server::HandlerResponse::Unhandled;
    Handle(req, res, nullptr);
    return httplib::Server::HandlerResponse::Handled;
  });

  server.Post(kAnyPath,
              [this](const httplib::Request& req, httplib::Response& res,
                     const httplib::ContentReader& reader) { Handle(req, res, &reader); });

  // Errors the library raises itself (malformed request line, header too long, a Range
  // it cannot parse): problem+json instead of an empty body.
  server.set_error_handler(
      httplib::Server::HandlerWithResponse([](const httplib::Request& req, httplib::Response& res) {
        if (!res.body.empty() || res.content_length_ > 0 || res.content_provider_) {
          return httplib::Server::HandlerResponse::Unhandled;
        }
        const std::string id = t_request.active ? t_request.id : http::NewRequestId();
        if (!res.has_header("X-Request-Id")) SetCommonHeaders(res, id);
        const_cast<httplib::Request&>(req).ranges.clear();
        res.set_content(http::ProblemJson(res.status, http::StatusTitle(res.status), req.path, id),
                        "application/problem+json");
        return httplib::Server::HandlerResponse::Handled;
      }));
  // Never report what was thrown (the library's default puts it in a header).
  server.set_exception_handler([](const httplib::Request& req, httplib::Response& res,
                                  std::exception_ptr error) {
    std::string what = "unknown exception";
    try {
      if (error) std::rethrow_exception(error);
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
    }
    const std::string id = t_request.active ? t_request.id : http::NewRequestId();
    spdlog::error("[{}] uncaught exception: {}", id, http::Printable(what));
    res = httplib::Response();
    res.status = 500;
    SetCommonHeaders(res, id);
    res.set_content(http::ProblemJson(500, "internal error; the daemon's log has request id " + id,
                                      req.path, id),
                    "application/problem+json");
  });
  server.set_logger(
      [this](const httplib::Request& req, const httplib::Response& res) { Log(req, res); });
}

http::BodyResult HttpServer::Impl::ReadBody(const httplib::Request& req,
                                            const httplib::ContentReader* reader, int64_t limit,
                                            int max_parts, bool& consumed) {
  consumed = true;
  if (reader == nullptr) {
    if (static_cast<int64_t>(req.body.size()) > limit) {
      return http::BodyFailure{http::BodyError::kTooLarge,
                               "the body is over " + std::to_string(limit) + " bytes"};
    }
    return http::Body{false, req.body, {}};
  }
  const auto deadline = Clock::now() + std::chrono::seconds(config.upload_timeout_seconds);
  int64_t total = 0;
  bool too_large = false, too_many = false, timed_out = false;
  http::Body body;
  // Over the limit, up to kDrainBytes more are read and dropped, so that a client
  // still sending sees the 413 on a connection that stays usable; beyond, it is cut.
  const auto count = [&](size_t n) {
    total += static_cast<int64_t>(n);
    if (Clock::now() > deadline) {
      timed_out = true;
      return false;
    }
    if (total > limit) too_large = true;
    return total <= limit + static_cast<int64_t>(kDrainBytes);
  };
  bool ok = false;
  if (req.is_multipart_form_data()) {
    body.multipart = true;
    ok = (*reader)(
        [&](const httplib::MultipartFormData& part) {
          if (static_cast<int>(body.parts.size()) >= max_parts) {
            too_many = true;
            return false;
          }
          body.parts.push_back({part.name, part.filename, part.content_type, {}});
          return true;
        },
        [&](const char* data, size_t n) {
          if (!count(n) || body.parts.empty()) return false;
          if (!too_large) body.parts.back().bytes.append(data, n);
          return true;
        });
  } else {
    ok = (*reader)([&](const char* data, size_t n) {
      if (!count(n)) return false;
      if (!too_large) body.bytes.append(data, n);
      return true;
    });
  }
  if (too_large) {
    consumed = ok && !timed_out;  // read to its end within the drain allowance
    return http::BodyFailure{http::BodyError::kTooLarge,
                             "the decoded body is over the limit of " + std::to_string(limit) +
                                 " bytes (max_upload_bytes / max_json_bytes)"};
  }
  if (too_many) {
    consumed = false;
    return http::BodyFailure{
        http::BodyError::kTooManyParts,
        "more than " + std::to_string(max_parts) + " multipart parts (max_upload_parts)"};
  }
  if (timed_out) {
    consumed = false;
    return http::BodyFailure{http::BodyError::kTimeout,
                             "the body took longer than " +
                                 std::to_string(config.upload_timeout_seconds) +
                                 " s (upload_timeout_seconds)"};
  }
  if (!ok) {
    consumed = false;
    return http::BodyFailure{
        http::BodyError::kMalformed,
        "the body could not be read: truncated, badly encoded or malformed multipart"};
  }
  return body;
}

void HttpServer::Impl::Begin(const httplib::Request& req) {
  RequestContext& context = t_request;
  context.active = true;
  http::NewRequestId(context.id);
  context.start = Clock::now();
  context.route = -1;
  context.response_bytes.reset();
  http::Request& request = context.request;
  request.method.assign(req.method);
  request.path.assign(req.path);
  request.query.clear();
  request.headers.clear();
  request.path_params.clear();
  request.request_id.assign(context.id);
  request.header_lookup = [&req](std::string_view name) { return Find(req, name); };
  request.read_body = nullptr;
}

void HttpServer::Impl::Handle(const httplib::Request& req, httplib::Response& res,
                              const httplib::ContentReader* reader) {
  // The pre-routing handler has begun the request on this thread (POST bodies too).
  if (!t_request.active) Begin(req);
  http::Request& request = t_request.request;
  for (const auto& [name, value] : req.params) request.query.emplace_back(name, value);
  bool body_read = reader == nullptr;
  bool request_read_failed = false;  // the reader was used: it cannot be used again
  if (reader == nullptr) {
    // The library has read the (small, bounded) body already.
    request.read_body = [this, &req](int64_t limit, int max_parts) {
      bool consumed = false;
      return ReadBody(req, nullptr, limit, max_parts, consumed);
    };
  } else {
    request.read_body = [&](int64_t limit, int max_parts) {
      bool consumed = false;
      http::BodyResult result = ReadBody(req, reader, limit, max_parts, consumed);
      body_read = consumed;
      request_read_failed = !consumed;
      return result;
    };
  }
  http::Response out;
  t_request.route = http::Dispatch(router, dispatch, request, out);
  if (t_request.route < 0) t_request.route = metrics.unmatched();
  request.read_body = nullptr;  // it refers to this call's locals
  // A body left unread would be parsed as the next request. A small one is read and
  // dropped, so that a client still sending it sees the answer (401, 415, ...) instead
  // of a reset connection; a large or half-read one closes the connection.
  if (!body_read && (req.has_header("Content-Length") || req.has_header("Transfer-Encoding"))) {
    bool drained = false;
    if (reader != nullptr && !request_read_failed) {
      size_t seen = 0;
      const auto drop = [&seen](const char*, size_t n) {
        seen += n;
        return seen <= kDrainBytes;
      };
      // A multipart body must be read with both callbacks: the library calls the part
      // header one without checking it (an empty one throws std::bad_function_call).
      drained = req.is_multipart_form_data()
                    ? (*reader)([](const httplib::MultipartFormData&) { return true; }, drop)
                    : (*reader)(drop);
    }
    if (!drained) out.SetHeader("Connection", "close");
  }
  Write(req, out, res);
}

void HttpServer::Impl::Write(const httplib::Request& req, http::Response& out,
                             httplib::Response& res) {
  // Ranges are answered by the routes; the library must not apply them again.
  const_cast<httplib::Request&>(req).ranges.clear();
  res.status = out.status;
  SetCommonHeaders(res, t_request.id);
  for (auto& [name, value] : out.headers) res.set_header(name, HeaderSafe(std::move(value)));
  std::function<void()> on_close = std::move(out.on_close);
  if (out.stream) {
    auto stream = std::move(out.stream);
    res.set_chunked_content_provider(
        out.content_type,
        [stream](size_t, httplib::DataSink& sink) {
          SinkAdapter adapter(sink);
          if (!stream(adapter)) sink.done();
          return true;
        },
        [on_close](bool) {
          if (on_close) on_close();
        });
  } else if (out.shared) {
    // The provider runs on this thread before the logger: the thread's context keeps the
    // bytes alive, and the provider captures one pointer (no allocation for it).
    t_request.response_bytes = std::move(out.shared);
    const char* const data = t_request.response_bytes->data() + out.offset;
    res.set_content_provider(
        out.length, out.content_type,
        [data](size_t from, size_t length, httplib::DataSink& sink) {
          return sink.write(data + from, length);
        },
        on_close ? httplib::ContentProviderResourceReleaser([on_close](bool) { on_close(); })
                 : httplib::ContentProviderResourceReleaser());
  } else {
    if (!out.body.empty() || !out.content_type.empty()) res.set_content(out.body, out.content_type);
    if (on_close) on_close();
  }
}

bool HttpServer::Impl::Serve(Connection& connection) {
  GateStream stream(connection, config.read_timeout_seconds * 1000,
                    config.write_timeout_seconds * 1000);
  const bool last =
      ++connection.requests_served >= config.keep_alive_max_requests || gate->stopping();
  bool client_closes = false;
  t_request.close_connection = false;
  const bool written = server.process_request(stream, last, client_closes, nullptr);
  return written && !last && !client_closes && !t_request.close_connection;
}

void HttpServer::Impl::Log(const httplib::Request& req, const httplib::Response& res) {
  const bool active = t_request.active;
  t_request.close_connection = !active || res.get_header_value("Connection") == "close";
  const double seconds =
      active ? std::chrono::duration<double>(Clock::now() - t_request.start).count() : 0.0;
  metrics.Record(active ? t_request.route : metrics.unmatched(), res.status, seconds);
  if (access_log && spdlog::should_log(spdlog::level::info)) {
    access_log->Write(active ? std::string_view(t_request.id) : std::string_view("-"), req.method,
                      req.path, res.status, seconds, req.remote_addr);
  }
  t_request.active = false;
  t_request.response_bytes.reset();
}

HttpServer::HttpServer(const Config& config, const http::Router& router, HttpMetrics& metrics)
    : impl_(std::make_unique<Impl>(config, router, metrics)) {
  impl_->Configure();
}

HttpServer::~HttpServer() = default;

StatusOr<int> HttpServer::Bind() {
  int port = impl_->config.port;
  if (port == 0) {
    port = impl_->server.bind_to_any_port(impl_->config.bind);
    if (port <= 0)
      return Status(StatusCode::kInternal, "cannot bind " + impl_->config.bind + " on any port");
  } else if (!impl_->server.bind_to_port(impl_->config.bind, port)) {
    return Status(StatusCode::kInternal, "cannot bind " + impl_->config.bind + ":" +
                                             std::to_string(port) +
                                             " (in use, or not an address here)");
  }
  // The library listens with a backlog of 5; a burst of connections would see SYN
  // retransmits (a second each). listen() again only raises the backlog.
  if (const int fd = impl_->listen_fd.load(); fd >= 0) ::listen(fd, 1024);
  return port;
}

bool HttpServer::Run() {
  {
    std::lock_guard lock(impl_->run_mutex);
    if (impl_->stop_requested) return true;
    impl_->run_started = true;
  }
  GateLimits limits;
  limits.max_connections = impl_->config.max_connections;
  limits.max_header_bytes = static_cast<size_t>(impl_->config.max_header_bytes);
  limits.header_timeout_seconds = impl_->config.header_timeout_seconds;
  limits.keep_alive_timeout_seconds = impl_->config.keep_alive_timeout_seconds;
  limits.threads = impl_->config.http_threads;
  impl_->gate = std::make_unique<ConnectionGate>(
      limits, impl_->metrics.connections,
      [this](Connection& connection) { return impl_->Serve(connection); },
      RefusalResponse);
  const bool served = impl_->server.listen_after_bind();
  // Waiting connections are closed; requests being served finish.
  impl_->gate->Stop();
  impl_->run_ended = true;
  // The connection threads have ended: their last access lines go out now.
  if (impl_->access_log) impl_->access_log->Flush();
  return served;
}

void HttpServer::Stop() {
  {
    std::lock_guard lock(impl_->run_mutex);
    impl_->stop_requested = true;
    if (!impl_->run_started) return;
  }
  while (!impl_->server.is_running() && !impl_->run_ended) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  impl_->server.stop();
}

}  // namespace motionlod::server
