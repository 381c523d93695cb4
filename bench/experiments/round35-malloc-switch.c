// Round 35 (docs/PERFORMANCE.md): counts malloc calls by size (up to 1 KiB, up to 64 KiB,
// larger) only while a program has switched counting on, and prints them per switch-on
// (per bake) at exit. With round35-malloc-switch.patch, Bake switches it on at its start
// and off where it takes bake_seconds, so the counts are those of the timed bake alone
// (not the import before it nor the report after it):
//   patch -p1 < bench/experiments/round35-malloc-switch.patch   (in a copy of the tree)
//   cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOTIONLOD_BUILD_BENCH=ON
//   cmake --build build --target motionlod_bench_bake_once
//   gcc -O2 -shared -fPIC -o /tmp/malloc_switch.so bench/experiments/round35-malloc-switch.c -ldl
//   LD_PRELOAD=/tmp/malloc_switch.so build/bench/motionlod_bench_bake_once ../shared/data/characters/Fox.glb vp+pd
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <stdatomic.h>
static atomic_long small_n, mid_n, big_n, bakes; static atomic_int on;
static void* (*real_malloc)(size_t);
void malloc_count_set(int v) { atomic_store(&on, v); if (v) atomic_fetch_add(&bakes, 1); }
void* malloc(size_t n) {
  if (!real_malloc) real_malloc = dlsym(RTLD_NEXT, "malloc");
  if (atomic_load(&on)) { if (n <= 1024) atomic_fetch_add(&small_n, 1); else if (n <= 65536) atomic_fetch_add(&mid_n, 1); else atomic_fetch_add(&big_n, 1); }
  return real_malloc(n);
}
__attribute__((destructor)) static void report(void) {
  fprintf(stderr, "per bake: small %.1f mid %.1f big %.1f\n", (double)small_n/bakes, (double)mid_n/bakes, (double)big_n/bakes);
}
