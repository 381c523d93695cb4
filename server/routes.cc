#include "server/routes.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>

namespace motionlod::server {
namespace {

namespace api = proto::api;
using http::Access;
using http::Request;
using http::Response;
using nlohmann::json;

constexpr const char* kLevelContentType = "application/octet-stream";
constexpr const char* kImmutable = "public, max-age=31536000, immutable";

std::string Lower(std::string_view text) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return lower;
}

std::string Dump(const json& value) {
  return value.dump(-1, ' ', false, json::error_handler_t::replace);
}

void Fail(const Request& request, Response& response, const ServiceError& error) {
  if (error.retry_after_seconds > 0)
    response.SetHeader("Retry-After", std::to_string(error.retry_after_seconds));
  http::SetProblem(request, response, HttpStatus(error.kind), error.detail);
}

std::optional<double> ParseNumber(std::string_view text) {
  double value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() ||
      !std::isfinite(value)) {
    return std::nullopt;
  }
  return value;
}

std::optional<uint64_t> ParseUnsigned(std::string_view text) {
  uint64_t value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

bool IsModelFile(const std::string& name) {
  const size_t dot = name.rfind('.');
  if (dot == std::string::npos) return false;
  const std::string ext = Lower(name.substr(dot + 1));
  for (const char* known : {"glb", "gltf", "fbx", "dae", "bvh", "x", "smd"}) {
    if (ext == known) return true;
  }
  return false;
}

// Reads an upload: the raw body named by ?filename= or X-Filename, or multipart parts
// named by their filenames (the main file: the part of field "file", else the only model
// file). Fills `files` (main first) or the problem.
bool ReadUpload(Request& request, Response& response, const Config& config,
                std::atomic<int>* open_uploads, std::vector<io::SourceFile>& files) {
  const std::string type = Lower(request.Header("content-type").value_or(""));
  const bool multipart = type.rfind("multipart/form-data", 0) == 0;
  if (type.rfind("application/x-www-form-urlencoded", 0) == 0 ||
      (type.rfind("multipart/", 0) == 0 && !multipart)) {
    http::SetProblem(
        request, response, 415,
        "send the file as the raw body (Content-Type: application/octet-stream, name in "
        "?filename= or X-Filename) or as multipart/form-data parts with filenames");
    return false;
  }
  std::string name;
  if (!multipart) {
    if (auto query = request.Query("filename")) {
      name = std::string(*query);
    } else if (auto header = request.Header("x-filename")) {
      name = std::string(*header);
    } else {
      http::SetProblem(request, response, 400,
                       "name the file with ?filename=NAME or an X-Filename header (the extension "
                       "picks the format)");
      return false;
    }
  }
  // Bodies are held in memory: bound how many arrive at once.
  const int uploading = open_uploads->fetch_add(1);
  struct Release {
    std::atomic<int>* count;
    ~Release() { count->fetch_sub(1); }
  } release{open_uploads};
  if (uploading >= config.max_concurrent_uploads) {
    response.SetHeader("Retry-After", "2");
    http::SetProblem(request, response, 503,
                     "too many uploads are arriving (" +
                         std::to_string(config.max_concurrent_uploads) + "); retry shortly");
    return false;
  }
  http::BodyResult body = request.read_body(config.max_upload_bytes, config.max_upload_parts);
  if (const auto* failure = std::get_if<http::BodyFailure>(&body)) {
    const int status = failure->error == http::BodyError::kTimeout     ? 408
                       : failure->error == http::BodyError::kMalformed ? 400
                                                                       : 413;
    http::SetProblem(request, response, status, failure->detail);
    return false;
  }
  http::Body& content = std::get<http::Body>(body);
  if (!content.multipart) {
    files.push_back({name, std::move(content.bytes)});
    return true;
  }
  int main = -1;
  int models = 0;
  for (size_t p = 0; p < content.parts.size(); ++p) {
    const http::BodyPart& part = content.parts[p];
    if (part.filename.empty()) {
      http::SetProblem(request, response, 400,
                       "every multipart part needs a filename (field '" +
                           http::Printable(part.field, 64) + "' has none)");
      return false;
    }
    if (part.field == "file" && main < 0) main = static_cast<int>(p);
    if (IsModelFile(part.filename)) ++models;
  }
  if (main < 0) {
    if (models != 1) {
      http::SetProblem(
          request, response, 400,
          models == 0
              ? "no part is a model file (.glb, .gltf, .fbx, .dae, .bvh, .x, .smd)"
              : "several parts are model files: send the main one in the form field 'file'");
      return false;
    }
    for (size_t p = 0; p < content.parts.size(); ++p) {
      if (IsModelFile(content.parts[p].filename)) main = static_cast<int>(p);
    }
  }
  files.push_back({content.parts[main].filename, std::move(content.parts[main].bytes)});
  for (size_t p = 0; p < content.parts.size(); ++p) {
    if (static_cast<int>(p) != main)
      files.push_back({content.parts[p].filename, std::move(content.parts[p].bytes)});
  }
  if (files.empty()) {
    http::SetProblem(request, response, 400, "the multipart body holds no part");
    return false;
  }
  return true;
}

// Counts an open stream or long-poll; refuses beyond the limit.
class StreamSlot {
 public:
  StreamSlot(std::atomic<int>* open, int limit) : open_(open) {
    acquired_ = open_->fetch_add(1) < limit;
    if (!acquired_) open_->fetch_sub(1);
  }
  ~StreamSlot() {
    if (acquired_) open_->fetch_sub(1);
  }
  StreamSlot(const StreamSlot&) = delete;
  StreamSlot& operator=(const StreamSlot&) = delete;
  bool acquired() const { return acquired_; }
  // Hands the slot to someone else (a streamed response's on_close).
  void Release() { acquired_ = false; }

 private:
  std::atomic<int>* open_;
  bool acquired_ = false;
};

void RefuseStream(const Request& request, Response& response, int limit) {
  response.SetHeader("Retry-After", "2");
  http::SetProblem(request, response, 503,
                   "too many open event streams and long-polls (" + std::to_string(limit) +
                       "); retry, or poll without ?wait=");
}

// If-None-Match holds this entity tag (or *).
bool MatchesEtag(std::string_view header, std::string_view etag) {
  size_t start = 0;
  while (start < header.size()) {
    size_t end = header.find(',', start);
    if (end == std::string_view::npos) end = header.size();
    std::string_view item = header.substr(start, end - start);
    while (!item.empty() && item.front() == ' ') item.remove_prefix(1);
    while (!item.empty() && item.back() == ' ') item.remove_suffix(1);
    if (item.substr(0, 2) == "W/") item.remove_prefix(2);
    if (item == "*" || item == etag) return true;
    start = end + 1;
  }
  return false;
}

struct ByteRange {
  uint64_t first = 0, last = 0;  // inclusive
};

enum class RangeAnswer { kIgnore, kPartial, kUnsatisfiable };

// RFC 9110 byte ranges: one satisfiable range (after merging overlapping or adjacent
// ones) is served as 206; several disjoint ones, more than 16, or a malformed header are
// ignored (200 with the whole file); none satisfiable is 416.
RangeAnswer ResolveRange(std::string_view header, uint64_t size, ByteRange& out) {
  if (header.substr(0, 6) != "bytes=") return RangeAnswer::kIgnore;
  header.remove_prefix(6);
  std::vector<ByteRange> ranges;
  int count = 0;
  size_t start = 0;
  while (start <= header.size()) {
    size_t end = header.find(',', start);
    if (end == std::string_view::npos) end = header.size();
    std::string_view spec = header.substr(start, end - start);
    while (!spec.empty() && spec.front() == ' ') spec.remove_prefix(1);
    while (!spec.empty() && spec.back() == ' ') spec.remove_suffix(1);
    if (++count > 16) return RangeAnswer::kIgnore;
    const size_t dash = spec.find('-');
    if (dash == std::string_view::npos) return RangeAnswer::kIgnore;
    const std::string_view a = spec.substr(0, dash), b = spec.substr(dash + 1);
    if (a.empty()) {
      const auto suffix = ParseUnsigned(b);
      if (!suffix) return RangeAnswer::kIgnore;
      if (*suffix > 0 && size > 0) ranges.push_back({size - std::min(*suffix, size), size - 1});
    } else {
      const auto first = ParseUnsigned(a);
      if (!first) return RangeAnswer::kIgnore;
      uint64_t last = size == 0 ? 0 : size - 1;
      if (!b.empty()) {
        const auto parsed = ParseUnsigned(b);
        if (!parsed || *parsed < *first) return RangeAnswer::kIgnore;
        last = std::min(last, *parsed);
      }
      if (*first < size) ranges.push_back({*first, last});
    }
    start = end + 1;
  }
  if (ranges.empty()) return RangeAnswer::kUnsatisfiable;
  std::sort(ranges.begin(), ranges.end(),
            [](const ByteRange& x, const ByteRange& y) { return x.first < y.first; });
  ByteRange merged = ranges[0];
  for (size_t r = 1; r < ranges.size(); ++r) {
    if (ranges[r].first > merged.last + 1) return RangeAnswer::kIgnore;  // disjoint
    merged.last = std::max(merged.last, ranges[r].last);
  }
  out = merged;
  return RangeAnswer::kPartial;
}

// ?clip=NAME of the level routes: "" when absent; false (the problem set) when empty.
bool ReadClip(const Request& request, Response& response, std::string& clip) {
  const auto text = request.Query("clip");
  if (!text) return true;
  if (text->empty()) {
    http::SetProblem(request, response, 400,
                     "clip must name one of the bake's clips (an animation name); leave it out "
                     "for every clip");
    return false;
  }
  clip = std::string(*text);
  return true;
}

void ServeLevel(Levels& levels, Request& request, Response& response) {
  const std::string& hash = request.path_params[0];
  std::string clip;
  if (!ReadClip(request, response, clip)) return;
  auto file = levels.Get(hash, clip);
  if (!file.ok()) return Fail(request, response, file.error());
  const std::string etag = "\"" + file->key + "\"";
  response.SetHeader("ETag", etag);
  response.SetHeader("Cache-Control", kImmutable);
  response.SetHeader("Accept-Ranges", "bytes");
  if (auto match = request.Header("if-none-match"); match && MatchesEtag(*match, etag)) {
    response.status = 304;
    return;
  }
  const LevelCache::Bytes& shared = file->bytes;
  const uint64_t size = shared->size();
  response.content_type = kLevelContentType;
  response.shared = shared;
  response.offset = 0;
  response.length = size;
  response.status = 200;
  const auto range = request.Header("range");
  const auto if_range = request.Header("if-range");
  if (!range || (if_range && *if_range != etag)) return;
  ByteRange resolved;
  switch (ResolveRange(*range, size, resolved)) {
    case RangeAnswer::kIgnore:
      return;
    case RangeAnswer::kUnsatisfiable:
      // The error is not the immutable resource: no long-lived caching of it.
      response.SetHeader("Cache-Control", "no-store");
      response.SetHeader("Content-Range", "bytes */" + std::to_string(size));
      http::SetProblem(
          request, response, 416,
          "no requested range starts within the " + std::to_string(size) + " bytes of the level");
      return;
    case RangeAnswer::kPartial:
      response.status = 206;
      response.offset = resolved.first;
      response.length = resolved.last - resolved.first + 1;
      response.SetHeader("Content-Range", "bytes " + std::to_string(resolved.first) + "-" +
                                              std::to_string(resolved.last) + "/" +
                                              std::to_string(size));
      return;
  }
}

// Server-Sent Events of one job: a "progress" event per change, "done" at the end.
struct EventStream {
  Jobs* jobs = nullptr;
  std::string id;
  uint64_t version = 0;
  uint64_t sequence = 0;
  bool started = false, finished = false;
  std::chrono::steady_clock::time_point deadline;
};

bool WriteEvent(EventStream& state, http::StreamSink& sink, const api::JobStatus& status) {
  const bool terminal = status.state == "succeeded" || status.state == "failed";
  state.version = status.version;
  if (terminal) state.finished = true;
  return sink.Write("id: " + std::to_string(++state.sequence) + "\nevent: " +
                    (terminal ? "done" : "progress") + "\ndata: " + Dump(json(status)) + "\n\n");
}

bool NextEvent(EventStream& state, http::StreamSink& sink) {
  if (state.finished) return false;
  const auto now = std::chrono::steady_clock::now();
  if (!state.started) {
    state.started = true;
    auto status = state.jobs->Get(state.id);
    if (!status.ok()) return false;
    if (!sink.Write("retry: 2000\n\n")) return false;
    return WriteEvent(state, sink, status.value());
  }
  if (now >= state.deadline || state.jobs->draining()) return false;
  auto status = state.jobs->Wait(state.id, state.version, 1.0);
  if (!status.ok()) {
    (void)sink.Write("event: gone\ndata: {}\n\n");
    return false;
  }
  const bool terminal = status->state == "succeeded" || status->state == "failed";
  if (status->version != state.version || terminal) return WriteEvent(state, sink, status.value());
  // A comment each second without news: writing is how a client that is gone (reset, not
  // closed) is noticed, and its stream slot freed, within a second or two.
  return sink.Write(": keep-alive\n\n");
}

void ServeWebFile(const WebFile& file, const Request& request, Response& response) {
  response.SetHeader("ETag", file.etag);
  response.SetHeader("Cache-Control", file.cache_control);
  for (const auto& [name, value] : http::kViewerSecurityHeaders) response.SetHeader(name, value);
  if (auto match = request.Header("if-none-match"); match && MatchesEtag(*match, file.etag)) {
    response.status = 304;
    return;
  }
  response.status = 200;
  response.content_type = file.content_type;
  response.shared = file.bytes;
  response.offset = 0;
  response.length = file.bytes->size();
}

// One exact route per file listed at start-up ("/" is index.html); without them, "/"
// explains how to build the viewer.
void AddWebRoutes(http::Router& router, const WebAssets* web) {
  const WebFile* index = web != nullptr ? web->index() : nullptr;
  if (index == nullptr) {
    router.Add("GET", "/", Access::kPublic, [](Request& request, Response& response) {
      http::SetProblem(request, response, 404,
                       "the web viewer is not built: run `bash scripts/setup.sh` (it runs npm ci "
                       "and the Vite build into web/dist), or point web_root (--web-root, "
                       "MOTIONLODD_WEB_ROOT) at a built viewer; the API is under /v1");
    });
    return;
  }
  router.Add("GET", "/", Access::kPublic, [index](Request& request, Response& response) {
    ServeWebFile(*index, request, response);
  });
  for (const WebFile& file : web->files) {
    router.Add(
        "GET", file.url_path, Access::kPublic,
        [&file](Request& request, Response& response) { ServeWebFile(file, request, response); });
  }
}

}  // namespace

int HttpStatus(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kBadRequest:
      return 400;
    case ErrorKind::kNotFound:
      return 404;
    case ErrorKind::kConflict:
      return 409;
    case ErrorKind::kTooLarge:
      return 413;
    case ErrorKind::kUnsupportedMedia:
      return 415;
    case ErrorKind::kUnprocessable:
      return 422;
    case ErrorKind::kUnavailable:
      return 503;
    case ErrorKind::kInternal:
      return 500;
  }
  return 500;
}

http::Router MakeRouter(const RouteContext& context) {
  Service& service = *context.service;
  Characters& characters = service.characters();
  Motions& motions = service.motions();
  Bakes& bakes = service.bakes();
  Jobs& jobs = service.jobs();
  Levels& levels = service.levels();
  const Config& config = *context.config;
  http::Router router;

  router.Add("GET", "/healthz", Access::kPublic, [](Request&, Response& response) {
    response.SetJson(200, R"({"status":"ok"})");
    response.SetHeader("Cache-Control", "no-store");
  });
  router.Add("GET", "/readyz", Access::kPublic, [&service](Request& request, Response& response) {
    response.SetHeader("Cache-Control", "no-store");
    const Status ready = service.Ready();
    if (ready.ok()) return response.SetJson(200, R"({"status":"ready"})");
    response.SetHeader("Retry-After", "5");
    http::SetProblem(request, response, 503, ready.message());
  });
  router.Add("GET", "/metrics", Access::kRead, [&service, context](Request&, Response& response) {
    std::string text;
    context.render_http_metrics(text);
    service.RenderMetrics(text);
    text +=
        "# HELP motionlodd_open_streams SSE streams and long-polls open now.\n"
        "# TYPE motionlodd_open_streams gauge\nmotionlodd_open_streams " +
        std::to_string(context.open_streams->load()) + "\n";
    text +=
        "# HELP motionlodd_uploads_in_progress Upload bodies being received now.\n"
        "# TYPE motionlodd_uploads_in_progress gauge\nmotionlodd_uploads_in_progress " +
        std::to_string(context.open_uploads->load()) + "\n";
    response.status = 200;
    response.content_type = "text/plain; version=0.0.4; charset=utf-8";
    response.body = std::move(text);
    response.SetHeader("Cache-Control", "no-store");
  });
  router.Add("GET", "/v1/openapi.yaml", Access::kPublic, [](Request&, Response& response) {
    response.status = 200;
    response.content_type = "application/yaml";
    response.body = std::string(OpenApiYaml());
  });

  // Characters.
  router.Add("POST", "/v1/characters", Access::kWrite,
             [&characters, &config, context](Request& request, Response& response) {
               std::vector<io::SourceFile> files;
               if (!ReadUpload(request, response, config, context.open_uploads, files)) return;
               auto uploaded = characters.Upload(std::move(files));
               if (!uploaded.ok()) return Fail(request, response, uploaded.error());
               response.SetJson(uploaded->created ? 201 : 200, Dump(json(uploaded->value)));
               response.SetHeader("Location", "/v1/characters/" + uploaded->value.id);
             });
  router.Add("GET", "/v1/characters", Access::kRead,
             [&characters](Request& request, Response& response) {
               auto list = characters.List();
               if (!list.ok()) return Fail(request, response, list.error());
               response.SetJson(200, Dump(json{{"characters", list.value()}}));
             });
  router.Add("GET", "/v1/characters/{id}", Access::kRead,
             [&characters](Request& request, Response& response) {
               auto character = characters.Get(request.path_params[0]);
               if (!character.ok()) return Fail(request, response, character.error());
               response.SetJson(200, Dump(json(character.value())));
             });
  router.Add("DELETE", "/v1/characters/{id}", Access::kWrite,
             [&characters](Request& request, Response& response) {
               auto deleted = characters.Delete(request.path_params[0]);
               if (!deleted.ok()) return Fail(request, response, deleted.error());
               response.status = 204;
             });
  router.Add("GET", "/v1/characters/{id}/motions", Access::kRead,
             [&motions](Request& request, Response& response) {
               auto list = motions.List(request.path_params[0]);
               if (!list.ok()) return Fail(request, response, list.error());
               response.SetJson(200, Dump(json{{"motions", list.value()}}));
             });

  // Motions.
  router.Add(
      "POST", "/v1/motions", Access::kWrite,
      [&motions, &config, context](Request& request, Response& response) {
        const auto character = request.Query("character");
        if (!character) {
          return http::SetProblem(request, response, 400,
                                  "name the character the motion is for: ?character=ID");
        }
        const std::string character_id(*character);
        std::vector<io::SourceFile> files;
        if (!ReadUpload(request, response, config, context.open_uploads, files)) return;
        auto uploaded = motions.Upload(character_id, std::move(files));
        if (!uploaded.ok()) return Fail(request, response, uploaded.error());
        response.SetJson(uploaded->created ? 201 : 200, Dump(json{{"motions", uploaded->value}}));
      });
  router.Add("GET", "/v1/motions/{id}", Access::kRead,
             [&motions](Request& request, Response& response) {
               auto motion = motions.Get(request.path_params[0]);
               if (!motion.ok()) return Fail(request, response, motion.error());
               response.SetJson(200, Dump(json(motion.value())));
             });

  // Bakes.
  router.Add("POST", "/v1/bakes", Access::kWrite,
             [&bakes, &config](Request& request, Response& response) {
               const std::string type = Lower(request.Header("content-type").value_or(""));
               if (type != "application/json" && type.rfind("application/json;", 0) != 0) {
                 return http::SetProblem(request, response, 415,
                                         "send the bake request as Content-Type: application/json");
               }
               http::BodyResult body = request.read_body(config.max_json_bytes, 0);
               if (const auto* failure = std::get_if<http::BodyFailure>(&body)) {
                 return http::SetProblem(request, response,
                                         failure->error == http::BodyError::kTimeout     ? 408
                                         : failure->error == http::BodyError::kMalformed ? 400
                                                                                         : 413,
                                         failure->detail);
               }
               auto parsed = api::ParseBakeRequest(std::get<http::Body>(body).bytes);
               if (!parsed.ok())
                 return http::SetProblem(request, response, 400, parsed.status().message());
               auto submitted = bakes.Submit(*parsed);
               if (!submitted.ok()) return Fail(request, response, submitted.error());
               response.SetJson(submitted->created ? 202 : 200, Dump(json(submitted->value)));
               response.SetHeader("Location", "/v1/jobs/" + submitted->value.id);
             });
  router.Add("GET", "/v1/bakes", Access::kRead, [&bakes](Request& request, Response& response) {
    auto list = bakes.List(std::string(request.Query("character").value_or("")));
    if (!list.ok()) return Fail(request, response, list.error());
    response.SetJson(200, Dump(json{{"bakes", list.value()}}));
  });
  router.Add("GET", "/v1/bakes/{id}", Access::kRead,
             [&bakes](Request& request, Response& response) {
               auto bake = bakes.Get(request.path_params[0]);
               if (!bake.ok()) return Fail(request, response, bake.error());
               response.SetJson(200, Dump(json(bake.value())));
             });
  router.Add("DELETE", "/v1/bakes/{id}", Access::kWrite,
             [&bakes](Request& request, Response& response) {
               auto deleted = bakes.Delete(request.path_params[0]);
               if (!deleted.ok()) return Fail(request, response, deleted.error());
               response.status = 204;
             });
  router.Add("GET", "/v1/bakes/{id}/report", Access::kRead,
             [&bakes](Request& request, Response& response) {
               auto report = bakes.GetReport(request.path_params[0]);
               if (!report.ok()) return Fail(request, response, report.error());
               response.SetJson(200, report.value());
               response.SetHeader("Cache-Control", "public, max-age=3600");
             });
  router.Add("GET", "/v1/bakes/{id}/level", Access::kRead,
             [&levels](Request& request, Response& response) {
               const auto px_text = request.Query("px");
               if (!px_text) {
                 return http::SetProblem(request, response, 400,
                                         "give the character's on-screen height: ?px=PIXELS");
               }
               const auto px = ParseNumber(*px_text);
               if (!px)
                 return http::SetProblem(request, response, 400, "px must be a number (pixels)");
               double budget = 1.0;
               if (const auto budget_text = request.Query("budget")) {
                 const auto parsed = ParseNumber(*budget_text);
                 if (!parsed)
                   return http::SetProblem(request, response, 400,
                                           "budget must be a number (pixels)");
                 budget = *parsed;
               }
               std::string clip;
               if (!ReadClip(request, response, clip)) return;
               auto choice = levels.Choose(request.path_params[0], *px, budget, clip);
               if (!choice.ok()) return Fail(request, response, choice.error());
               response.SetHeader("Vary", "Accept");
               // A bake id names its content, so the choice for (bake, px, budget, clip) never
               // changes.
               response.SetHeader("Cache-Control", "public, max-age=86400");
               const std::string accept = Lower(request.Header("accept").value_or(""));
               if (accept.find("application/json") != std::string::npos) {
                 return response.SetJson(200, Dump(json(choice.value())));
               }
               response.status = 302;
               response.SetHeader("Location", choice->url);
             });

  // One level as glTF 2.0 binary (docs/EXPORT.md): the route the web viewer loads.
  router.Add(
      "GET", "/v1/bakes/{id}/levels/{file}", Access::kRead,
      [&levels](Request& request, Response& response) {
        constexpr std::string_view kSuffix = ".glb";
        const std::string_view file = request.path_params[1];
        const std::string_view stem =
            file.ends_with(kSuffix) ? file.substr(0, file.size() - kSuffix.size()) : "";
        Levels::GltfPick pick;
        if (proto::api::IsContentId(stem)) {
          pick.hash = stem;
        } else if (const std::optional<uint64_t> joints = ParseUnsigned(stem);
                   joints && *joints > 0 && *joints <= 65535) {
          pick.joints = static_cast<int>(*joints);
        } else {
          return http::SetProblem(request, response, 404,
                                  "a level is exported as /v1/bakes/{id}/levels/{joints}.glb "
                                  "(joints its kept count) or /v1/bakes/{id}/levels/{hash}.glb");
        }
        std::string clip;
        if (!ReadClip(request, response, clip)) return;
        auto gltf = levels.GetGltf(request.path_params[0], pick, clip);
        if (!gltf.ok()) return Fail(request, response, gltf.error());
        const std::string etag = "\"" + gltf->key + "\"";
        response.SetHeader("ETag", etag);
        // A bake id names its content; the export of its level changes only with the exporter.
        response.SetHeader("Cache-Control", "public, max-age=86400");
        if (auto match = request.Header("if-none-match"); match && MatchesEtag(*match, etag)) {
          response.status = 304;
          return;
        }
        response.content_type = "model/gltf-binary";
        response.length = gltf->glb->size();
        response.offset = 0;
        response.shared = std::move(gltf->glb);
        response.status = 200;
      });

  // Jobs.
  router.Add("GET", "/v1/jobs/{id}", Access::kRead,
             [&jobs, &config, context](Request& request, Response& response) {
               const std::string& id = request.path_params[0];
               auto status = jobs.Get(id);
               if (!status.ok()) return Fail(request, response, status.error());
               response.SetHeader("Cache-Control", "no-store");
               const auto wait_text = request.Query("wait");
               const bool terminal = status->state == "succeeded" || status->state == "failed";
               if (!wait_text || terminal) return response.SetJson(200, Dump(json(status.value())));
               const auto wait = ParseNumber(*wait_text);
               if (!wait || *wait < 0)
                 return http::SetProblem(request, response, 400,
                                         "wait must be a number of seconds >= 0");
               uint64_t after = status->version;
               if (const auto after_text = request.Query("after")) {
                 const auto parsed = ParseUnsigned(*after_text);
                 if (!parsed)
                   return http::SetProblem(request, response, 400,
                                           "after must be a job version (an integer)");
                 after = *parsed;
               }
               StreamSlot slot(context.open_streams, config.max_streams);
               if (!slot.acquired()) return RefuseStream(request, response, config.max_streams);
               auto waited = jobs.Wait(id, after, std::min(*wait, config.max_wait_seconds));
               if (!waited.ok()) return Fail(request, response, waited.error());
               response.SetJson(200, Dump(json(waited.value())));
             });
  router.Add(
      "GET", "/v1/jobs/{id}/events", Access::kRead,
      [&jobs, &config, context](Request& request, Response& response) {
        auto status = jobs.Get(request.path_params[0]);
        if (!status.ok()) return Fail(request, response, status.error());
        auto slot = std::make_shared<StreamSlot>(context.open_streams, config.max_streams);
        if (!slot->acquired()) return RefuseStream(request, response, config.max_streams);
        auto state = std::make_shared<EventStream>();
        state->jobs = &jobs;
        state->id = request.path_params[0];
        state->deadline =
            std::chrono::steady_clock::now() +
            std::chrono::milliseconds(static_cast<int64_t>(config.max_stream_seconds * 1000));
        response.status = 200;
        response.content_type = "text/event-stream";
        response.SetHeader("Cache-Control", "no-store");
        response.SetHeader("X-Accel-Buffering", "no");
        response.stream = [state](http::StreamSink& sink) { return NextEvent(*state, sink); };
        response.on_close = [slot] {};  // the slot lives as long as the response
      });

  // Levels.
  router.Add(
      "GET", "/v1/levels/{hash}", Access::kRead,
      [&levels](Request& request, Response& response) { ServeLevel(levels, request, response); });

  AddWebRoutes(router, context.web);
  return router;
}

}  // namespace motionlod::server
