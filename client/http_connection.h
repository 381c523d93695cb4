// The one HTTP connection the client talks through: plain requests in, status, headers
// and body out. Library-neutral on purpose: cpp-httplib stays behind
// client/http_connection.cc (the only client file that includes httplib.h), so the rest
// of client/ and its users never see it. Not thread-safe: one per Client.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "client/error.h"

namespace motionlod::client {

struct HttpPart {  // one multipart/form-data part
  std::string field;
  std::string filename;
  std::string bytes;
};

struct HttpRequest {
  std::string method;  // GET, POST, DELETE
  std::string target;  // path and query, e.g. /v1/jobs/ID?wait=5
  std::vector<std::pair<std::string, std::string>> headers;
  std::string content_type;     // of `body`
  std::string body;             // POST with a raw body
  std::vector<HttpPart> parts;  // POST as multipart/form-data (then `body` is unused)
};

struct HttpResponse {
  int status = 0;
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-case
  std::string body;

  // The first header of that (lower-case) name.
  std::optional<std::string_view> Header(std::string_view lower_case_name) const;
};

struct ConnectionOptions {
  std::string base_url;  // http://host:port
  double connect_timeout_seconds = 5;
  double read_timeout_seconds = 60;  // also bounds a long-poll: keep it above the wait
  double write_timeout_seconds = 60;
};

class HttpConnection {
 public:
  // kInvalidArgument when the base URL is not http://host[:port] (motionlodd speaks plain
  // HTTP; see docs/SERVER.md on TLS).
  static Result<std::unique_ptr<HttpConnection>> Open(const ConnectionOptions& options);
  ~HttpConnection();
  HttpConnection(const HttpConnection&) = delete;
  HttpConnection& operator=(const HttpConnection&) = delete;

  // The daemon's answer, whatever its status; an Error (kConnection, with the transport's
  // reason) only when there was none: refused, reset, timed out.
  Result<HttpResponse> Send(const HttpRequest& request);

 private:
  struct Impl;
  explicit HttpConnection(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace motionlod::client
