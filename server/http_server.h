// The HTTP server: cpp-httplib (Debian's compiled 0.11.4) behind the neutral types of
// server/http.h. http_server.cc is the only file of the daemon that includes httplib.h.
// What it adds to the library's defaults:
//  * a connection thread pool of Config::http_threads (the library's is fixed at 8),
//    TCP_NODELAY, a listen backlog of 1024 (the library's is 5), no SO_REUSEPORT;
//  * framing guards before any body is read (http::CheckFraming), and bodies read
//    through the library's content reader with the decoded size counted, so chunked and
//    compressed uploads meet the same limit as plain ones;
//  * its own range handling (the library's is switched off per response), problem+json
//    for the errors the library raises itself, an exception handler that never reports
//    what was thrown, and no request header value ever copied into a response header;
//  * a request id per request (X-Request-Id), request metrics, and an access log line
//    formatted into a buffer of the connection thread (no lock shared between requests);
//  * per-thread request state reused from request to request: little allocation per
//    request beyond the library's own.
#pragma once

#include <memory>
#include <string>

#include "base/status.h"
#include "server/config.h"
#include "server/http.h"
#include "server/metrics.h"

namespace motionlod::server {

class HttpServer {
 public:
  HttpServer(const Config& config, const http::Router& router, HttpMetrics& metrics);
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Binds config.bind:config.port and returns the port (the chosen one for port 0).
  StatusOr<int> Bind();
  // Serves until Stop(); false when the listener failed.
  bool Run();
  // Stops accepting, closes idle connections and lets Run() return. Thread-safe, and
  // effective whenever it comes: before Run() (which then returns at once) or while
  // Run() is starting the library's loop.
  void Stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Route labels for HttpMetrics, in router order.
std::vector<HttpMetrics::RouteLabel> RouteLabels(const http::Router& router);

}  // namespace motionlod::server
