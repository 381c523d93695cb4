// A bounded FIFO of job ids drained by a fixed pool of worker threads. The queue knows
// nothing of bakes: a worker calls `run(id)` and takes the next id when it returns.
// Thread-safe.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

namespace motionlod::server {

class JobQueue {
 public:
  using Runner = std::function<void(const std::string& id)>;

  // `capacity` bounds the ids waiting (not those running); `workers` >= 1.
  JobQueue(size_t capacity, int workers, Runner run);
  ~JobQueue();  // Stop()
  JobQueue(const JobQueue&) = delete;
  JobQueue& operator=(const JobQueue&) = delete;

  enum class PushResult { kQueued, kAlreadyQueued, kFull, kStopped };
  // `force` ignores the capacity (jobs accepted before a restart are never refused).
  PushResult Push(const std::string& id, bool force = false);
  // Drops a waiting id (its job was deleted); false when it is not waiting.
  bool Remove(const std::string& id);

  size_t depth() const;  // waiting
  size_t running() const;
  size_t capacity() const { return capacity_; }

  // Workers take no new id from now on (the ids still waiting stay waiting).
  void StopTaking();
  // StopTaking, then joins the workers (each finishes the job it runs).
  void Stop();

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
