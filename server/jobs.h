// Bake jobs: a bounded queue of job ids, the workers that run pipeline::Bake on them, and
// the board of the jobs queued or running in this process, whose every change bumps a
// version that long-polls and event streams wait on. A job has the id of its bake.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "pipeline/bake.h"
#include "proto/api.h"
#include "server/job_queue.h"
#include "server/service_context.h"
#include "server/store.h"

namespace motionlod::server {

class Jobs {
 public:
  explicit Jobs(ServiceContext& context) : context_(context) {}

  // Requeues the jobs a crash or a shutdown left unfinished and starts the workers.
  Status Start();
  // Stops taking jobs, lets running bakes finish for up to drain_seconds, then stops them
  // (they stay queued in the store and run again at the next start).
  void Shutdown();
  // Refuses new bakes and ends long-polls and event streams (before the HTTP server
  // stops, so that its connection threads are free to finish).
  void BeginDrain();
  bool draining() const { return draining_.load(); }
  // The queue, or null before Start().
  const JobQueue* queue() const { return queue_.get(); }

  // Puts a job stored as queued on the board and the queue; when the queue is full or
  // stopped, takes it off the board again and answers 503.
  Result<Done> Enqueue(const JobRecord& job);
  // Takes a job off the queue and the board and stops it if it runs (its bake is deleted).
  void Cancel(const std::string& id);

  Result<proto::api::JobStatus> Get(const std::string& id);
  // Returns once the job's version exceeds `after_version`, it is finished, `seconds`
  // passed, or the daemon drains.
  Result<proto::api::JobStatus> Wait(const std::string& id, uint64_t after_version, double seconds);

 private:
  struct LiveJob {
    JobRecord record;
    uint64_t version = 0;
    std::shared_ptr<std::atomic<bool>> cancel = std::make_shared<std::atomic<bool>>(false);
  };

  // Runs the job; `interrupted`: it stopped before its end (shutdown, or a shared store
  // that did not answer) and must run again.
  void Run(const std::string& id, bool& interrupted);
  // Stores the levels and commits the bake; `written` receives the blobs it wrote.
  Status FinishBake(const BakeRecord& bake, pipeline::BakeOutput output, JobRecord& job,
                    std::vector<std::string>& written);
  void Publish(const JobRecord& record, bool erase = false);  // board update + notify
  // A record's version on the board: the store's when shared (every daemon answers the
  // same), else this process's next. Under board_mutex_.
  uint64_t NextVersion(const JobRecord& record);
  // Puts the record on the board as a new live job (a fresh cancel flag). Under board_mutex_.
  LiveJob& PutOnBoard(const JobRecord& record);
  Result<proto::api::JobStatus> FromStore(const std::string& id);
  // Wait for a job not on the board: reads the store every kStorePollInterval.
  Result<proto::api::JobStatus> WaitInStore(const std::string& id, uint64_t after_version,
                                            std::chrono::steady_clock::time_point deadline);
  proto::api::JobStatus ToStatus(const JobRecord& record, uint64_t version) const;

  ServiceContext& context_;
  std::unique_ptr<JobQueue> queue_;
  std::atomic<bool> draining_{false};
  std::atomic<bool> stopping_{false};

  std::mutex board_mutex_;
  std::condition_variable board_changed_;
  // Jobs queued or running in this process (on a shared store, only those running here:
  // a queued job may run on any daemon).
  std::map<std::string, LiveJob> board_;
  uint64_t next_version_ = 1;
};

}  // namespace motionlod::server
