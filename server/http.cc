#include "server/http.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <nlohmann/json.hpp>
#include <random>

namespace motionlod::server::http {
namespace {

constexpr char kHex[] = "0123456789abcdef";

std::string Lower(std::string_view text) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return lower;
}

std::string Trim(std::string_view text) {
  size_t begin = 0, end = text.size();
  while (begin < end && (text[begin] == ' ' || text[begin] == '\t')) ++begin;
  while (end > begin && (text[end - 1] == ' ' || text[end - 1] == '\t')) --end;
  return std::string(text.substr(begin, end - begin));
}

std::vector<std::string_view> SplitView(std::string_view path) {
  std::vector<std::string_view> segments;
  size_t start = 1;  // paths start with '/'
  while (start <= path.size()) {
    const size_t end = std::min(path.find('/', start), path.size());
    segments.push_back(path.substr(start, end - start));
    start = end + 1;
  }
  return segments;
}

std::vector<std::string> Split(std::string_view path) {
  std::vector<std::string> segments;
  size_t start = 1;  // paths start with '/'
  while (start <= path.size()) {
    const size_t end = std::min(path.find('/', start), path.size());
    segments.emplace_back(path.substr(start, end - start));
    start = end + 1;
  }
  return segments;
}

const char* Slug(int status) {
  switch (status) {
    case 400:
      return "bad-request";
    case 401:
      return "unauthorized";
    case 403:
      return "forbidden";
    case 404:
      return "not-found";
    case 405:
      return "method-not-allowed";
    case 408:
      return "request-timeout";
    case 409:
      return "conflict";
    case 411:
      return "length-required";
    case 413:
      return "content-too-large";
    case 414:
      return "uri-too-long";
    case 415:
      return "unsupported-media-type";
    case 416:
      return "range-not-satisfiable";
    case 422:
      return "unprocessable-content";
    case 431:
      return "request-header-fields-too-large";
    case 501:
      return "not-implemented";
    case 503:
      return "service-unavailable";
    default:
      return status >= 500 ? "internal-error" : "client-error";
  }
}

// Equal keys compare in time independent of where they differ.
bool SameKey(std::string_view a, std::string_view b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  const size_t n = std::max(a.size(), b.size());
  for (size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff |= static_cast<unsigned char>(x ^ y);
  }
  return diff == 0;
}

bool AnyKey(const std::vector<std::string>& keys, std::string_view token) {
  bool found = false;
  for (const std::string& key : keys) found = SameKey(key, token) || found;
  return found;
}

std::string JoinMethods(const std::vector<std::string>& methods) {
  std::string text;
  for (const std::string& m : methods) text += (text.empty() ? "" : ", ") + m;
  return text;
}

}  // namespace

std::optional<std::string_view> Request::Header(std::string_view lower_name) const {
  if (header_lookup) return header_lookup(lower_name);
  for (const auto& [name, value] : headers) {
    if (name == lower_name) return std::string_view(value);
  }
  return std::nullopt;
}

std::optional<std::string_view> Request::Query(std::string_view name) const {
  for (const auto& [key, value] : query) {
    if (key == name) return std::string_view(value);
  }
  return std::nullopt;
}

void Response::SetHeader(std::string name, std::string value) {
  const auto same = [](std::string_view a, std::string_view b) {
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
             return std::tolower(static_cast<unsigned char>(x)) ==
                    std::tolower(static_cast<unsigned char>(y));
           });
  };
  for (auto& [key, existing] : headers) {
    if (same(key, name)) {
      existing = std::move(value);
      return;
    }
  }
  headers.emplace_back(std::move(name), std::move(value));
}

void Response::SetJson(int status_code, const std::string& json_text) {
  status = status_code;
  content_type = "application/json";
  body = json_text;
}

const char* StatusTitle(int status) {
  switch (status) {
    case 400:
      return "Bad Request";
    case 401:
      return "Unauthorized";
    case 403:
      return "Forbidden";
    case 404:
      return "Not Found";
    case 405:
      return "Method Not Allowed";
    case 408:
      return "Request Timeout";
    case 409:
      return "Conflict";
    case 411:
      return "Length Required";
    case 413:
      return "Content Too Large";
    case 414:
      return "URI Too Long";
    case 415:
      return "Unsupported Media Type";
    case 416:
      return "Range Not Satisfiable";
    case 422:
      return "Unprocessable Content";
    case 431:
      return "Request Header Fields Too Large";
    case 500:
      return "Internal Server Error";
    case 501:
      return "Not Implemented";
    case 503:
      return "Service Unavailable";
    default:
      return status >= 500 ? "Server Error" : "Client Error";
  }
}

std::string ProblemJson(int status, const std::string& detail, const std::string& instance,
                        const std::string& request_id) {
  nlohmann::json problem = {{"type", std::string("urn:motionlod:problem:") + Slug(status)},
                            {"title", StatusTitle(status)},
                            {"status", status},
                            {"detail", detail},
                            {"instance", instance},
                            {"request_id", request_id}};
  // Replace invalid UTF-8 (a path can hold any bytes) instead of throwing.
  return problem.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

void SetProblem(const Request& request, Response& response, int status, std::string detail) {
  response.status = status;
  response.content_type = "application/problem+json";
  response.body = ProblemJson(status, detail, request.path, request.request_id);
  response.shared.reset();
  response.stream = nullptr;
}

void Router::Add(std::string method, std::string pattern, Access access, Handler handler) {
  Route route{std::move(method), std::move(pattern), access, std::move(handler), {}};
  route.segments = Split(route.pattern);
  routes_.push_back(std::move(route));
}

Router::Match Router::Find(std::string_view method, std::string_view path) const {
  Match match;
  if (path.empty() || path[0] != '/') return match;
  const std::vector<std::string_view> segments = SplitView(path);
  const std::string_view wanted = method == "HEAD" ? std::string_view("GET") : method;
  const auto matches = [&](const Route& route) {
    if (route.segments.size() != segments.size()) return false;
    for (size_t s = 0; s < segments.size(); ++s) {
      const std::string& expected = route.segments[s];
      const bool placeholder =
          expected.size() >= 2 && expected.front() == '{' && expected.back() == '}';
      if (placeholder ? segments[s].empty() : expected != segments[s]) return false;
    }
    return true;
  };
  for (size_t r = 0; r < routes_.size(); ++r) {
    const Route& route = routes_[r];
    if (route.method != wanted || !matches(route)) continue;
    match.route = static_cast<int>(r);
    for (size_t s = 0; s < segments.size(); ++s) {
      const std::string& expected = route.segments[s];
      if (expected.size() >= 2 && expected.front() == '{') match.params.emplace_back(segments[s]);
    }
    return match;
  }
  // No route for this method: the methods the path has, for 405 and OPTIONS.
  for (const Route& route : routes_) {
    if (!matches(route)) continue;
    if (std::find(match.allowed.begin(), match.allowed.end(), route.method) ==
        match.allowed.end()) {
      match.allowed.push_back(route.method);
      if (route.method == "GET") match.allowed.push_back("HEAD");
    }
  }
  return match;
}

int Dispatch(const Router& router, const DispatchOptions& options, Request& request,
             Response& response) {
  try {
    Router::Match match = router.Find(request.method, request.path);
    if (match.route < 0) {
      if (match.allowed.empty()) {
        SetProblem(request, response, 404, "nothing is served at this path; see /v1/openapi.yaml");
        return -1;
      }
      const std::string allow = JoinMethods(match.allowed) + ", OPTIONS";
      response.SetHeader("Allow", allow);
      if (request.method == "OPTIONS") {
        response.status = 204;
        return -1;
      }
      SetProblem(
          request, response, 405,
          request.method.size() <= 16 && std::all_of(request.method.begin(), request.method.end(),
                                                     [](char c) { return c >= 'A' && c <= 'Z'; })
              ? request.method + " is not allowed here; allowed: " + allow
              : "the method is not allowed here; allowed: " + allow);
      return -1;
    }
    const Route& route = router.routes()[static_cast<size_t>(match.route)];
    const bool needs_key = (route.access == Access::kWrite && !options.write_keys.empty()) ||
                           (route.access == Access::kRead && !options.read_keys.empty());
    if (needs_key) {
      const std::optional<std::string_view> authorization = request.Header("authorization");
      std::string token;
      if (authorization && authorization->size() > 7 &&
          Lower(authorization->substr(0, 7)) == "bearer ") {
        token = Trim(authorization->substr(7));
      }
      const bool write_ok = AnyKey(options.write_keys, token);
      const bool read_ok = AnyKey(options.read_keys, token);
      const bool allowed = route.access == Access::kWrite ? write_ok : (write_ok || read_ok);
      if (!allowed) {
        if (token.empty()) {
          response.SetHeader("WWW-Authenticate", "Bearer realm=\"motionlodd\"");
          SetProblem(request, response, 401,
                     std::string("this daemon needs a bearer key for ") +
                         (route.access == Access::kWrite ? "writes" : "reads") +
                         ": send 'Authorization: Bearer <key>'");
        } else if (route.access == Access::kWrite && read_ok) {
          SetProblem(request, response, 403, "the key allows reads only; this request writes");
        } else {
          response.SetHeader("WWW-Authenticate",
                             "Bearer realm=\"motionlodd\", error=\"invalid_token\"");
          SetProblem(request, response, 401, "the bearer key is not valid");
        }
        return match.route;
      }
    }
    request.path_params = std::move(match.params);
    route.handler(request, response);
    return match.route;
  } catch (const std::exception& error) {
    spdlog::error("[{}] handler threw: {}", request.request_id, Printable(error.what()));
  } catch (...) {
    spdlog::error("[{}] handler threw a non-standard exception", request.request_id);
  }
  response = Response{};
  SetProblem(request, response, 500,
             "internal error; the daemon's log has request id " + request.request_id);
  return -1;
}

bool CheckFraming(const Request& request, const FramingLimits& limits, Response& response) {
  const std::optional<std::string_view> te = request.Header("transfer-encoding");
  const std::optional<std::string_view> cl = request.Header("content-length");
  const std::optional<std::string_view> ce = request.Header("content-encoding");
  const bool takes_body = request.method == "POST";
  if (te && cl) {
    SetProblem(request, response, 400,
               "a request may not carry both Content-Length and Transfer-Encoding");
    return false;
  }
  if (te && Lower(Trim(*te)) != "chunked") {
    SetProblem(request, response, 501, "the only transfer coding accepted is 'chunked'");
    return false;
  }
  int64_t length = 0;
  if (cl) {
    const std::string text = Trim(*cl);
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), length);
    if (text.empty() || error != std::errc() || end != text.data() + text.size() || length < 0) {
      SetProblem(request, response, 400, "Content-Length must be a non-negative decimal integer");
      return false;
    }
  }
  if (!takes_body) {
    if (te || (ce && Lower(Trim(*ce)) != "identity")) {
      SetProblem(
          request, response, 400,
          "a " + Printable(request.method, 16) + " request takes no chunked or encoded body");
      return false;
    }
    if (length > 0) {
      SetProblem(request, response, 400,
                 "a " + Printable(request.method, 16) + " request takes no body");
      return false;
    }
    return true;
  }
  if (length > limits.max_upload_bytes + limits.drain_bytes) {
    SetProblem(request, response, 413,
               "the body has " + std::to_string(length) + " bytes; the limit is " +
                   std::to_string(limits.max_upload_bytes) + " (max_upload_bytes)");
    return false;
  }
  if (ce) {
    const std::string coding = Lower(Trim(*ce));
    if (coding != "identity" && coding != "gzip" && coding != "deflate" && coding != "br") {
      SetProblem(request, response, 415, "Content-Encoding must be identity, gzip, deflate or br");
      return false;
    }
  }
  const std::optional<std::string_view> type = request.Header("content-type");
  if (type && Lower(*type).rfind("multipart/", 0) == 0) {
    if (te) {
      SetProblem(request, response, 411,
                 "multipart uploads need a Content-Length (no chunked transfer)");
      return false;
    }
    if (ce && Lower(Trim(*ce)) != "identity") {
      SetProblem(
          request, response, 415,
          "multipart uploads cannot be compressed as a whole; compress nothing or send one file");
      return false;
    }
  }
  return true;
}

std::string NewRequestId() {
  std::string id;
  NewRequestId(id);
  return id;
}

void NewRequestId(std::string& id) {
  thread_local std::mt19937_64 generator{std::random_device{}()};
  uint64_t value = generator();
  id.resize(16);
  for (int i = 15; i >= 0; --i) {
    id[static_cast<size_t>(i)] = kHex[value & 15];
    value >>= 4;
  }
}

std::string Printable(std::string_view text, size_t max) {
  std::string out;
  AppendPrintable(out, text, max);
  return out;
}

void AppendPrintable(std::string& out, std::string_view text, size_t max) {
  for (unsigned char c : text.substr(0, max)) {
    if (c < 0x20 || c == 0x7f || c == '\\') {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    } else {
      out += static_cast<char>(c);
    }
  }
  if (text.size() > max) out += "...";
}

}  // namespace motionlod::server::http
