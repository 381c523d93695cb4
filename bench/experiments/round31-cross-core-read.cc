// Round 31 (docs/PERFORMANCE.md): what reading data the other core just wrote costs on this
// machine. CPU 1 adds 1 to every double of a buffer, then CPU 0 sums it (a throughput-bound
// loop); then CPU 0 writes and sums the same buffer itself. Medians of 50 rounds per size.
//   g++ -O3 -ffast-math -mavx2 -o /tmp/cross_core bench/experiments/round31-cross-core-read.cc -lpthread
//   /tmp/cross_core
#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

using Clock = std::chrono::steady_clock;

void PinTo(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  pthread_setaffinity_np(pthread_self(), sizeof set, &set);
}

double Microseconds(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double, std::micro>(to - from).count();
}

int main() {
  PinTo(0);
  double checksum = 0;  // keeps the sums
  for (size_t kib : {16, 64, 256, 1024}) {
    std::vector<double> buffer(kib * 128, 1.0);
    std::vector<double> own, other;
    for (int round = 0; round < 50; ++round) {
      std::atomic<int> phase{0};
      std::thread writer([&] {
        PinTo(1);
        for (double& x : buffer) x += 1;
        phase = 1;
        while (phase != 2) {
        }
      });
      while (phase != 1) {
      }
      auto begin = Clock::now();
      double sum = 0;
      for (double x : buffer) sum += x;
      auto end = Clock::now();
      phase = 2;
      writer.join();
      other.push_back(Microseconds(begin, end));
      checksum += sum;
      for (double& x : buffer) x += 1;
      begin = Clock::now();
      sum = 0;
      for (double x : buffer) sum += x;
      end = Clock::now();
      own.push_back(Microseconds(begin, end));
      checksum += sum;
    }
    std::sort(own.begin(), own.end());
    std::sort(other.begin(), other.end());
    std::printf("%5zu KiB: read after this core's writes %7.2f us, after the other core's %7.2f us\n",
                kib, own[25], other[25]);
  }
  return checksum > 0 ? 0 : 1;
}
