#include "server/service.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <set>

#include "server/directory_blob_store.h"
#include "server/memory_job_queue.h"
#include "server/redis_job_queue.h"
#include "server/redis_store.h"
#include "server/sqlite_store.h"

namespace motionlod::server {
namespace {

// The store, the blob store and the job queue the configuration names.
Status OpenStorage(const Config& config, ServiceContext& context) {
  const std::filesystem::path blob_dir = config.blob_dir.empty()
                                             ? std::filesystem::path(config.data_dir) / "blobs"
                                             : std::filesystem::path(config.blob_dir);
  std::shared_ptr<RedisPool> redis;
  if (config.backend == "redis") {
    auto endpoint = ParseRedisUrl(config.redis_url);
    if (!endpoint.ok()) return endpoint.status();
    redis = std::make_shared<RedisPool>(*endpoint, config.redis_timeout_seconds);
    context.store = std::make_unique<RedisStore>(redis, config.redis_prefix);
    context.make_queue = [redis, prefix = config.redis_prefix,
                          visibility = config.job_visibility_seconds](
                             size_t capacity, int workers,
                             JobQueue::Runner run) -> StatusOr<std::unique_ptr<JobQueue>> {
      auto queue =
          RedisJobQueue::Open(redis, prefix, capacity, workers, visibility, std::move(run));
      if (!queue.ok()) return queue.status();
      return std::unique_ptr<JobQueue>(std::move(*queue));
    };
    // The URL may hold a password: the log names where, not how.
    const std::string where = endpoint->socket_path.empty()
                                  ? endpoint->host + ":" + std::to_string(endpoint->port)
                                  : endpoint->socket_path;
    spdlog::info("backend redis at {} (keys {}*), blobs in {}", where, config.redis_prefix,
                 config.blob_store == "redis" ? "redis" : blob_dir.string());
  } else {
    auto store = SqliteStore::Open(std::filesystem::path(config.data_dir) / "motionlodd.db");
    if (!store.ok()) return store.status();
    context.store = std::move(*store);
    context.make_queue = [](size_t capacity, int workers, JobQueue::Runner run)
        -> StatusOr<std::unique_ptr<JobQueue>> {
      return std::unique_ptr<JobQueue>(
          std::make_unique<MemoryJobQueue>(capacity, workers, std::move(run)));
    };
  }
  if (config.blob_store == "redis") {
    context.blobs =
        std::make_unique<RedisBlobStore>(redis, config.redis_prefix, config.redis_max_blob_bytes);
    return Status::Ok();
  }
  auto blobs = DirectoryBlobStore::Open(blob_dir, config.backend == "redis");
  if (!blobs.ok()) return blobs.status();
  context.blobs = std::move(*blobs);
  return Status::Ok();
}

}  // namespace

Service::Service(const Config& config)
    : context_(config),
      jobs_(context_),
      levels_(context_, jobs_),
      bakes_(context_, jobs_, levels_),
      characters_(context_, bakes_),
      motions_(context_) {}

Service::~Service() { Shutdown(); }

StatusOr<std::unique_ptr<Service>> Service::Open(const Config& config) {
  std::unique_ptr<Service> service(new Service(config));
  ServiceContext& context = service->context_;
  std::error_code error;
  std::filesystem::create_directories(config.data_dir, error);
  if (error) {
    return Status(StatusCode::kInternal,
                  "cannot create the data directory '" + config.data_dir + "': " + error.message());
  }
  ImportLimits limits;
  limits.memory_bytes = config.import_memory_bytes;
  limits.cpu_seconds = config.import_cpu_seconds;
  limits.wall_seconds = config.import_timeout_seconds;
  limits.output_bytes = config.import_output_bytes;
  auto importer = ImportSandbox::Create(config.import_isolation, config.import_worker, limits);
  if (!importer.ok()) return importer.status();
  context.importer = std::move(*importer);
  if (context.importer->fallback_reason().empty()) {
    spdlog::info("imports run in a {} sandbox", IsolationName(context.importer->isolation()));
  } else {
    spdlog::warn("imports run as plain processes with limits only: bubblewrap does not work ({})",
                 context.importer->fallback_reason());
  }
  if (Status status = OpenStorage(config, context); !status.ok()) return status;
  // Blobs no row names (a crash between writing them and committing, or a delete that
  // stopped half way) are removed; not in a shared store, where another daemon may be
  // between the two now.
  if (context.store->shared()) return service;
  auto referenced = context.store->ReferencedBlobs();
  if (!referenced.ok()) return referenced.status();
  const std::set<std::string> keep(referenced->begin(), referenced->end());
  size_t removed = 0;
  for (const std::string& hash : context.blobs->List()) {
    if (!keep.count(hash) && context.blobs->Remove(hash).ok()) ++removed;
  }
  if (removed > 0) spdlog::info("removed {} unreferenced blobs", removed);
  return service;
}

Status Service::Start() { return jobs_.Start(); }

void Service::BeginDrain() { jobs_.BeginDrain(); }

void Service::Shutdown() { jobs_.Shutdown(); }

Status Service::Ready() {
  if (jobs_.draining()) return Status(StatusCode::kUnavailable, "the daemon is shutting down");
  if (jobs_.queue() == nullptr) return Status(StatusCode::kUnavailable, "the daemon is starting");
  if (!context_.store->Healthy()) {
    return Status(StatusCode::kUnavailable, context_.store->shared()
                                                ? "Redis does not answer"
                                                : "the database does not answer");
  }
  return context_.blobs->CheckWritable(context_.config.min_free_bytes);
}

void Service::RenderMetrics(std::string& out) {
  const auto gauge = [&](const char* name, const char* help, const std::string& value) {
    out += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " gauge\n" + name +
           " " + value + "\n";
  };
  const JobQueue* queue = jobs_.queue();
  gauge("motionlodd_queue_depth", "Bakes waiting in the queue.",
        std::to_string(queue ? queue->depth() : 0));
  gauge("motionlodd_queue_capacity", "Queued bakes beyond which submissions get 503.",
        std::to_string(context_.config.queue_capacity));
  gauge("motionlodd_jobs_running", "Bakes running now.",
        std::to_string(queue ? queue->running() : 0));
  if (auto counts = context_.store->CountJobsByState(); counts.ok()) {
    out += "# HELP motionlodd_jobs Jobs in the store by state.\n# TYPE motionlodd_jobs gauge\n";
    for (const auto& [state, count] : *counts) {
      out +=
          "motionlodd_jobs{state=\"" + EscapeLabel(state) + "\"} " + std::to_string(count) + "\n";
    }
  }
  out +=
      "# HELP motionlodd_bakes_total Bakes finished by this process, by outcome.\n"
      "# TYPE motionlodd_bakes_total counter\n";
  out += "motionlodd_bakes_total{outcome=\"succeeded\"} " +
         std::to_string(context_.bake_metrics.succeeded.load()) + "\n";
  out += "motionlodd_bakes_total{outcome=\"failed\"} " +
         std::to_string(context_.bake_metrics.failed.load()) + "\n";
  out += "motionlodd_bakes_total{outcome=\"interrupted\"} " +
         std::to_string(context_.bake_metrics.interrupted.load()) + "\n";
  out +=
      "# HELP motionlodd_bake_duration_seconds Wall time of successful bakes.\n"
      "# TYPE motionlodd_bake_duration_seconds histogram\n";
  context_.bake_metrics.seconds.Render(out, "motionlodd_bake_duration_seconds", "");
  const LevelCache::Stats cache = context_.cache.stats();
  out +=
      "# HELP motionlodd_level_cache_requests_total Level cache lookups by result.\n"
      "# TYPE motionlodd_level_cache_requests_total counter\n";
  out +=
      "motionlodd_level_cache_requests_total{result=\"hit\"} " + std::to_string(cache.hits) + "\n";
  out += "motionlodd_level_cache_requests_total{result=\"miss\"} " + std::to_string(cache.misses) +
         "\n";
  out +=
      "# HELP motionlodd_level_cache_evictions_total Levels evicted from the cache.\n"
      "# TYPE motionlodd_level_cache_evictions_total "
      "counter\nmotionlodd_level_cache_evictions_total " +
      std::to_string(cache.evictions) + "\n";
  gauge("motionlodd_level_cache_bytes", "Bytes held by the level cache.",
        std::to_string(cache.bytes));
  gauge("motionlodd_level_cache_entries", "Levels held by the level cache.",
        std::to_string(cache.entries));
  gauge("motionlodd_level_cache_capacity_bytes", "The level cache's byte budget.",
        std::to_string(cache.capacity));
  gauge("motionlodd_imports_in_progress", "Uploads being imported now.",
        std::to_string(context_.imports.load()));
}

}  // namespace motionlod::server
