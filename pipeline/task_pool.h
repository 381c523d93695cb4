// The fork-join pool of the pipeline and the programs above it (the core, io and proto
// start no thread: they take a PieceRunner, base/pieces.h, which Runner() gives them): a
// fixed set of worker threads that run the pieces of Run calls, with the calling thread
// taking part. Header-only: its users link Threads::Threads.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "base/pieces.h"

namespace motionlod::pipeline {

inline int ResolveThreads(int threads) {
  if (threads > 0) return threads;
  const unsigned hardware = std::thread::hardware_concurrency();
  return hardware == 0 ? 1 : static_cast<int>(hardware);
}

// Why a pool and not a thread per piece: a bake makes several parallel calls, and starting
// and joining threads for each was a noticeable share of a small character's bake; threads
// started from inside another piece while the other cores were busy were also placed on
// one core and stayed there (the motion's sampling, beside the character's build, gained
// nothing from a second thread).
//
// Why a thread waits by spinning first: a wake-up through the condition variable takes
// tens of microseconds on virtual CPUs, and a bake makes dozens of short Run calls, so
// sleeping between them ate what a second thread gained. A thread with nothing to do
// watches the pool's change count for kSpin before it sleeps, so that the next job or the
// last piece's end reaches it in well under a microsecond; kSpin is about two wake-ups,
// the most a spin can cost beyond what sleeping would have.
class TaskPool {
 public:
  // threads - 1 workers: the thread that calls Run is the last. 0 = one per hardware thread.
  explicit TaskPool(int threads) : threads_(ResolveThreads(threads)) {
    workers_.reserve(threads_ - 1);
    for (int w = 1; w < threads_; ++w) workers_.emplace_back([this] { Work(); });
  }
  ~TaskPool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
      Changed();
    }
    for (std::thread& worker : workers_) worker.join();
  }
  TaskPool(const TaskPool&) = delete;
  TaskPool& operator=(const TaskPool&) = delete;

  int threads() const { return threads_; }

  // Run as a PieceRunner, for the functions of the core, io and proto that take one
  // (base/pieces.h).
  PieceRunner Runner() {
    return [this](int count, const std::function<void(int)>& piece) { Run(count, piece); };
  }

  // Runs piece(index) for every index in [0, count) and returns when all have run. Pieces
  // are handed out in order, to the workers and to the calling thread; on_done(done) runs
  // on the calling thread, serially, after pieces complete (done: how many so far, each
  // value once, up to count). Safe to call from several threads at once and from inside a
  // piece. A caller whose own pieces are all handed out helps with other open jobs while
  // the last of its pieces finish elsewhere: a job opened inside a piece (the motion's
  // sampling, inside the inputs' task) would otherwise wait for its one busy owner.
  void Run(int count, const std::function<void(int)>& piece,
           const std::function<void(int)>& on_done = {}) {
    if (count <= 0) return;
    if (workers_.empty() || count == 1) {
      for (int index = 0; index < count; ++index) {
        piece(index);
        if (on_done) on_done(index + 1);
      }
      return;
    }
    Job job(&piece, count);
    std::unique_lock<std::mutex> lock(mutex_);
    open_.push_back(&job);
    Changed();
    int reported = 0;
    while (reported < count) {
      if (job.next < count) {
        RunPiece(job, lock);
      } else if (job.done == reported) {
        if (open_.empty()) {
          WaitUntil(lock, [&] { return job.done != reported || !open_.empty(); });
        } else {
          RunPiece(*open_.front(), lock);
        }
      }
      if (reported < job.done) {
        const int done = job.done;
        if (on_done) {
          lock.unlock();
          for (int r = reported + 1; r <= done; ++r) on_done(r);
          lock.lock();
        }
        reported = done;
      }
    }
  }

 private:
  struct Job {
    Job(const std::function<void(int)>* piece, int count) : piece(piece), count(count) {}
    const std::function<void(int)>* piece;
    int count;
    int next = 0;  // the next piece to hand out
    int done = 0;  // pieces finished
  };

  // Takes the job's next piece and runs it with the lock released. Called with the lock
  // held and job.next < job.count; returns with it held.
  void RunPiece(Job& job, std::unique_lock<std::mutex>& lock) {
    const int index = job.next++;
    if (job.next == job.count) open_.erase(std::find(open_.begin(), open_.end(), &job));
    lock.unlock();
    (*job.piece)(index);
    lock.lock();
    ++job.done;
    Changed();
  }

  // Called with the lock held after a job was opened, a piece finished or stopping_ set.
  void Changed() {
    changes_.fetch_add(1, std::memory_order_release);
    changed_.notify_all();
  }

  // Returns, with the lock held, once ready() holds (checked under the lock): spins on
  // changes_ with the lock released, checking ready() at each change, for up to kSpin, then
  // sleeps on changed_.
  template <typename Ready>
  void WaitUntil(std::unique_lock<std::mutex>& lock, Ready ready) {
    constexpr auto kSpin = std::chrono::microseconds(50);
    const auto deadline = std::chrono::steady_clock::now() + kSpin;
    while (!ready()) {
      if (std::chrono::steady_clock::now() > deadline) {
        changed_.wait(lock, ready);
        return;
      }
      const unsigned seen = changes_.load(std::memory_order_relaxed);
      lock.unlock();
      for (unsigned spins = 1; changes_.load(std::memory_order_acquire) == seen; ++spins) {
        CpuRelax();
        if (spins % 64 == 0 && std::chrono::steady_clock::now() > deadline) break;
      }
      lock.lock();
    }
  }

  static void CpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    asm volatile("yield");
#endif
  }

  void Work() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (true) {
      WaitUntil(lock, [&] { return stopping_ || !open_.empty(); });
      if (open_.empty()) return;  // stopping, nothing left
      RunPiece(*open_.front(), lock);
    }
  }

  const int threads_;
  std::mutex mutex_;
  // A job was opened, a piece finished, or the pool is stopping.
  std::condition_variable changed_;
  // How many times changed_ was notified: what a spinning thread watches.
  std::atomic<unsigned> changes_{0};
  std::deque<Job*> open_;  // jobs with pieces not yet handed out, oldest first
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

}  // namespace motionlod::pipeline
