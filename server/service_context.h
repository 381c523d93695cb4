// What the parts of the daemon's service (characters, motions, bakes, jobs, levels) share:
// the kinds of error they answer with, which the HTTP layer maps to status codes, and the
// ServiceContext of resources they all work on. Nothing here knows HTTP.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <string>
#include <utility>
#include <vector>

#include "base/expected.h"
#include "base/status.h"
#include "io/asset.h"
#include "proto/api.h"
#include "server/blob_store.h"
#include "server/config.h"
#include "server/import_sandbox.h"
#include "server/job_queue.h"
#include "server/level_cache.h"
#include "server/metrics.h"
#include "server/store.h"

namespace motionlod::server {

enum class ErrorKind {
  kBadRequest,        // malformed input
  kNotFound,          // no such id
  kConflict,          // the resource is not in a state that allows this (bake not finished)
  kTooLarge,          // an upload over the limits
  kUnsupportedMedia,  // a file type the importer does not take
  kUnprocessable,     // well-formed but unusable (import failed, unknown animation, ...)
  kUnavailable,       // busy: retry after retry_after_seconds
  kInternal,
};

struct ServiceError {
  ErrorKind kind = ErrorKind::kInternal;
  std::string detail;
  int retry_after_seconds = 0;
};

// A value or the ServiceError that explains why there is none.
template <typename T>
using Result = Expected<T, ServiceError>;

template <typename T>
struct Created {
  T value;
  bool created = false;  // false: it existed already (same content, same id)
};
struct Done {};

ServiceError Error(ErrorKind kind, std::string detail, int retry_after = 0);

// An internal error: logged with its message, answered without it.
// An internal failure as the client sees it: 503 with kStorageFaultDetail when the data
// directory failed (kUnavailable), else a 500 pointing at the log (where the message goes).
ServiceError Internal(const Status& status);
// What a client is told of a storage fault: no server path, and what to do.
inline constexpr const char* kStorageFaultDetail =
    "the daemon's storage cannot be written now (a full or read-only data directory, or its "
    "Redis not answering); retry later";

// The 404 for an id that cannot name anything (not 64 lower-case hex digits), answered
// before any lookup.
ServiceError MalformedId(const std::string& what);

// The record that `get`, a Store getter, finds under `id` (a character, motion, bake or
// job): 404 for an id that is malformed or names nothing, 500 when the store fails.
template <typename Record>
Result<Record> FindRecord(Store& store,
                          StatusOr<std::optional<Record>> (Store::*get)(const std::string&),
                          const std::string& what, const std::string& id) {
  if (!proto::api::IsContentId(id)) return MalformedId(what);
  auto record = (store.*get)(id);
  if (!record.ok()) return Internal(record.status());
  if (!record->has_value()) return Error(ErrorKind::kNotFound, "no " + what + " " + id);
  return std::move(**record);
}

// Milliseconds since the Unix epoch, and their RFC 3339 text in UTC ("" for 0).
int64_t NowMs();
std::string Rfc3339(int64_t ms);

// The last few imported assets by source id (the id of the upload they come from), most
// recently used first, so that bakes of one character import it once. Thread-safe.
class AssetCache {
 public:
  // The asset, or null.
  std::shared_ptr<const io::Asset> Get(const std::string& source_id);
  void Put(const std::string& source_id, std::shared_ptr<const io::Asset> asset);
  void Erase(const std::string& source_id);

 private:
  std::mutex mutex_;
  std::list<std::pair<std::string, std::shared_ptr<const io::Asset>>> entries_;
};

// What the bake workers count for /metrics.
struct BakeMetrics {
  Histogram seconds{BakeBounds()};  // wall time of successful bakes
  std::atomic<uint64_t> succeeded{0}, failed{0}, interrupted{0};
};

// The resources every part of the service works on. Service owns it (and opens the store,
// the blob directory and the importer); each part holds a reference.
struct ServiceContext {
  explicit ServiceContext(const Config& config) : config(config), cache(config.cache_bytes) {}

  // Imports uploaded files in the sandboxed worker (never in this process).
  StatusOr<std::shared_ptr<const io::Asset>> Import(const std::vector<io::SourceFile>& files);
  // The asset of a stored upload: cached, or imported again from its blobs.
  StatusOr<std::shared_ptr<const io::Asset>> LoadSource(const std::string& source_id,
                                                        const std::vector<FileRecord>& files);
  // Writes the files as blobs and appends their records (under blobs_mutex, shared).
  Status StoreFiles(const std::vector<io::SourceFile>& files, std::vector<FileRecord>& records);
  // Removes the blobs of `hashes` that no row names any more, and their cached levels.
  void CollectBlobs(const std::vector<std::string>& hashes);

  const Config config;
  std::unique_ptr<Store> store;
  std::unique_ptr<BlobStore> blobs;
  // Makes the job queue Jobs::Start drains (a MemoryJobQueue, or a RedisJobQueue that the
  // daemons on one Redis share).
  std::function<StatusOr<std::unique_ptr<JobQueue>>(size_t capacity, int workers,
                                                     JobQueue::Runner run)>
      make_queue;
  std::unique_ptr<ImportSandbox> importer;
  LevelCache cache;
  AssetCache assets;

  // Writers hold it shared from writing blobs to committing the rows that name them;
  // CollectBlobs holds it exclusively from checking references to removing files, so a
  // blob is never removed between being written and being named.
  std::shared_mutex blobs_mutex;

  std::atomic<int> imports{0};  // uploads being imported now
  BakeMetrics bake_metrics;
};

}  // namespace motionlod::server
