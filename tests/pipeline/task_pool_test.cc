#include "base/parallel.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

namespace motionlod {
namespace {

TEST(TaskPool, RunsEveryPieceOnceAndReportsEachCountInOrder) {
  for (int threads : {1, 2, 4}) {
    TaskPool pool(threads);
    EXPECT_EQ(pool.threads(), threads);
    for (int count : {0, 1, 2, 3, 100}) {
      std::vector<std::atomic<int>> runs(count);
      std::vector<int> reported;
      const std::thread::id caller = std::this_thread::get_id();
      bool reported_elsewhere = false;
      pool.Run(
          count, [&](int index) { ++runs[index]; },
          [&](int done) {
            reported.push_back(done);
            reported_elsewhere |= std::this_thread::get_id() != caller;
          });
      for (int index = 0; index < count; ++index) {
        EXPECT_EQ(runs[index].load(), 1) << "threads " << threads << " count " << count << " index " << index;
      }
      ASSERT_EQ(static_cast<int>(reported.size()), count) << "threads " << threads;
      for (int r = 0; r < count; ++r) EXPECT_EQ(reported[r], r + 1);
      EXPECT_FALSE(reported_elsewhere);
    }
  }
}

// Two pieces that each wait for the other to start finish only if they run at the same
// time: the pool really uses its worker beside the calling thread.
TEST(TaskPool, PiecesRunAtTheSameTime) {
  TaskPool pool(2);
  std::atomic<int> started{0};
  std::atomic<int> met{0};
  pool.Run(2, [&](int) {
    ++started;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (started.load() < 2 && std::chrono::steady_clock::now() < deadline) std::this_thread::yield();
    if (started.load() == 2) ++met;
  });
  EXPECT_EQ(met.load(), 2);
}

// Runs from inside pieces, nested deeper than there are threads, and from several
// threads at once, all complete: a caller works on its own pieces while it waits.
TEST(TaskPool, NestedAndConcurrentRunsComplete) {
  TaskPool pool(2);
  std::atomic<int> leaves{0};
  const auto nested = [&](int depth, auto&& self) -> void {
    if (depth == 0) {
      ++leaves;
      return;
    }
    pool.Run(3, [&](int) { self(depth - 1, self); });
  };
  std::vector<std::thread> callers;
  for (int c = 0; c < 3; ++c) callers.emplace_back([&] { nested(4, nested); });
  for (std::thread& caller : callers) caller.join();
  EXPECT_EQ(leaves.load(), 3 * 81);
}

}  // namespace
}  // namespace motionlod
