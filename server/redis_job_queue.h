// The JobQueue of daemons sharing one Redis: a Redis Stream (P jobs:stream) read through
// one consumer group (motionlodd), each daemon a consumer. Delivery is at least once: a
// worker acknowledges (and deletes) an entry when its job has finished; while it runs,
// a heartbeat keeps the entry's idle time low, and an entry idle longer than the
// visibility timeout (its daemon died) is taken over by another daemon's worker with
// XAUTOCLAIM. Jobs::Run counts such runs toward max_job_crashes. P jobs:queued holds the
// ids waiting (for deduplication and the capacity); a push is one Lua script.
#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "server/job_queue.h"
#include "server/redis_client.h"

namespace motionlod::server {

class RedisJobQueue final : public JobQueue {
 public:
  // Creates the consumer group when missing. `visibility_seconds`: how long an entry may
  // go without a heartbeat before another daemon takes it over.
  static StatusOr<std::unique_ptr<RedisJobQueue>> Open(std::shared_ptr<RedisPool> redis,
                                                       std::string prefix, size_t capacity,
                                                       int workers, double visibility_seconds,
                                                       Runner run);
  ~RedisJobQueue() override;  // Stop()
  RedisJobQueue(const RedisJobQueue&) = delete;
  RedisJobQueue& operator=(const RedisJobQueue&) = delete;

  using JobQueue::Push;
  PushResult Push(const std::string& id, bool force) override;
  // Drops the id from the waiting set; its stream entry, when a worker takes it, finds the
  // bake gone.
  bool Remove(const std::string& id) override;
  size_t depth() const override;
  size_t running() const override { return running_.load(); }
  size_t capacity() const override { return capacity_; }
  void StopTaking() override;
  void Stop() override;

  const std::string& consumer() const { return consumer_; }

 private:
  RedisJobQueue(std::shared_ptr<RedisPool> redis, std::string prefix, size_t capacity,
                double visibility_seconds, Runner run);
  void Work();
  void Heartbeat();
  // Runs the job of one entry and acknowledges it (requeued when interrupted).
  void Take(RedisConnection& connection, const std::string& entry, const std::string& id);

  std::shared_ptr<RedisPool> redis_;
  const std::string prefix_, stream_, queued_;
  const size_t capacity_;
  const double visibility_seconds_;
  const Runner run_;
  const std::string consumer_;  // host:pid:random, unique per process start
  std::atomic<size_t> running_{0};
  std::atomic<bool> stopping_{false};
  std::mutex entries_mutex_;
  std::set<std::string> entries_;  // stream entries running here (for the heartbeat)
  std::vector<std::thread> workers_;
  std::thread heartbeat_;
};

}  // namespace motionlod::server
