// Process-wide allocator settings for the programs that bake (motionlodd, the motionlod
// tool, the benchmarks). Libraries never call this: it belongs to a program's main.
#pragma once

namespace motionlod {

// Keeps the large blocks a bake frees in the heap, for the next level or the next bake to
// reuse. glibc hands blocks over its mmap threshold (128 KiB at start, adjusted up to the
// largest block freed) back to the kernel when they are freed, and trims the heap's free
// top past twice that threshold; the next matrix of the same size then faults every page
// in again and has the kernel zero it. A bake's transient matrices (right-hand sides,
// solutions, projections, per-frame bounds) are megabytes per level on a long clip: on a
// 1807-frame clip 15% to 20% of the bake was the kernel's page-fault handler.
// Blocks up to 32 MiB (the most glibc allows) now come from the heap and the heap keeps up
// to 128 MiB free: the resident size stays at its peak instead of following each level.
// A no-op where the C library is not glibc.
void KeepFreedBlocksForReuse();

}  // namespace motionlod
