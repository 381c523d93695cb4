#include "client/client.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>
#include <system_error>
#include <thread>

namespace motionlod::client {
namespace {

namespace api = proto::api;
namespace fs = std::filesystem;
using nlohmann::json;

Error MakeError(ErrorKind kind, std::string message) {
  return Error{kind, 0, std::nullopt, std::move(message)};
}

// A reply body as a T, or kDataLoss naming the request (`what`).
template <typename T>
Result<T> ParseBody(const std::string& body, const std::string& what) {
  auto parsed = api::ParseReply<T>(body);
  if (!parsed.ok()) return MakeError(ErrorKind::kDataLoss, what + ": " + parsed.status().message());
  return std::move(*parsed);
}

std::string FormatNumber(double value) {
  std::ostringstream text;
  text.precision(17);
  text << value;
  return text.str();
}

// Ids go into paths: only well-formed ones are sent (and named in the error otherwise).
std::optional<Error> CheckId(std::string_view what, const std::string& id) {
  if (api::IsContentId(id)) return std::nullopt;
  return MakeError(ErrorKind::kInvalidArgument,
                   std::string(what) + " id must be 64 lower-case hex digits, got '" +
                       id.substr(0, 80) + "'");
}

bool Terminal(const api::JobStatus& job) {
  return job.state == "succeeded" || job.state == "failed";
}

// The level cache: <dir>/<hash>.mlod, and <dir>/<hash>.<clip's name in hex>.mlod for one
// clip's frames of it. Entries are immutable (named by their content) and written
// atomically, so a reader never sees a partial file.
fs::path CachePath(const fs::path& dir, const std::string& hash) { return dir / (hash + ".mlod"); }

// A clip's name longer than this is not cached (its file name would be too long).
constexpr size_t kMaxCachedClipNameBytes = 64;

fs::path ClipCachePath(const fs::path& dir, const std::string& hash, std::string_view clip) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string name = hash + ".";
  for (const unsigned char c : clip) {
    name += kHex[c >> 4];
    name += kHex[c & 15];
  }
  return dir / (name + ".mlod");
}

std::optional<std::string> ReadCached(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return std::nullopt;
  return bytes;
}

}  // namespace

const char* ErrorKindName(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kConnection:
      return "connection";
    case ErrorKind::kHttp:
      return "http";
    case ErrorKind::kInvalidArgument:
      return "invalid_argument";
    case ErrorKind::kDataLoss:
      return "data_loss";
    case ErrorKind::kIo:
      return "io";
    case ErrorKind::kJobFailed:
      return "job_failed";
  }
  return "unknown";
}

std::string Error::ToString() const { return std::string(ErrorKindName(kind)) + ": " + message; }

Error ErrorFromResponse(const HttpResponse& response, const std::string& what) {
  Error error{ErrorKind::kHttp, response.status, std::nullopt, ""};
  const std::string type(response.Header("content-type").value_or(""));
  auto problem = type.rfind("application/problem+json", 0) == 0
                     ? api::ParseReply<api::Problem>(response.body)
                     : StatusOr<api::Problem>(DataLoss("not problem+json"));
  if (problem.ok()) {
    error.problem = std::move(*problem);
  } else {
    // Not the daemon's own answer (a proxy, a load balancer): keep what can be said.
    error.problem = api::Problem{"about:blank", "HTTP " + std::to_string(response.status),
                                 response.status, response.body.substr(0, 200), "", ""};
  }
  error.message = what + ": HTTP " + std::to_string(response.status) + " " + error.problem->title;
  if (!error.problem->detail.empty()) error.message += ": " + error.problem->detail;
  return error;
}

std::optional<Error> WriteFileAtomically(const fs::path& path, std::span<const std::byte> bytes) {
  std::error_code error;
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  fs::create_directories(dir, error);
  if (error) return MakeError(ErrorKind::kIo, dir.string() + ": " + error.message());
  thread_local std::mt19937_64 random{std::random_device{}()};
  const fs::path temporary =
      dir / ("." + path.filename().string() + ".tmp." + std::to_string(random()));
  std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (out) fs::rename(temporary, path, error);
  if (!out || error) {
    std::error_code ignored;
    fs::remove(temporary, ignored);
    return MakeError(ErrorKind::kIo, "cannot write " + path.string() +
                                         (error ? ": " + error.message() : std::string()));
  }
  return std::nullopt;
}

Result<UploadFile> ReadUploadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return MakeError(ErrorKind::kIo, "cannot read " + path.string());
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return MakeError(ErrorKind::kIo, "cannot read " + path.string());
  return UploadFile{path.filename().string(), std::move(bytes)};
}

Client::Client(ClientOptions options, std::unique_ptr<HttpConnection> connection)
    : options_(std::move(options)), connection_(std::move(connection)) {}
Client::Client(Client&&) noexcept = default;
Client& Client::operator=(Client&&) noexcept = default;
Client::~Client() = default;

Result<Client> Client::Create(ClientOptions options) {
  const RetryPolicy& retry = options.retry;
  if (retry.max_attempts < 1 || !(retry.initial_backoff_seconds >= 0) ||
      !(retry.backoff_multiplier >= 1) || !(retry.max_backoff_seconds >= 0) ||
      !std::isfinite(retry.max_backoff_seconds) || !std::isfinite(retry.initial_backoff_seconds)) {
    return MakeError(ErrorKind::kInvalidArgument,
                     "retry policy: max_attempts >= 1, backoffs finite and >= 0, multiplier >= 1");
  }
  ConnectionOptions connection_options;
  connection_options.base_url = options.base_url;
  connection_options.connect_timeout_seconds = options.connect_timeout_seconds;
  connection_options.read_timeout_seconds = options.read_timeout_seconds;
  connection_options.write_timeout_seconds = options.read_timeout_seconds;
  auto connection = HttpConnection::Open(connection_options);
  if (!connection.ok()) return connection.error();
  return Client(std::move(options), std::move(*connection));
}

Result<HttpResponse> Client::Send(HttpRequest request) {
  if (!options_.api_key.empty())
    request.headers.emplace_back("Authorization", "Bearer " + options_.api_key);
  const RetryPolicy& policy = options_.retry;
  double backoff = policy.initial_backoff_seconds;
  for (int attempt = 1;; ++attempt) {
    Result<HttpResponse> response = connection_->Send(request);
    const bool unavailable = response.ok() && response->status == 503;
    const bool unreachable = !response.ok() && response.error().kind == ErrorKind::kConnection;
    if ((!unavailable && !unreachable) || attempt >= policy.max_attempts) return response;
    RetryEvent event{attempt, unavailable ? 503 : 0, backoff, ""};
    if (unavailable) {
      // The daemon says when it expects room (whole seconds); capped by the policy.
      if (auto after = response->Header("retry-after")) {
        double seconds = 0;
        std::istringstream(std::string(*after)) >> seconds;
        if (seconds > 0) event.delay_seconds = std::max(backoff, seconds);
      }
      event.reason = ErrorFromResponse(*response, request.method + " " + request.target).message;
    } else {
      event.reason = response.error().message;
    }
    event.delay_seconds = std::min(event.delay_seconds, policy.max_backoff_seconds);
    if (options_.on_retry) options_.on_retry(event);
    std::this_thread::sleep_for(std::chrono::duration<double>(event.delay_seconds));
    backoff = std::min(backoff * policy.backoff_multiplier, policy.max_backoff_seconds);
  }
}

Result<HttpResponse> Client::SendExpecting(HttpRequest request, std::initializer_list<int> expected,
                                           const std::string& what) {
  Result<HttpResponse> response = Send(std::move(request));
  if (!response.ok()) return response;
  if (std::find(expected.begin(), expected.end(), response->status) == expected.end()) {
    return ErrorFromResponse(*response, what);
  }
  return response;
}

template <typename T>
Result<T> Client::Call(HttpRequest request, std::initializer_list<int> expected) {
  const std::string what = request.method + " " + request.target;
  Result<HttpResponse> response = SendExpecting(std::move(request), expected, what);
  if (!response.ok()) return response.error();
  return ParseBody<T>(response->body, what);
}

namespace {

// The upload request for `files` at `target` (query without the filename).
std::optional<Error> BuildUpload(const std::vector<UploadFile>& files, std::string target,
                                 HttpRequest& request) {
  if (files.empty()) return MakeError(ErrorKind::kInvalidArgument, "nothing to upload");
  for (const UploadFile& file : files) {
    if (file.name.empty() || file.name.find('/') != std::string::npos) {
      return MakeError(ErrorKind::kInvalidArgument,
                       "upload file names must be plain names, got '" + file.name + "'");
    }
  }
  request.method = "POST";
  if (files.size() == 1) {
    const char separator = target.find('?') == std::string::npos ? '?' : '&';
    request.target = target + separator + "filename=" + api::EncodeQueryValue(files[0].name);
    request.content_type = "application/octet-stream";
    request.body = files[0].bytes;
    return std::nullopt;
  }
  request.target = std::move(target);
  for (size_t f = 0; f < files.size(); ++f) {
    request.parts.push_back({f == 0 ? "file" : "part" + std::to_string(f), files[f].name,
                             files[f].bytes});
  }
  return std::nullopt;
}

}  // namespace

Result<Uploaded<api::CharacterInfo>> Client::UploadCharacter(const std::vector<UploadFile>& files) {
  HttpRequest request;
  if (auto error = BuildUpload(files, "/v1/characters", request)) return *error;
  const std::string what = "POST /v1/characters";
  Result<HttpResponse> response = SendExpecting(std::move(request), {200, 201}, what);
  if (!response.ok()) return response.error();
  auto character = ParseBody<api::CharacterInfo>(response->body, what);
  if (!character.ok()) return character.error();
  return Uploaded<api::CharacterInfo>{std::move(*character), response->status == 201};
}

Result<Uploaded<std::vector<api::MotionInfo>>> Client::UploadMotion(
    const std::string& character_id, const std::vector<UploadFile>& files) {
  if (auto error = CheckId("character", character_id)) return *error;
  HttpRequest request;
  if (auto error = BuildUpload(files, "/v1/motions?character=" + character_id, request))
    return *error;
  const std::string what = "POST /v1/motions";
  Result<HttpResponse> response = SendExpecting(std::move(request), {200, 201}, what);
  if (!response.ok()) return response.error();
  const json body = json::parse(response->body, nullptr, /*allow_exceptions=*/false);
  if (!body.is_object() || !body.contains("motions"))
    return MakeError(ErrorKind::kDataLoss, what + ": the reply has no 'motions' list");
  auto motions = ParseBody<std::vector<api::MotionInfo>>(body["motions"].dump(), what);
  if (!motions.ok()) return motions.error();
  return Uploaded<std::vector<api::MotionInfo>>{std::move(*motions), response->status == 201};
}

Result<api::CharacterInfo> Client::GetCharacter(const std::string& id) {
  if (auto error = CheckId("character", id)) return *error;
  return Call<api::CharacterInfo>({"GET", "/v1/characters/" + id, {}, "", "", {}}, {200});
}

Result<api::JobStatus> Client::SubmitBake(const api::BakeRequest& bake) {
  if (auto error = CheckId("character", bake.character)) return *error;
  json body = bake;
  // Only what the caller set: the daemon fills in the defaults (and resolves the motion).
  if (bake.motion.empty()) body.erase("motion");
  if (bake.clips.empty()) body.erase("clips");
  return Call<api::JobStatus>(
      {"POST", "/v1/bakes", {}, "application/json", body.dump(), {}}, {200, 202});
}

Result<api::JobStatus> Client::GetJob(const std::string& job_id) {
  if (auto error = CheckId("job", job_id)) return *error;
  return Call<api::JobStatus>({"GET", "/v1/jobs/" + job_id, {}, "", "", {}}, {200});
}

Result<api::BakeInfo> Client::WaitForBake(const std::string& job_id,
                                          const ProgressCallback& progress,
                                          double timeout_seconds) {
  using Clock = std::chrono::steady_clock;
  const auto deadline =
      timeout_seconds > 0 ? Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double>(timeout_seconds))
                          : Clock::time_point::max();
  Result<api::JobStatus> job = GetJob(job_id);
  if (!job.ok()) return job.error();
  if (progress) progress(*job);
  // Long-polls end at the daemon's max_wait_seconds (30 by default): a shorter wait keeps
  // each request well inside the read timeout.
  const double wait = std::clamp(options_.read_timeout_seconds / 2, 1.0, 20.0);
  while (!Terminal(*job)) {
    if (Clock::now() >= deadline) {
      return MakeError(ErrorKind::kConnection,
                       "job " + job_id + " did not finish within " + FormatNumber(timeout_seconds) +
                           " s (state " + job->state + ")");
    }
    const uint64_t seen = job->version;
    job = Call<api::JobStatus>({"GET",
                                "/v1/jobs/" + job_id + "?wait=" + FormatNumber(wait) +
                                    "&after=" + std::to_string(seen),
                                {}, "", "", {}},
                               {200});
    if (!job.ok()) return job.error();
    if (progress && job->version != seen) progress(*job);
  }
  if (job->state == "failed") {
    const api::JobError failure = job->error.value_or(api::JobError{"internal", "no detail"});
    Error error{ErrorKind::kJobFailed, 0,
                api::Problem{"urn:motionlod:problem:" + failure.code, "bake failed", 0,
                             failure.detail, "/v1/jobs/" + job_id, ""},
                "bake " + job->bake + " failed (" + failure.code + "): " + failure.detail};
    return error;
  }
  return GetBake(job->bake);
}

Result<api::BakeInfo> Client::GetBake(const std::string& bake_id) {
  if (auto error = CheckId("bake", bake_id)) return *error;
  return Call<api::BakeInfo>({"GET", "/v1/bakes/" + bake_id, {}, "", "", {}}, {200});
}

Result<api::LevelChoice> Client::ChooseLevel(const std::string& bake_id, double px,
                                             double budget_px, const std::string& clip) {
  if (auto error = CheckId("bake", bake_id)) return *error;
  if (!std::isfinite(px) || !std::isfinite(budget_px)) {
    return MakeError(ErrorKind::kInvalidArgument, "px and budget must be finite numbers");
  }
  return Call<api::LevelChoice>({"GET",
                                 "/v1/bakes/" + bake_id + "/level?px=" + FormatNumber(px) +
                                     "&budget=" + FormatNumber(budget_px) +
                                     (clip.empty() ? "" : "&clip=" + api::EncodeQueryValue(clip)),
                                 {{"Accept", "application/json"}},
                                 "",
                                 "",
                                 {}},
                                {200});
}

Result<Level> Client::FetchLevel(const std::string& hash, const std::string& clip) {
  if (auto error = CheckId("level", hash)) return *error;
  if (!clip.empty()) return FetchClipLevel(hash, clip);
  const bool caching = !options_.cache_dir.empty();
  std::optional<std::string> cached;
  if (caching) cached = ReadCached(CachePath(options_.cache_dir, hash));
  HttpRequest request{"GET", "/v1/levels/" + hash, {}, "", "", {}};
  if (cached) request.headers.emplace_back("If-None-Match", "\"" + hash + "\"");
  const std::string what = request.method + " " + request.target;
  Result<HttpResponse> response = Send(request);
  if (!response.ok()) return response.error();
  if (response->status == 304 && cached) {
    ++fetch_stats_.revalidated;
    Result<Level> level = Level::Decode(std::move(*cached));
    if (level.ok()) return level;
    // A damaged cache file: drop it and download the level again, unconditionally.
    std::error_code ignored;
    fs::remove(CachePath(options_.cache_dir, hash), ignored);
    request.headers.clear();
    response = Send(request);
    if (!response.ok()) return response.error();
  }
  if (response->status != 200) return ErrorFromResponse(*response, what);
  ++fetch_stats_.downloads;
  Result<Level> level = Level::Decode(std::move(response->body));
  if (!level.ok()) return MakeError(ErrorKind::kDataLoss, what + ": " + level.error().message);
  // Only a level that decoded (checksum included) enters the cache.
  if (caching) {
    if (auto error = WriteFileAtomically(CachePath(options_.cache_dir, hash), level->level_set().bytes()))
      return *error;
    ++fetch_stats_.cache_writes;
  }
  return level;
}

Result<Level> Client::FetchClipLevel(const std::string& hash, const std::string& clip) {
  const bool caching = !options_.cache_dir.empty() && clip.size() <= kMaxCachedClipNameBytes;
  const fs::path path = caching ? ClipCachePath(options_.cache_dir, hash, clip) : fs::path();
  if (caching) {
    if (std::optional<std::string> cached = ReadCached(path)) {
      Result<Level> level = Level::Decode(std::move(*cached));
      if (level.ok()) {
        ++fetch_stats_.cache_hits;
        return level;
      }
      std::error_code ignored;  // damaged on disk: download it again
      fs::remove(path, ignored);
    }
  }
  const std::string what = "GET /v1/levels/" + hash + "?clip=" + clip;
  Result<HttpResponse> response = SendExpecting(
      {"GET", "/v1/levels/" + hash + "?clip=" + api::EncodeQueryValue(clip), {}, "", "", {}}, {200},
      what);
  if (!response.ok()) return response.error();
  ++fetch_stats_.downloads;
  Result<Level> level = Level::Decode(std::move(response->body));
  if (!level.ok()) return MakeError(ErrorKind::kDataLoss, what + ": " + level.error().message);
  if (caching) {
    if (auto error = WriteFileAtomically(path, level->level_set().bytes())) return *error;
    ++fetch_stats_.cache_writes;
  }
  return level;
}

}  // namespace motionlod::client
