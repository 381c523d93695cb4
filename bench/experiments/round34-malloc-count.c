// Round 34 (docs/PERFORMANCE.md): counts a process's malloc calls by size (up to 1 KiB,
// up to 64 KiB, larger) and their bytes, printed at exit. Per bake: the difference of two
// runs of a harness that differ only in their number of bakes, e.g.
//   gcc -O2 -shared -fPIC -o /tmp/malloc_count.so bench/experiments/round34-malloc-count.c -ldl
//   LD_PRELOAD=/tmp/malloc_count.so /tmp/every_level_medians ../shared/data/characters/Orc.gltf vpno+pd 2 16089 10
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <stdatomic.h>
static atomic_long small_n, mid_n, big_n, total_bytes;
static void* (*real_malloc)(size_t);
void* malloc(size_t n) {
  if (!real_malloc) real_malloc = dlsym(RTLD_NEXT, "malloc");
  if (n <= 1024) atomic_fetch_add(&small_n, 1); else if (n <= 65536) atomic_fetch_add(&mid_n, 1); else atomic_fetch_add(&big_n, 1);
  atomic_fetch_add(&total_bytes, n);
  return real_malloc(n);
}
__attribute__((destructor)) static void report(void) {
  fprintf(stderr, "malloc: small %ld mid %ld big %ld bytes %ld\n", small_n, mid_n, big_n, total_bytes);
}
