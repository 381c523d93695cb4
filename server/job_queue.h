// The queue of bake jobs: ids pushed by the HTTP side, taken by a fixed pool of worker
// threads that call `run(id)` and take the next id when it returns. The queue knows
// nothing of bakes. Two implementations: MemoryJobQueue (server/memory_job_queue.h, one
// daemon; the store keeps the queued jobs across restarts) and RedisJobQueue
// (server/redis_job_queue.h: a Redis Stream that several daemons take from, at least
// once). Thread-safe.
#pragma once

#include <cstddef>
#include <functional>
#include <string>

namespace motionlod::server {

class JobQueue {
 public:
  // kInterrupted: the job stopped before its end (shutdown) and must run again.
  enum class RunOutcome { kFinished, kInterrupted };
  using Runner = std::function<RunOutcome(const std::string& id)>;

  virtual ~JobQueue() = default;

  // kUnavailable: the queue's backend does not answer now (the caller answers 503).
  enum class PushResult { kQueued, kAlreadyQueued, kFull, kStopped, kUnavailable };
  // `force` ignores the capacity (jobs accepted before a restart are never refused).
  virtual PushResult Push(const std::string& id, bool force) = 0;
  PushResult Push(const std::string& id) { return Push(id, false); }
  // Drops a waiting id (its job was deleted); false when it is not waiting here.
  virtual bool Remove(const std::string& id) = 0;

  virtual size_t depth() const = 0;    // waiting
  virtual size_t running() const = 0;  // running in this process
  virtual size_t capacity() const = 0;

  // Workers take no new id from now on (the ids still waiting stay waiting).
  virtual void StopTaking() = 0;
  // StopTaking, then joins the workers (each finishes the job it runs).
  virtual void Stop() = 0;
};

}  // namespace motionlod::server
