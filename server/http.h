// The daemon's HTTP vocabulary, independent of the HTTP library: a parsed request, a
// response to fill, a route table with access levels, RFC 9457 problems, and the
// dispatcher that matches a route (404/405), checks the bearer key (401/403), runs the
// handler and turns any exception into a generic 500. server/http_server.cc is the only
// file that includes httplib.h: it converts to and from these types.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include "server/config.h"

namespace motionlod::server::http {

struct BodyPart {
  std::string field;     // form field name
  std::string filename;  // as the client sent it (validated by the service)
  std::string content_type;
  std::string bytes;
};

struct Body {
  bool multipart = false;
  std::string bytes;            // not multipart
  std::vector<BodyPart> parts;  // multipart
};

enum class BodyError {
  kTooLarge,      // decoded bytes over the limit (413)
  kTooManyParts,  // multipart parts over the limit (413)
  kTimeout,       // the whole body took longer than upload_timeout_seconds (408)
  kMalformed,     // broken framing, encoding or multipart syntax, or the client went away (400)
};

struct BodyFailure {
  BodyError error;
  std::string detail;
};

using BodyResult = std::variant<Body, BodyFailure>;

struct Request {
  std::string method;                                        // GET, HEAD, POST, DELETE, ...
  std::string path;                                          // percent-decoded
  std::vector<std::pair<std::string, std::string>> query;    // decoded
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-case
  // Instead of `headers`: looks a header up in the HTTP library's own request (saves
  // copying every header of every request). Called with a lower-case name.
  std::function<std::optional<std::string_view>(std::string_view lower_name)> header_lookup;
  std::vector<std::string> path_params;  // the {placeholders} of the route, in order
  std::string request_id;
  // Reads the body: at most `limit` decoded bytes and `max_parts` multipart parts.
  std::function<BodyResult(int64_t limit, int max_parts)> read_body;

  // First value of a header (lower-case name), or nullopt. Values are as the HTTP library
  // decoded them: never copy one into a response header.
  std::optional<std::string_view> Header(std::string_view lower_name) const;
  std::optional<std::string_view> Query(std::string_view name) const;
};

// Writes a chunk of a streamed response; false when the client is gone.
class StreamSink {
 public:
  virtual ~StreamSink() = default;
  virtual bool Write(std::string_view data) = 0;
};

struct Response {
  int status = 200;
  std::vector<std::pair<std::string, std::string>> headers;
  std::string content_type;
  std::string body;
  // Zero-copy body: bytes [offset, offset + length) of `shared` (kept alive until sent).
  std::shared_ptr<const std::string> shared;
  size_t offset = 0, length = 0;
  // Streamed body (chunked): called until it returns false; it must return within about
  // a second each time so that shutdown and dead clients are noticed.
  std::function<bool(StreamSink&)> stream;
  // Runs when the response is done with (sent, failed or dropped): releases stream slots.
  std::function<void()> on_close;

  void SetHeader(std::string name, std::string value);
  void SetJson(int status_code, const std::string& json_text);
};

// The security headers the daemon sends, all in this one place (docs/SERVER.md,
// docs/WEB.md).
struct HeaderField {
  const char* name;
  const char* value;
};
// On every response: the declared Content-Type is final, a browser never sniffs one (a
// problem+json body quoting the request path is never read as HTML).
inline constexpr HeaderField kNoSniffHeader{"X-Content-Type-Options", "nosniff"};
// On the web viewer's files in addition. The policy allows what the built page does and
// nothing else: its own module script and style sheet, fetch and XMLHttpRequest to the
// same origin's /v1 API, and blob: images. The exported levels have no textures, but the
// page's stand-in original (the uploaded .glb, when the export route fails) may:
// three.js's GLTFLoader turns each embedded image into a blob: URL the page itself made
// and loads it with fetch and createImageBitmap (an <img> in Safari before 17). No
// inline script or style attribute, eval, data: URL, worker, plug-in, <base>, form
// submission or framing; no Referer sent anywhere.
inline constexpr HeaderField kViewerSecurityHeaders[] = {
    {"Content-Security-Policy",
     "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' blob:; "
     "connect-src 'self' blob:; worker-src 'none'; object-src 'none'; base-uri 'none'; "
     "frame-ancestors 'none'; form-action 'none'"},
    {"Referrer-Policy", "no-referrer"},
    {"X-Frame-Options", "DENY"},
};

// RFC 9457 problem details: application/problem+json with type, title, status, detail,
// instance (the request path) and request_id.
void SetProblem(const Request& request, Response& response, int status, std::string detail);
// The problem body for a status alone (for errors the HTTP library raises itself).
std::string ProblemJson(int status, const std::string& detail, const std::string& instance,
                        const std::string& request_id);
const char* StatusTitle(int status);

enum class Access {
  kPublic,  // health probes and the API description
  kRead,    // needs a read or write key when read keys are configured
  kWrite,   // needs a write key when write keys are configured
};

using Handler = std::function<void(Request&, Response&)>;

struct Route {
  std::string method;
  std::string pattern;  // "/v1/bakes/{id}/level": literal segments and {placeholders}
  Access access;
  Handler handler;
  std::vector<std::string> segments;
};

class Router {
 public:
  void Add(std::string method, std::string pattern, Access access, Handler handler);
  const std::vector<Route>& routes() const { return routes_; }

  struct Match {
    int route = -1;  // index into routes(), -1 when none
    std::vector<std::string> params;
    std::vector<std::string> allowed;  // methods the path has (for 405 and OPTIONS)
  };
  // HEAD matches GET routes.
  Match Find(std::string_view method, std::string_view path) const;

 private:
  std::vector<Route> routes_;
};

// What the dispatcher needs beyond the routes.
struct DispatchOptions {
  std::vector<std::string> write_keys;
  std::vector<std::string> read_keys;
};

// Finds the route, checks access, runs the handler. Returns the route index (-1 when no
// route matched) for metrics. Never throws.
int Dispatch(const Router& router, const DispatchOptions& options, Request& request,
             Response& response);

// Request framing the daemon refuses before reading a body (the HTTP library's own
// payload limit does not see chunked or compressed bodies): ambiguous or unknown
// Transfer-Encoding, Content-Length over the limit, any body on a method but POST,
// compressed or chunked multipart. Returns false and fills `response` with the problem.
struct FramingLimits {
  int64_t max_upload_bytes = 0;
  int64_t max_json_bytes = 0;
  // A POST whose Content-Length is over max_upload_bytes by at most this much gets
  // through, so that its body is read and dropped and the 413 reaches a client that
  // sends it whole; beyond, it is refused at once and the connection closed.
  int64_t drain_bytes = 0;
};
bool CheckFraming(const Request& request, const FramingLimits& limits, Response& response);

// A random 16-hex-digit request id.
std::string NewRequestId();
// The same, written over `id` (no allocation once it has held one).
void NewRequestId(std::string& id);

// Text safe to log: control characters escaped, at most `max` bytes.
std::string Printable(std::string_view text, size_t max = 200);
// The same, appended to `out`.
void AppendPrintable(std::string& out, std::string_view text, size_t max = 200);

}  // namespace motionlod::server::http
