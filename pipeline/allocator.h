// Process-wide allocator settings for the programs that bake (motionlodd, the motionlod
// tool, the benchmarks), called first thing in their main. In the pipeline because the
// settings are tuned to a bake's allocations and every such program links it; the
// pipeline's own functions never call it (a library must not change a process's heap).
#pragma once

namespace motionlod::pipeline {

// Keeps the large blocks a bake frees in the heap, for the next level or the next bake to
// reuse. glibc hands blocks over its mmap threshold (128 KiB at start, adjusted up to the
// largest block freed) back to the kernel when they are freed, and trims the heap's free
// top past twice that threshold; the next matrix of the same size then faults every page
// in again and has the kernel zero it. A bake's transient matrices (right-hand sides,
// solutions, projections, per-frame bounds) are megabytes per level on a long clip, where
// those page faults were 15% to 20% of the bake. Blocks up to 32 MiB (the most glibc
// allows) now come from the heap and the heap keeps up to 128 MiB free: the resident size
// stays at its peak instead of following each level. A no-op where the C library is not
// glibc.
void KeepFreedBlocksForReuse();

}  // namespace motionlod::pipeline
