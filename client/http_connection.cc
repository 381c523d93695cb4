// The only client file that includes httplib.h (scripts/check_layering.sh checks it).
#include "client/http_connection.h"

#include <httplib.h>

#include <algorithm>
#include <cctype>
#include <cmath>

namespace motionlod::client {
namespace {

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

// Whole seconds and the remaining microseconds, as httplib's setters take them.
std::pair<time_t, time_t> SplitSeconds(double seconds) {
  const double whole = std::floor(seconds);
  return {static_cast<time_t>(whole), static_cast<time_t>((seconds - whole) * 1e6)};
}

}  // namespace

std::optional<std::string_view> HttpResponse::Header(std::string_view lower_case_name) const {
  for (const auto& [name, value] : headers) {
    if (name == lower_case_name) return value;
  }
  return std::nullopt;
}

struct HttpConnection::Impl {
  explicit Impl(const std::string& base_url) : base_url(base_url), client(base_url) {}
  std::string base_url;
  httplib::Client client;
};

// What a failed exchange means, in words a user can act on.
std::string TransportFailure(httplib::Error error) {
  switch (error) {
    case httplib::Error::Connection:
      return "could not connect (nothing listening there, unreachable, or no answer within the "
             "connect timeout)";
    case httplib::Error::Read:
      return "the connection closed, or no answer came within the read timeout";
    case httplib::Error::Write:
      return "the connection closed while the request was being sent";
    default:
      return httplib::to_string(error);
  }
}

HttpConnection::HttpConnection(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
HttpConnection::~HttpConnection() = default;

Result<std::unique_ptr<HttpConnection>> HttpConnection::Open(const ConnectionOptions& options) {
  const std::string& url = options.base_url;
  constexpr std::string_view kScheme = "http://";
  if (url.rfind(kScheme, 0) != 0 || url.size() == kScheme.size() ||
      url.find_first_of("/?#", kScheme.size()) != std::string::npos) {
    return Error{ErrorKind::kInvalidArgument, 0, std::nullopt,
                 "the server URL must be http://HOST[:PORT] without a path, got '" + url + "'"};
  }
  for (double timeout : {options.connect_timeout_seconds, options.read_timeout_seconds,
                         options.write_timeout_seconds}) {
    if (!(timeout > 0) || !std::isfinite(timeout)) {
      return Error{ErrorKind::kInvalidArgument, 0, std::nullopt,
                   "timeouts must be positive numbers of seconds"};
    }
  }
  auto impl = std::make_unique<Impl>(url);
  httplib::Client& client = impl->client;
  const auto [connect_s, connect_us] = SplitSeconds(options.connect_timeout_seconds);
  const auto [read_s, read_us] = SplitSeconds(options.read_timeout_seconds);
  const auto [write_s, write_us] = SplitSeconds(options.write_timeout_seconds);
  client.set_connection_timeout(connect_s, connect_us);
  client.set_read_timeout(read_s, read_us);
  client.set_write_timeout(write_s, write_us);
  client.set_keep_alive(true);
  // A request goes out as two writes (head, then body): without TCP_NODELAY the body
  // waits for the server's delayed ACK of the head, 40 ms per POST on a kept connection.
  client.set_tcp_nodelay(true);
  client.set_follow_location(false);  // the level redirect is followed by the Client
  return std::unique_ptr<HttpConnection>(new HttpConnection(std::move(impl)));
}

Result<HttpResponse> HttpConnection::Send(const HttpRequest& request) {
  httplib::Client& client = impl_->client;
  httplib::Headers headers;
  for (const auto& [name, value] : request.headers) headers.emplace(name, value);
  if (request.method != "GET" && request.method != "DELETE" && request.method != "POST") {
    return Error{ErrorKind::kInvalidArgument, 0, std::nullopt,
                 "unsupported HTTP method " + request.method};
  }
  httplib::Result result = [&] {
    if (request.method == "GET") return client.Get(request.target, headers);
    if (request.method == "DELETE") return client.Delete(request.target, headers);
    if (request.parts.empty())
      return client.Post(request.target, headers, request.body, request.content_type);
    httplib::MultipartFormDataItems items;
    for (const HttpPart& part : request.parts) {
      items.push_back({part.field, part.bytes, part.filename, "application/octet-stream"});
    }
    return client.Post(request.target, headers, items);
  }();
  if (!result) {
    return Error{ErrorKind::kConnection, 0, std::nullopt,
                 request.method + " " + impl_->base_url + request.target + ": " +
                     TransportFailure(result.error())};
  }
  HttpResponse response;
  response.status = result->status;
  for (const auto& [name, value] : result->headers) response.headers.emplace_back(Lower(name), value);
  response.body = std::move(result->body);
  return response;
}

}  // namespace motionlod::client
