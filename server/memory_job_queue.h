// The JobQueue of one daemon: a bounded FIFO in memory. Jobs outlive a restart through
// the store (Store::TakeUnfinishedJobs), not through the queue.
#pragma once

#include <condition_variable>
#include <deque>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

#include "server/job_queue.h"

namespace motionlod::server {

class MemoryJobQueue final : public JobQueue {
 public:
  // `capacity` bounds the ids waiting (not those running); `workers` >= 1.
  MemoryJobQueue(size_t capacity, int workers, Runner run);
  ~MemoryJobQueue() override;  // Stop()
  MemoryJobQueue(const MemoryJobQueue&) = delete;
  MemoryJobQueue& operator=(const MemoryJobQueue&) = delete;

  using JobQueue::Push;
  PushResult Push(const std::string& id, bool force) override;
  bool Remove(const std::string& id) override;
  size_t depth() const override;
  size_t running() const override;
  size_t capacity() const override { return capacity_; }
  void StopTaking() override;
  void Stop() override;

 private:
  void Work();

  const size_t capacity_;
  const Runner run_;
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::string> waiting_;
  std::set<std::string> waiting_ids_;
  size_t running_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

}  // namespace motionlod::server
