// Round 30 (docs/PERFORMANCE.md): what two threads cost on this machine, apart from the
// bake. (1) Starting a thread: how long std::thread's constructor takes, and how long until
// the new thread runs (medians of 200). (2) Whether the two CPUs share a core: a loop of
// 12 independent AVX2 FMA chains (throughput-bound) alone on CPU 0, then on CPUs 0 and 1
// at once; hyperthreads of one core would take about twice as long together.
//   g++ -O2 -mavx2 -mfma -o /tmp/two_cores bench/experiments/round30-two-cores.cc -lpthread
//   /tmp/two_cores
#include <immintrin.h>
#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

using Clock = std::chrono::steady_clock;

double Microseconds(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double, std::micro>(to - from).count();
}

__attribute__((noinline)) double FmaChains(long iterations, double seed) {
  __m256d chains[12];
  for (int k = 0; k < 12; ++k) chains[k] = _mm256_set1_pd(seed + k);
  const __m256d factor = _mm256_set1_pd(1.0000001), offset = _mm256_set1_pd(1e-9);
  for (long i = 0; i < iterations; ++i) {
    for (int k = 0; k < 12; ++k) chains[k] = _mm256_fmadd_pd(chains[k], factor, offset);
  }
  __m256d sum = chains[0];
  for (int k = 1; k < 12; ++k) sum = _mm256_add_pd(sum, chains[k]);
  return sum[0] + sum[1] + sum[2] + sum[3];
}

void PinTo(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  pthread_setaffinity_np(pthread_self(), sizeof set, &set);
}

int main() {
  std::vector<double> constructed, running;
  for (int i = 0; i < 200; ++i) {
    std::atomic<bool> started{false};
    Clock::time_point ran;
    const auto begin = Clock::now();
    std::thread thread([&] {
      ran = Clock::now();
      started = true;
    });
    const auto returned = Clock::now();
    while (!started) {
    }
    thread.join();
    constructed.push_back(Microseconds(begin, returned));
    running.push_back(Microseconds(begin, ran));
  }
  std::sort(constructed.begin(), constructed.end());
  std::sort(running.begin(), running.end());
  std::printf("std::thread: constructor %.1f us, the thread runs after %.1f us (medians)\n",
              constructed[100], running[100]);

  constexpr long kIterations = 10000000;
  volatile double sink = 0;
  for (int round = 0; round < 3; ++round) {
    PinTo(0);
    auto begin = Clock::now();
    sink = FmaChains(kIterations, round);
    const double alone = Microseconds(begin, Clock::now()) / 1000;
    double other = 0;
    std::thread thread([&] {
      PinTo(1);
      const auto start = Clock::now();
      sink = FmaChains(kIterations, round + 1);
      other = Microseconds(start, Clock::now()) / 1000;
    });
    begin = Clock::now();
    sink = FmaChains(kIterations, round + 2);
    const double together = Microseconds(begin, Clock::now()) / 1000;
    thread.join();
    std::printf("FMA chains: alone %.1f ms; together %.1f ms (CPU 0) and %.1f ms (CPU 1)\n", alone,
                together, other);
  }
}
