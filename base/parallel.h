// A minimal fork-join loop for the layers above the core (which starts no thread): runs
// fn(index) for every index in [0, count) on `threads` threads and lets the calling
// thread observe completions.
#pragma once

#include <atomic>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace motionlod {

inline int ResolveThreads(int threads) {
  if (threads > 0) return threads;
  const unsigned hardware = std::thread::hardware_concurrency();
  return hardware == 0 ? 1 : static_cast<int>(hardware);
}

// Runs fn over [0, count) on `threads` worker threads; on_done(done_count) runs on the
// calling thread after each completion (serially). Indices are handed out in order.
inline void ParallelFor(int count, int threads, const std::function<void(int)>& fn,
                        const std::function<void(int)>& on_done = {}) {
  if (count <= 0) return;
  if (threads <= 1 || count == 1) {  // on the calling thread: no thread to start
    for (int index = 0; index < count; ++index) {
      fn(index);
      if (on_done) on_done(index + 1);
    }
    return;
  }
  std::atomic<int> next{0};
  std::mutex mutex;
  std::condition_variable changed;
  int done = 0;
  const int workers = std::max(1, std::min(threads, count));
  std::vector<std::thread> pool;
  pool.reserve(workers);
  for (int w = 0; w < workers; ++w) {
    pool.emplace_back([&] {
      for (int index = next++; index < count; index = next++) {
        fn(index);
        {
          std::lock_guard<std::mutex> lock(mutex);
          ++done;
        }
        changed.notify_one();
      }
    });
  }
  int reported = 0;
  {
    std::unique_lock<std::mutex> lock(mutex);
    while (reported < count) {
      changed.wait(lock, [&] { return done > reported; });
      const int now = done;
      lock.unlock();
      if (on_done) {
        for (int r = reported + 1; r <= now; ++r) on_done(r);
      }
      reported = now;
      lock.lock();
    }
  }
  for (std::thread& t : pool) t.join();
}

}  // namespace motionlod
