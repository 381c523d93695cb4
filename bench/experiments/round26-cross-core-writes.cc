// Round 26 (docs/PERFORMANCE.md): what a pass over a buffer costs on one core when the
// other core wrote that buffer last. Thread B (CPU 1) times a write pass, then a second
// write pass, over 191 KB (Fox's Kt) that thread A (CPU 0) has just written; 2000 rounds,
// medians. Round 29 added the cases that follow it (SharedLineCases): who touched the
// buffer last, and how, before core 1 writes it; 1500 rounds each. Build and run:
//   g++ -O2 -march=native -o /tmp/cross_core bench/experiments/round26-cross-core-writes.cc -lpthread
//   /tmp/cross_core
#include <immintrin.h>
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

static double sink_value = 0;

static void Flush(double* p, size_t n) {
  for (size_t i = 0; i < n; i += 8) _mm_clflushopt(p + i);
  _mm_sfence();
}

static double Read(const double* b, size_t n) {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  for (size_t i = 0; i < n; i += 4) {
    s0 += b[i];
    s1 += b[i + 1];
    s2 += b[i + 2];
    s3 += b[i + 3];
  }
  return s0 + s1 + s2 + s3;
}

// Round 29's cases.
static void SharedLineCases() {
  const size_t n = 191 * 1024 / 8, ring = 256;
  std::vector<double> big(n * ring, 1.0);
  std::atomic<int> phase{0};
  volatile double sink = 0;
  // Each round core 1 (B) writes the buffer, core 0 (A) then does the case's step, and B
  // (A in case 4) times a write pass over it; the other core waits meanwhile.
  const char* names[] = {"B wrote, A read, B writes", "B wrote, A read and flushed, B writes",
                         "B wrote, A read, B flushes and writes", "a cold buffer, B writes",
                         "B wrote, A read, A writes", "B wrote, B writes"};
  for (int c = 0; c < 6; ++c) {
    std::vector<double> times;
    phase = 0;
    const int rounds = 1500;
    std::thread b([&] {
      Pin(1);
      for (int r = 0; r < rounds; ++r) {
        double* buffer = c == 3 ? big.data() + n * (r % ring) : big.data();
        for (size_t i = 0; i < n; ++i) buffer[i] = i * 0.5 + r;
        phase.store(4 * r + 1);
        while (phase.load() < 4 * r + 2) {
        }
        double* written = c == 3 ? big.data() + n * ((r + ring / 2) % ring) : buffer;
        const auto t0 = Clock::now();
        if (c == 2) Flush(written, n);
        if (c != 4) {
          for (size_t i = 0; i < n; ++i) written[i] = i * 0.25 + r;
        }
        if (c != 4) times.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
        phase.store(4 * r + 3);
        while (phase.load() < 4 * r + 4) {
        }
      }
    });
    Pin(0);
    for (int r = 0; r < rounds; ++r) {
      while (phase.load() < 4 * r + 1) {
      }
      double* buffer = c == 3 ? big.data() + n * (r % ring) : big.data();
      if (c != 5) sink = Read(buffer, n);
      if (c == 1) Flush(buffer, n);
      phase.store(4 * r + 2);
      while (phase.load() < 4 * r + 3) {
      }
      if (c == 4) {
        const auto t0 = Clock::now();
        for (size_t i = 0; i < n; ++i) buffer[i] = i * 0.3 + r;
        times.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
      }
      phase.store(4 * r + 4);
    }
    b.join();
    std::sort(times.begin(), times.end());
    std::printf("%-40s %.1f us\n", names[c], times[times.size() / 2]);
  }
  sink_value = sink;
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
  SharedLineCases();
  return sink_value == 42;
}
