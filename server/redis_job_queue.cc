#include "server/redis_job_queue.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <random>

namespace motionlod::server {
namespace {

constexpr const char* kGroup = "motionlodd";
// How long a worker's XREADGROUP blocks, so that it sees StopTaking within this.
constexpr int kBlockMilliseconds = 1000;
// A consumer (a daemon's start) with nothing pending and idle this long is removed from
// the group at another daemon's start (XREADGROUP brings it back if it still lives).
constexpr int64_t kStaleConsumerMilliseconds = 3600 * 1000;

// ARGV: prefix, id, capacity, force ("1"). 'queued', 'already' or 'full'.
constexpr const char* kPush = R"lua(
local P, id = ARGV[1], ARGV[2]
if redis.call('SISMEMBER', P .. 'jobs:queued', id) == 1 then return 'already' end
if ARGV[4] ~= '1' and redis.call('SCARD', P .. 'jobs:queued') >= tonumber(ARGV[3]) then
  return 'full'
end
redis.call('SADD', P .. 'jobs:queued', id)
redis.call('XADD', P .. 'jobs:stream', '*', 'job', id)
return 'queued'
)lua";

// ARGV: prefix, entry, id, requeue ("1"): acknowledges and deletes the entry, and with
// requeue adds the id again at the end of the stream.
constexpr const char* kFinish = R"lua(
local P = ARGV[1]
redis.call('XACK', P .. 'jobs:stream', 'motionlodd', ARGV[2])
redis.call('XDEL', P .. 'jobs:stream', ARGV[2])
if ARGV[4] == '1' then
  redis.call('SADD', P .. 'jobs:queued', ARGV[3])
  redis.call('XADD', P .. 'jobs:stream', '*', 'job', ARGV[3])
end
return 1
)lua";

std::string ConsumerName() {
  char host[256] = "host";
  ::gethostname(host, sizeof host - 1);
  std::random_device random;
  char suffix[16];
  std::snprintf(suffix, sizeof suffix, "%06x", random() & 0xffffff);
  return std::string(host) + ":" + std::to_string(::getpid()) + ":" + suffix;
}

// The group exists (a Redis restarted without its data, or a new one, has none).
Status EnsureGroup(RedisConnection& connection, const std::string& stream) {
  auto reply = connection.Command({"XGROUP", "CREATE", stream, kGroup, "0", "MKSTREAM"});
  if (reply.ok() || reply.status().message().find("BUSYGROUP") != std::string::npos)
    return Status::Ok();
  return reply.status();
}

// The (entry id, job id) pairs of a list of stream entries ([id, [field, value, ...]]).
std::vector<std::pair<std::string, std::string>> Entries(const RedisReply& list) {
  std::vector<std::pair<std::string, std::string>> entries;
  for (const RedisReply& entry : list.elements) {
    if (entry.elements.size() != 2) continue;  // deleted meanwhile
    const RedisReply& fields = entry.elements[1];
    std::string job;
    for (size_t i = 0; i + 1 < fields.elements.size(); i += 2) {
      if (fields.elements[i].text == "job") job = fields.elements[i + 1].text;
    }
    entries.emplace_back(entry.elements[0].text, job);
  }
  return entries;
}

void SleepUnlessStopping(const std::atomic<bool>& stopping, std::chrono::milliseconds total) {
  const auto end = std::chrono::steady_clock::now() + total;
  while (!stopping.load() && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
}

}  // namespace

RedisJobQueue::RedisJobQueue(std::shared_ptr<RedisPool> redis, std::string prefix, size_t capacity,
                             double visibility_seconds, Runner run)
    : redis_(std::move(redis)),
      prefix_(std::move(prefix)),
      stream_(prefix_ + "jobs:stream"),
      queued_(prefix_ + "jobs:queued"),
      capacity_(capacity),
      visibility_seconds_(visibility_seconds),
      run_(std::move(run)),
      consumer_(ConsumerName()) {}

StatusOr<std::unique_ptr<RedisJobQueue>> RedisJobQueue::Open(std::shared_ptr<RedisPool> redis,
                                                             std::string prefix, size_t capacity,
                                                             int workers, double visibility_seconds,
                                                             Runner run) {
  std::unique_ptr<RedisJobQueue> queue(new RedisJobQueue(
      std::move(redis), std::move(prefix), capacity, visibility_seconds, std::move(run)));
  {
    RedisConnection connection(queue->redis_->endpoint(), queue->redis_->timeout_seconds());
    if (Status status = EnsureGroup(connection, queue->stream_); !status.ok()) return status;
    auto consumers = connection.Command({"XINFO", "CONSUMERS", queue->stream_, kGroup});
    if (!consumers.ok()) return consumers.status();
    for (const RedisReply& consumer : consumers->elements) {
      std::string name;
      int64_t pending = 1, idle = 0;
      for (size_t i = 0; i + 1 < consumer.elements.size(); i += 2) {
        const std::string& key = consumer.elements[i].text;
        if (key == "name") name = consumer.elements[i + 1].text;
        if (key == "pending") pending = consumer.elements[i + 1].integer;
        if (key == "idle") idle = consumer.elements[i + 1].integer;
      }
      if (pending == 0 && idle > kStaleConsumerMilliseconds)
        (void)connection.Command({"XGROUP", "DELCONSUMER", queue->stream_, kGroup, name});
    }
  }
  for (int w = 0; w < std::max(1, workers); ++w)
    queue->workers_.emplace_back([q = queue.get()] { q->Work(); });
  queue->heartbeat_ = std::thread([q = queue.get()] { q->Heartbeat(); });
  return queue;
}

RedisJobQueue::~RedisJobQueue() { Stop(); }

JobQueue::PushResult RedisJobQueue::Push(const std::string& id, bool force) {
  if (stopping_.load()) return PushResult::kStopped;
  auto reply = redis_->Eval(kPush, {prefix_, id, std::to_string(capacity_), force ? "1" : "0"});
  if (!reply.ok()) {
    spdlog::error("bake queue: {}", reply.status().message());
    return PushResult::kUnavailable;
  }
  if (reply->text == "already") return PushResult::kAlreadyQueued;
  if (reply->text == "full") return PushResult::kFull;
  return PushResult::kQueued;
}

bool RedisJobQueue::Remove(const std::string& id) {
  auto reply = redis_->Command({"SREM", queued_, id});
  return reply.ok() && reply->integer == 1;
}

size_t RedisJobQueue::depth() const {
  auto reply = redis_->Command({"SCARD", queued_});
  return reply.ok() ? static_cast<size_t>(reply->integer) : 0;
}

void RedisJobQueue::StopTaking() { stopping_ = true; }

void RedisJobQueue::Stop() {
  StopTaking();
  for (std::thread& worker : workers_) {
    if (worker.joinable()) worker.join();
  }
  if (heartbeat_.joinable()) heartbeat_.join();
}

void RedisJobQueue::Work() {
  // Its own connection: XREADGROUP blocks it.
  RedisConnection connection(redis_->endpoint(),
                             redis_->timeout_seconds() + kBlockMilliseconds / 1000.0);
  const std::string min_idle = std::to_string(static_cast<int64_t>(visibility_seconds_ * 1000));
  bool failing = false;
  while (!stopping_.load()) {
    // An entry whose daemon died (idle past the visibility timeout) first, then new ones.
    auto claimed = connection.Command(
        {"XAUTOCLAIM", stream_, kGroup, consumer_, min_idle, "0-0", "COUNT", "1"});
    StatusOr<RedisReply> read = claimed;
    std::vector<std::pair<std::string, std::string>> entries;
    if (claimed.ok() && claimed->elements.size() >= 2) entries = Entries(claimed->elements[1]);
    if (claimed.ok() && entries.empty()) {
      read = connection.Command({"XREADGROUP", "GROUP", kGroup, consumer_, "COUNT", "1", "BLOCK",
                                 std::to_string(kBlockMilliseconds), "STREAMS", stream_, ">"});
      if (read.ok() && !read->nil() && !read->elements.empty() &&
          read->elements[0].elements.size() == 2) {
        entries = Entries(read->elements[0].elements[1]);
      }
    }
    if (!read.ok()) {
      if (!failing) spdlog::error("bake queue: {}; retrying", read.status().message());
      failing = true;
      if (read.status().message().find("NOGROUP") != std::string::npos)
        (void)EnsureGroup(connection, stream_);
      SleepUnlessStopping(stopping_, std::chrono::milliseconds(500));
      continue;
    }
    if (failing) spdlog::info("bake queue: Redis answers again");
    failing = false;
    for (const auto& [entry, id] : entries) Take(connection, entry, id);
  }
}

void RedisJobQueue::Take(RedisConnection& connection, const std::string& entry,
                         const std::string& id) {
  RunOutcome outcome = RunOutcome::kInterrupted;  // taken while stopping: not run here
  if (!stopping_.load() && !id.empty()) {
    {
      std::lock_guard lock(entries_mutex_);
      entries_.insert(entry);
    }
    ++running_;
    (void)connection.Command({"SREM", queued_, id});
    outcome = run_(id);
    --running_;
    std::lock_guard lock(entries_mutex_);
    entries_.erase(entry);
  }
  const bool requeue = outcome == RunOutcome::kInterrupted && !id.empty();
  // Redis may be restarting: an entry left unacknowledged runs again elsewhere after the
  // visibility timeout (and finds its job finished), so a few tries suffice.
  for (int attempt = 0; attempt < 20; ++attempt) {
    auto done = connection.Command({"EVAL", kFinish, "0", prefix_, entry, id, requeue ? "1" : "0"});
    if (done.ok()) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  spdlog::warn("bake queue: entry {} (job {}) could not be acknowledged; it is reclaimed later",
               entry, id);
}

// Every fifth of the visibility timeout: a daemon starved of CPU for most of it (a loaded
// machine) still keeps its bakes.
void RedisJobQueue::Heartbeat() {
  const auto period = std::chrono::milliseconds(
      std::max<int64_t>(100, static_cast<int64_t>(visibility_seconds_ * 1000 / 5)));
  while (!stopping_.load() || running_.load() > 0) {
    std::vector<std::string> entries;
    {
      std::lock_guard lock(entries_mutex_);
      entries.assign(entries_.begin(), entries_.end());
    }
    for (const std::string& entry : entries)  // resets the entry's idle time
      (void)redis_->Command({"XCLAIM", stream_, kGroup, consumer_, "0", entry, "JUSTID"});
    const auto end = std::chrono::steady_clock::now() + period;
    while (std::chrono::steady_clock::now() < end && !(stopping_.load() && running_.load() == 0))
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

}  // namespace motionlod::server
