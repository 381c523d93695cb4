#include "server/memory_job_queue.h"

#include <algorithm>

namespace motionlod::server {

MemoryJobQueue::MemoryJobQueue(size_t capacity, int workers, Runner run)
    : capacity_(capacity), run_(std::move(run)) {
  for (int w = 0; w < std::max(1, workers); ++w) workers_.emplace_back([this] { Work(); });
}

MemoryJobQueue::~MemoryJobQueue() { Stop(); }

JobQueue::PushResult MemoryJobQueue::Push(const std::string& id, bool force) {
  {
    std::lock_guard lock(mutex_);
    if (stopping_) return PushResult::kStopped;
    if (waiting_ids_.count(id)) return PushResult::kAlreadyQueued;
    if (!force && waiting_.size() >= capacity_) return PushResult::kFull;
    waiting_.push_back(id);
    waiting_ids_.insert(id);
  }
  ready_.notify_one();
  return PushResult::kQueued;
}

bool MemoryJobQueue::Remove(const std::string& id) {
  std::lock_guard lock(mutex_);
  if (!waiting_ids_.erase(id)) return false;
  waiting_.erase(std::find(waiting_.begin(), waiting_.end(), id));
  return true;
}

size_t MemoryJobQueue::depth() const {
  std::lock_guard lock(mutex_);
  return waiting_.size();
}

size_t MemoryJobQueue::running() const {
  std::lock_guard lock(mutex_);
  return running_;
}

void MemoryJobQueue::StopTaking() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  ready_.notify_all();
}

void MemoryJobQueue::Stop() {
  StopTaking();
  for (std::thread& worker : workers_) {
    if (worker.joinable()) worker.join();
  }
}

void MemoryJobQueue::Work() {
  while (true) {
    std::string id;
    {
      std::unique_lock lock(mutex_);
      ready_.wait(lock, [&] { return stopping_ || !waiting_.empty(); });
      if (stopping_) return;
      id = std::move(waiting_.front());
      waiting_.pop_front();
      waiting_ids_.erase(id);
      ++running_;
    }
    (void)run_(id);  // an interrupted job stays queued in the store for the next start
    std::lock_guard lock(mutex_);
    --running_;
  }
}

}  // namespace motionlod::server
