#include "pipeline/allocator.h"

#include <cstdlib>  // defines __GLIBC__ on glibc

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace motionlod::pipeline {

void KeepFreedBlocksForReuse() {
#if defined(__GLIBC__)
  constexpr int kMmapThreshold = 32 << 20;
  constexpr int kTrimThreshold = 128 << 20;
  // Either call can only fail on an out-of-range value; these are in range, and a C
  // library that ignores them (a sanitizer's allocator) just keeps its own policy.
  mallopt(M_MMAP_THRESHOLD, kMmapThreshold);
  mallopt(M_TRIM_THRESHOLD, kTrimThreshold);
#endif
}

}  // namespace motionlod::pipeline
