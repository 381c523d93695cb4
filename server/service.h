// The daemon's service: characters, motions, bakes, jobs and levels, on top of the store,
// the blob directory, the job queue and the level cache. It knows nothing of HTTP: it
// takes and returns proto::api DTOs, and its errors are kinds (not found, too large, ...)
// that the HTTP layer maps to status codes.
//
// Ids (all ^[0-9a-f]{64}$, checked before any lookup):
//   character = SHA-256 of the uploaded bytes (one file), or of the sorted list of
//               "name NUL sha256" lines of its parts (several files);
//   motion    = SHA-256 of (character, source upload id, animation name);
//   bake = job = SHA-256 of the resolved request, the solver settings hash and
//               core::kAlgorithmVersion (BakeKey), so the same request is the same bake;
//   level     = SHA-256 of the one-level file (proto::ExtractLevel).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <string>
#include <vector>

#include "base/expected.h"
#include "io/asset.h"
#include "pipeline/bake.h"
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

// The canonical text a bake id hashes, and the SHA-256 of the inputs stored in the
// level set (LevelSetData::source_hash). Exposed for tests that bake in-process.
struct BakeKey {
  std::string id;
  std::array<uint8_t, 32> source_hash{};
};
BakeKey MakeBakeKey(const proto::api::BakeRequest& resolved, const std::string& motion_source_id,
                    const std::string& animation, uint64_t settings_hash);

// The pipeline request the daemon bakes for a resolved API request (without assets).
pipeline::BakeRequest MakePipelineRequest(const proto::api::BakeRequest& resolved,
                                          const std::string& animation, int bake_threads);

// Id of an upload: SHA-256 of the one file, or of its parts' sorted (name, sha256) list.
std::string UploadId(const std::vector<io::SourceFile>& files);

class Service {
 public:
  static StatusOr<std::unique_ptr<Service>> Open(const Config& config);
  ~Service();

  // Requeues the jobs a crash or a shutdown left unfinished and starts the workers.
  Status Start();
  // Stops taking jobs, lets running bakes finish for up to drain_seconds, then stops them
  // (they stay queued in the store and run again at the next start).
  void Shutdown();
  // Refuses new bakes and ends long-polls and event streams (before the HTTP server
  // stops, so that its connection threads are free to finish).
  void BeginDrain();
  bool draining() const { return draining_.load(); }

  // files[0] is the main file; the others are what it references.
  Result<Created<proto::api::CharacterInfo>> UploadCharacter(std::vector<io::SourceFile> files);
  Result<proto::api::CharacterInfo> GetCharacter(const std::string& id);
  Result<std::vector<proto::api::CharacterInfo>> ListCharacters();
  Result<Done> DeleteCharacter(const std::string& id);

  // A motion file: each of its animations retargeted onto the character (validation)
  // and registered as a motion of it.
  Result<Created<std::vector<proto::api::MotionInfo>>> UploadMotion(
      const std::string& character_id, std::vector<io::SourceFile> files);
  Result<proto::api::MotionInfo> GetMotion(const std::string& id);
  Result<std::vector<proto::api::MotionInfo>> ListMotions(const std::string& character_id);

  Result<Created<proto::api::JobStatus>> SubmitBake(const proto::api::BakeRequest& request);
  Result<proto::api::JobStatus> GetJob(const std::string& id);
  // Returns once the job's version exceeds `after_version`, it is finished, `seconds`
  // passed, or the daemon drains.
  Result<proto::api::JobStatus> WaitJob(const std::string& id, uint64_t after_version,
                                        double seconds);
  Result<proto::api::BakeInfo> GetBake(const std::string& id);
  Result<std::vector<proto::api::BakeInfo>> ListBakes(const std::string& character_id);
  Result<std::string> GetReport(const std::string& bake_id);  // report.json text
  Result<Done> DeleteBake(const std::string& id);

  // core::SelectLevel on the bake's level table for a character `px` pixels tall.
  Result<proto::api::LevelChoice> ChooseLevel(const std::string& bake_id, double px,
                                              double budget_px);
  // The one-level file of that hash (served from the cache when hot).
  Result<LevelCache::Bytes> GetLevel(const std::string& hash);

  // The level of a bake that keeps `joints` joints as glTF 2.0 binary (docs/EXPORT.md),
  // exported from the stored character on the first request and then served from the
  // level cache under `key`, the SHA-256 of what it is made of (an ETag).
  struct GltfFile {
    LevelCache::Bytes glb;
    std::string key;
  };
  Result<GltfFile> GetLevelGltf(const std::string& bake_id, int joints);

  bool Ready();
  // Queue, jobs, bakes and cache metrics in Prometheus text.
  void RenderMetrics(std::string& out);

 private:
  struct LiveJob {
    JobRecord record;
    uint64_t version = 0;
    std::shared_ptr<std::atomic<bool>> cancel = std::make_shared<std::atomic<bool>>(false);
  };
  struct LevelTable {
    std::vector<double> max_error_fraction;  // finest first
    std::vector<proto::api::LevelEntry> entries;
  };

  explicit Service(const Config& config);
  void RunJob(const std::string& id);
  // Stores the levels and commits the bake; `written` receives the blobs it wrote.
  Status FinishBake(const BakeRecord& bake, pipeline::BakeOutput output, JobRecord& job,
                    std::vector<std::string>& written);
  void Publish(const JobRecord& record, bool erase = false);  // board update + notify
  StatusOr<std::shared_ptr<const io::Asset>> LoadSource(const std::string& source_id,
                                                        const std::vector<FileRecord>& files);
  void CacheAsset(const std::string& source_id, std::shared_ptr<const io::Asset> asset);
  StatusOr<std::shared_ptr<const LevelTable>> GetLevelTable(const BakeRecord& bake);
  // The bake record of a bake that has levels (an id checked first; 404, or 409 while its
  // job has not succeeded).
  Result<BakeRecord> BakeWithLevels(const std::string& bake_id);
  Result<proto::api::JobStatus> JobFromStore(const std::string& id);
  proto::api::JobStatus ToStatus(const JobRecord& record, uint64_t version) const;
  Result<proto::api::BakeInfo> ToBakeInfo(const BakeRecord& bake);
  void CollectBlobs(const std::vector<std::string>& blobs);
  // Stops the job of a bake whose rows are deleted and drops its cached level table.
  void ForgetBake(const std::string& id);
  // Imports uploaded files in the sandboxed worker (never in this process).
  StatusOr<std::shared_ptr<const io::Asset>> Import(const std::vector<io::SourceFile>& files);
  Status StoreFiles(const std::vector<io::SourceFile>& files, std::vector<FileRecord>& records);

  const Config config_;
  std::unique_ptr<Store> store_;
  std::unique_ptr<BlobStore> blobs_;
  std::unique_ptr<ImportSandbox> importer_;
  LevelCache cache_;
  std::unique_ptr<JobQueue> queue_;
  std::atomic<bool> draining_{false};
  std::atomic<bool> stopping_{false};

  std::mutex board_mutex_;
  std::condition_variable board_changed_;
  std::map<std::string, LiveJob> board_;  // jobs queued or running in this process
  uint64_t next_version_ = 1;

  std::mutex assets_mutex_;
  std::list<std::pair<std::string, std::shared_ptr<const io::Asset>>> assets_;  // small LRU

  std::mutex tables_mutex_;
  std::map<std::string, std::shared_ptr<const LevelTable>> tables_;

  // Writers hold it shared from writing blobs to committing the rows that name them;
  // CollectBlobs holds it exclusively from checking references to removing files, so a
  // blob is never removed between being written and being named.
  std::shared_mutex blobs_mutex_;

  std::atomic<int> imports_{0};
  Histogram bake_seconds_;
  std::atomic<uint64_t> bakes_succeeded_{0}, bakes_failed_{0}, bakes_interrupted_{0};
};

}  // namespace motionlod::server
