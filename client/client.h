// The thin client of motionlodd: what a game or a pipeline script links against. Uploads
// characters and motions, requests bakes and waits for them with progress, reads level
// tables, and fetches levels through a local disk cache. Depends on proto/ and base/
// only (never on the daemon or the core); HTTP goes through client/http_connection.h.
//
// Errors are values (Result<T>, client/error.h); an answer of the daemon's that is an
// error carries its problem+json detail. 503 (queue full, draining, too many uploads)
// and connection failures are retried with exponential backoff, honouring Retry-After;
// every request of the API is safe to repeat (uploads and bakes are content-addressed).
//
// Not thread-safe: one Client per thread (each holds one keep-alive connection). The
// Level objects it returns are independent of it.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "client/error.h"
#include "client/http_connection.h"
#include "client/level.h"
#include "proto/api.h"

namespace motionlod::client {

struct RetryPolicy {
  int max_attempts = 6;                  // tries in all, >= 1
  double initial_backoff_seconds = 0.2;  // before the second try
  double backoff_multiplier = 2.0;       // each next wait, up to the maximum
  double max_backoff_seconds = 5.0;      // also caps a Retry-After of the daemon
};

// What a retry is about to wait for (ClientOptions::on_retry).
struct RetryEvent {
  int attempt = 0;       // the try that failed, from 1
  int http_status = 0;   // 503, or 0 for a connection failure
  double delay_seconds = 0;
  std::string reason;    // the problem's detail or the transport's message
};

struct ClientOptions {
  std::string base_url = "http://127.0.0.1:8080";
  std::string api_key;  // sent as "Authorization: Bearer KEY" when not empty
  double connect_timeout_seconds = 5;
  double read_timeout_seconds = 60;
  RetryPolicy retry;
  // Level files by content hash ("<hash>.mlod"); empty: no disk cache.
  std::filesystem::path cache_dir;
  std::function<void(const RetryEvent&)> on_retry;  // optional: observe retries
};

// A file to upload: its plain name (the extension picks the format) and its bytes.
struct UploadFile {
  std::string name;
  std::string bytes;
};
// Reads `path` into an UploadFile named by its file name.
Result<UploadFile> ReadUploadFile(const std::filesystem::path& path);

// Writes `bytes` to a temporary sibling of `path`, then renames it over `path` (creating
// the directory): readers see the old file or the whole new one, never a part.
std::optional<Error> WriteFileAtomically(const std::filesystem::path& path,
                                         std::span<const std::byte> bytes);

template <typename T>
struct Uploaded {
  T value;
  bool created = false;  // false: the daemon had this content already
};

// Called on each change of a job while waiting for it.
using ProgressCallback = std::function<void(const proto::api::JobStatus&)>;

// What FetchLevel did (the counters of a Client grow over its life).
struct FetchStats {
  int downloads = 0;     // level bodies received (200)
  int revalidated = 0;   // cached levels confirmed by 304 (no body)
  int cache_hits = 0;    // one clip's levels read from the cache without a request
  int cache_writes = 0;  // level files written to the cache
};

class Client {
 public:
  // kInvalidArgument for a malformed URL, timeouts or retry policy.
  static Result<Client> Create(ClientOptions options);
  Client(Client&&) noexcept;
  Client& operator=(Client&&) noexcept;
  ~Client();

  // POST /v1/characters: one file as the raw body, several (a .gltf and its .bin) as
  // multipart parts, the first being the model file.
  Result<Uploaded<proto::api::CharacterInfo>> UploadCharacter(const std::vector<UploadFile>& files);
  // POST /v1/motions?character=ID: every animation of the file, retargeted.
  Result<Uploaded<std::vector<proto::api::MotionInfo>>> UploadMotion(
      const std::string& character_id, const std::vector<UploadFile>& files);
  Result<proto::api::CharacterInfo> GetCharacter(const std::string& id);

  // POST /v1/bakes: the bake's job (queued, or already finished for a known request).
  Result<proto::api::JobStatus> SubmitBake(const proto::api::BakeRequest& request);
  Result<proto::api::JobStatus> GetJob(const std::string& job_id);
  // Waits until the job is finished, calling `progress` on each change (long-polls of
  // GET /v1/jobs/{id}?wait=&after=), then returns the bake with its level table.
  // kJobFailed with the bake's message when it failed; kConnection when
  // `timeout_seconds` (> 0) passed first.
  Result<proto::api::BakeInfo> WaitForBake(const std::string& job_id,
                                           const ProgressCallback& progress = {},
                                           double timeout_seconds = 0);
  Result<proto::api::BakeInfo> GetBake(const std::string& bake_id);

  // The daemon's choice for a character `px` pixels tall (GET /v1/bakes/{id}/level as
  // JSON), by the figures over every clip; `clip` (an animation name of the bake) puts
  // ?clip= in the choice's url. LevelSelector makes the same choice locally, with
  // hysteresis.
  Result<proto::api::LevelChoice> ChooseLevel(const std::string& bake_id, double px,
                                              double budget_px = 1.0, const std::string& clip = "");
  // GET /v1/levels/{hash}, through the disk cache: a cached file is revalidated with
  // If-None-Match (304: nothing is downloaded again), a new one is stored atomically.
  // With `clip` (an animation name of the bake): ?clip=, the level with only that clip's
  // frames; its cached file (clip names up to 64 bytes) is used without asking the
  // daemon, since what the URL names never changes.
  Result<Level> FetchLevel(const std::string& hash, const std::string& clip = "");

  const FetchStats& fetch_stats() const { return fetch_stats_; }
  const ClientOptions& options() const { return options_; }

 private:
  Client(ClientOptions options, std::unique_ptr<HttpConnection> connection);
  // Sends with the key, retrying 503 and connection failures per the policy.
  Result<HttpResponse> Send(HttpRequest request);
  // Sends, then the reply when its status is one of `expected` and its Error otherwise
  // (`what` names the request in the message).
  Result<HttpResponse> SendExpecting(HttpRequest request, std::initializer_list<int> expected,
                                     const std::string& what);
  template <typename T>
  Result<T> Call(HttpRequest request, std::initializer_list<int> expected);
  Result<Level> FetchClipLevel(const std::string& hash, const std::string& clip);

  ClientOptions options_;
  std::unique_ptr<HttpConnection> connection_;
  FetchStats fetch_stats_;
};

// The error of a daemon's answer: its problem+json body, or one made from the status
// when the body is something else (a proxy's page).
Error ErrorFromResponse(const HttpResponse& response, const std::string& what);

}  // namespace motionlod::client
