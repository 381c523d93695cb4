// Round 26 (docs/PERFORMANCE.md): what a pass over a buffer costs on one core when the
// other core wrote that buffer last. Thread B (CPU 1) times a write pass, then a second
// write pass, over 191 KB (Fox's Kt) that thread A (CPU 0) has just written; 2000 rounds,
// medians. Build and run:
//   g++ -O2 -march=native -o /tmp/cross_core bench/experiments/round26-cross-core-writes.cc -lpthread
//   /tmp/cross_core
#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

using Clock = std::chrono::steady_clock;

static void Pin(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  pthread_setaffinity_np(pthread_self(), sizeof set, &set);
}

int main() {
  const size_t n = 191 * 1024 / 8;
  std::vector<double> buffer(n, 1.0);
  std::atomic<int> phase{0};
  std::vector<double> after_other, after_self;
  std::thread b([&] {
    Pin(1);
    for (int round = 0; round < 2000; ++round) {
      while (phase.load() != 2 * round + 1) {
      }
      const auto t0 = Clock::now();
      for (size_t i = 0; i < n; ++i) buffer[i] = i * 0.5 + round;
      const auto t1 = Clock::now();
      for (size_t i = 0; i < n; ++i) buffer[i] = i * 0.25 + round;
      const auto t2 = Clock::now();
      after_other.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
      after_self.push_back(std::chrono::duration<double, std::micro>(t2 - t1).count());
      phase.store(2 * round + 2);
    }
  });
  Pin(0);
  for (int round = 0; round < 2000; ++round) {
    while (phase.load() != 2 * round) {
    }
    for (size_t i = 0; i < n; ++i) buffer[i] = round + i;
    phase.store(2 * round + 1);
  }
  b.join();
  std::sort(after_other.begin(), after_other.end());
  std::sort(after_self.begin(), after_self.end());
  std::printf("191 KB written: lines the other core wrote last %.1f us, lines this core holds %.1f us\n",
              after_other[1000], after_self[1000]);
}
