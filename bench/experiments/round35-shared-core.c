// Round 35 (docs/PERFORMANCE.md): whether the two virtual CPUs share one core's execution
// units. A throughput-bound loop (16 independent multiply-add chains) and a latency-bound
// one (4 dependent chains), each timed on CPU 0 alone and while CPU 1 runs the same loop:
//   gcc -O2 -mavx2 -mfma -o /tmp/shared_core bench/experiments/round35-shared-core.c
//   taskset -c 0 /tmp/shared_core throughput
//   (taskset -c 1 /tmp/shared_core throughput &); taskset -c 0 /tmp/shared_core throughput
// and the same with `latency`. Cores of their own run either as fast beside each other;
// hyperthreads of one core slow the throughput-bound loop and not the latency-bound one.
#include <stdio.h>
#include <string.h>
#include <time.h>

int main(int argc, char** argv) {
  const int throughput = argc > 1 && strcmp(argv[1], "throughput") == 0;
  struct timespec a, b;
  clock_gettime(CLOCK_MONOTONIC, &a);
  double x[16];
  for (int k = 0; k < 16; ++k) x[k] = 1.0 + k * 1e-3;
  if (throughput) {
    for (long i = 0; i < 100000000L; ++i) {
      for (int k = 0; k < 16; ++k) x[k] = x[k] * 1.0000001 + 1e-9;
    }
  } else {
    for (long i = 0; i < 300000000L; ++i) {
      for (int k = 0; k < 4; ++k) x[k] = x[k] * 1.0000001 + 1e-9;
    }
  }
  double sum = 0;
  for (int k = 0; k < 16; ++k) sum += x[k];
  clock_gettime(CLOCK_MONOTONIC, &b);
  printf("%s: %.3f s (%g)\n", throughput ? "throughput" : "latency",
         (b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec), sum);
  return 0;
}
